"""Each optional physics effect (SPEC §7) changes the response the way its physics says."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import signal

from core.errors import InputError
from virtual_cnc.drive import Encoder
from virtual_cnc.effects import (
    EFFECTS,
    Backlash,
    CyclicError,
    Resonance,
    Saturation,
    Stribeck,
    TimeDelay,
    format_effect,
    parse_effect,
)
from virtual_cnc.presets import load_machine
from virtual_cnc.servo import simulate_axis_response

from _moves import point_to_point

TS = 0.001




def axis_of(preset="fadal-ppi", ideal_encoder=False):
    axis = load_machine(preset).axes["X"]
    return replace(axis, encoder=Encoder()) if ideal_encoder else axis


def onset(x, x0, threshold):
    """First sample where x has left x0 by more than threshold."""
    return int(np.flatnonzero(np.abs(x - x0) > threshold)[0])


# ----------------------------------------------------------------------------- backlash

def test_backlash_gives_a_lost_motion_step_of_about_the_gap_at_a_slow_reversal():
    gap = 0.02
    t = np.arange(2500) * TS
    x_r = np.sin(2 * np.pi * 0.5 * t)  # reversal at t = 1.5 s, peak speed 3.1 mm/s
    axis = axis_of()
    plain = simulate_axis_response(x_r, axis)
    lash = simulate_axis_response(x_r, axis, [Backlash(gap_mm=gap)])
    extra = (x_r - lash.actual) - (x_r - plain.actual)  # extra tracking error from the lost motion
    before, after = slice(1300, 1500), slice(1500, 1800)
    # the motor-table offset flips by the gap across the reversal (contact compliance aside)
    flip = (lash.motor - lash.table)[1750] - (lash.motor - lash.table)[1250]
    assert flip == pytest.approx(gap, rel=0.1)
    # the load-side encoder sees the table lag by a step of the order of the gap after the reversal,
    # which the position loop then removes; in steady motion before it there is no such lag
    assert 0.4 * gap < np.abs(extra[after]).max() < 1.2 * gap
    assert np.abs(extra[before]).max() < 0.1 * gap
    assert np.abs(extra[2400:]).max() < 0.25 * gap


# ----------------------------------------------------------------------------- time delay

def test_capture_delay_shifts_the_recorded_response_by_the_delay():
    delay = 0.0025  # 2.5 servo periods
    x_r = point_to_point([3.0, -2.0])
    axis = axis_of("fadal-pid", ideal_encoder=True)
    plain = simulate_axis_response(x_r, axis)
    late = simulate_axis_response(x_r, axis, [TimeDelay(delay, where="capture")])
    assert np.array_equal(plain.u, late.u)  # the loop itself is untouched
    t = np.arange(x_r.size) * TS
    # the shift that best aligns the two recordings (cross-correlation on a 0.1 ms grid)
    shifts = np.arange(0.0, 0.005, 0.0001)
    cost = [np.sum((late.actual - np.interp(t - s, t, plain.actual)) ** 2) for s in shifts]
    assert shifts[int(np.argmin(cost))] == pytest.approx(delay, abs=0.00015)


def test_actuation_delay_postpones_the_first_motion_by_the_delay():
    x_r = point_to_point([1.0])
    axis = axis_of("fadal-pid", ideal_encoder=True)
    plain = simulate_axis_response(x_r, axis)
    for delay in (0.001, 0.002, 0.003):
        late = simulate_axis_response(x_r, axis, [TimeDelay(delay)])
        shift = onset(late.table, 0.0, 1e-9) - onset(plain.table, 0.0, 1e-9)
        assert abs(shift - delay / TS) <= 1.0
        assert np.abs(late.actual - plain.actual).max() > 1e-4  # and the loop responds differently


def test_feedback_delay_moves_the_table_on_time_but_reports_it_late():
    delay = 0.002
    x_r = point_to_point([1.0])
    axis = axis_of("fadal-pid", ideal_encoder=True)
    plain = simulate_axis_response(x_r, axis)
    late = simulate_axis_response(x_r, axis, [TimeDelay(delay, where="feedback")])
    assert onset(late.table, 0.0, 1e-9) == onset(plain.table, 0.0, 1e-9)
    recorded_shift = onset(late.actual, 0.0, 1e-6) - onset(late.table, 0.0, 1e-6)
    assert abs(recorded_shift - delay / TS) <= 1.0


# ----------------------------------------------------------------------------- resonance

@pytest.mark.parametrize("preset", ["fadal-ppi", "fadal-pid"])
def test_resonance_puts_a_spectral_peak_at_the_mode_into_the_tracking_error(preset):
    freq = 150.0
    x_r = point_to_point(np.random.default_rng(1).uniform(-10, 10, 12))
    axis = axis_of(preset)
    f, p_plain = signal.welch(x_r - simulate_axis_response(x_r, axis).actual, fs=1 / TS, nperseg=512)
    mode = simulate_axis_response(x_r, axis, [Resonance(freq_hz=freq, damping=0.03)])
    f, p_mode = signal.welch(x_r - mode.actual, fs=1 / TS, nperseg=512)
    band = (f > 0.5 * freq) & (f < 2 * freq)
    ratio = p_mode[band] / p_plain[band]
    assert f[band][np.argmax(ratio)] == pytest.approx(freq, rel=0.07)
    assert ratio.max() > 10
    # the table vibrates against the motor at the mode: the deflection's spectrum peaks there too
    f, p_defl = signal.welch(np.diff(mode.motor - mode.table), fs=1 / TS, nperseg=512)
    assert f[band][np.argmax(p_defl[band])] == pytest.approx(freq, rel=0.07)


# ----------------------------------------------------------------------------- stribeck

def test_stribeck_friction_causes_stick_slip_at_low_speed_where_coulomb_slides_smoothly():
    t = np.arange(3000) * TS
    x_r = 0.2 * t  # 0.2 mm/s
    axis = axis_of()
    coulomb = simulate_axis_response(x_r, axis)
    stribeck = simulate_axis_response(x_r, axis, [Stribeck(static_to_coulomb_ratio=3.0, stribeck_velocity_mm_s=0.5)])
    steady = slice(1000, None)

    def stuck_fraction(r):
        return np.mean(np.diff(r.table[steady]) == 0.0)

    assert stuck_fraction(coulomb) == 0.0
    assert stuck_fraction(stribeck) > 0.5
    e_c = (x_r - coulomb.actual)[steady]
    e_s = (x_r - stribeck.actual)[steady]
    assert e_s.std() > 10 * e_c.std()
    # at speeds well above the Stribeck velocity the effect fades
    fast = 20.0 * t
    d_fast = np.abs(simulate_axis_response(fast, axis).actual
                    - simulate_axis_response(fast, axis, [Stribeck(3.0, 0.5)]).actual)[steady]
    assert d_fast.max() < 0.1 * np.abs(e_s - e_s.mean()).max()


# ----------------------------------------------------------------------------- cyclic error

@pytest.mark.parametrize("speed", [20.0, 40.0])
def test_cyclic_error_adds_an_error_component_periodic_in_position(speed):
    period = 2.0
    t = np.arange(2500) * TS
    x_r = speed * t
    axis = axis_of()
    steady = slice(1000, None)
    e_plain = (x_r - simulate_axis_response(x_r, axis).actual)[steady]
    e_cyc = (x_r - simulate_axis_response(x_r, axis, [CyclicError(period_mm=period, amplitude=300.0)]).actual)[steady]
    f = np.fft.rfftfreq(e_cyc.size, TS)
    spec_c = np.abs(np.fft.rfft(signal.detrend(e_cyc)))
    spec_p = np.abs(np.fft.rfft(signal.detrend(e_plain)))
    f_expected = speed / period  # one cycle per period_mm travelled
    k = int(np.argmin(np.abs(f - f_expected)))
    assert f[np.argmax(spec_c[1:]) + 1] == pytest.approx(f_expected, abs=1.0)
    assert spec_c[k] > 10 * spec_p[k]


# ----------------------------------------------------------------------------- saturation

def test_saturation_limits_the_command_and_grows_the_error_in_the_fastest_accelerations():
    limit = 1.5
    x_r = point_to_point([8.0, -8.0, 2.0])
    axis = axis_of()
    plain = simulate_axis_response(x_r, axis)
    sat = simulate_axis_response(x_r, axis, [Saturation(limit_v=limit)])
    assert np.abs(plain.u).max() > limit  # the unsaturated drive needs more than the limit ...
    assert np.abs(sat.u).max() <= limit  # ... the saturated one never exceeds it
    at_limit = np.abs(sat.u) >= limit - axis.dac_resolution
    acc = np.abs(np.gradient(np.gradient(x_r, TS), TS)) > 1000.0
    # the limit is reached while the command accelerates (or right after, while catching up)
    near_acc = np.convolve(acc, np.ones(60), mode="full")[: x_r.size] > 0
    assert at_limit.sum() > 20 and np.mean(near_acc[at_limit]) > 0.9
    extra = np.abs((x_r - sat.actual) - (x_r - plain.actual))
    assert extra.max() > 0.1  # mm: the lost acceleration shows as tracking error
    assert extra[near_acc].max() == extra.max()


# ----------------------------------------------------------------------------- parsing

@pytest.mark.parametrize(
    "text,expected",
    [
        ("backlash=0.012", Backlash(gap_mm=0.012)),
        ("resonance=freq_hz:40,damping:0.05", Resonance(freq_hz=40.0, damping=0.05)),
        ("stribeck=2", Stribeck(static_to_coulomb_ratio=2.0)),
        ("time_delay=0.003", TimeDelay(delay_s=0.003)),
        ("time_delay=delay_s:0.001,where:capture", TimeDelay(delay_s=0.001, where="capture")),
        ("time_delay=delay_s:0.001,at:capture", TimeDelay(delay_s=0.001, where="capture")),  # older spelling
        ("cyclic_error=period_mm:5,amplitude:100", CyclicError(period_mm=5.0, amplitude=100.0)),
        ("cyclic_error=period_mm:5,phase_rad:0.5", CyclicError(period_mm=5.0, phase_rad=0.5)),
        ("cyclic_error=period_mm:5,phase_deg:90", CyclicError(period_mm=5.0, phase_rad=math.pi / 2)),
        ("saturation=1.2", Saturation(limit_v=1.2)),
        ("saturation=limit_v:1.2", Saturation(limit_v=1.2)),
        ("saturation=limit:1.2", Saturation(limit_v=1.2)),  # older spelling: volts all the same
        ("backlash=gap_mm:0.01,axis:Y", Backlash(gap_mm=0.01, axis="Y")),
        (" Time-Delay = 0.002 ", TimeDelay(delay_s=0.002)),
    ],
)
def test_parse_effect_reads_primary_values_and_named_parameters(text, expected):
    assert parse_effect(text) == expected


@pytest.mark.parametrize("name", list(EFFECTS))
def test_format_effect_round_trips(name):
    effect = EFFECTS[name](axis="X")
    assert parse_effect(format_effect(effect)) == effect


@pytest.mark.parametrize(
    "text,match",
    [
        ("wobble=3", r"unknown effect 'wobble'; known: backlash, stribeck, resonance, time_delay, cyclic_error, saturation"),
        ("backlash", r"effect 'backlash' needs a value, e.g. backlash="),
        ("backlash=abc", r"effect backlash gap_mm: 'abc' is not a number"),
        ("backlash=-0.01", r"backlash gap_mm must be > 0"),
        ("resonance=freq:40", r"unknown parameter 'freq'; known: freq_hz, damping, motor_fraction, axis"),
        ("resonance=freq_hz:40,freq_hz:50", r"given twice"),
        ("resonance=freq_hz:nan", r"not a finite number"),
        ("resonance=freq_hz:40,damping", r"expected key:value"),
        ("time_delay=delay_s:0.001,at:output", r"time_delay where must be one of actuation, feedback, capture"),
        ("stribeck=0.5", r"static_to_coulomb_ratio must be >= 1"),
        ("saturation=0", r"saturation limit_v must be > 0"),
        ("saturation=limit_v:1,limit:2", r"parameter 'limit_v' given twice"),
    ],
)
def test_parse_effect_errors_are_one_line_and_name_the_problem(text, match):
    with pytest.raises(InputError, match=match) as ei:
        parse_effect(text)
    assert "\n" not in str(ei.value)

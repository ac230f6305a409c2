"""Building blocks of the mismatch diagnosis: the augmented simulator and the localisation.

Test data come from the augmented simulator itself on a random point-to-point command, so
each property is checked against a known truth.
"""

from __future__ import annotations

import math
import numpy as np
import pytest

from core.errors import InputError
from ident.diagnosis import diagnose
from ident.diagnosis.augmented import EP_INDEX, N_EP, segment_starts, simulate_augmented
from ident.diagnosis.candidates import ModelSpec, fit_spec, make_chunk, sse
from ident.model import BASE_KEYS
from ident.diagnosis.config import DEFAULT
from ident.diagnosis.residuals import localise, position_periodogram, reversal_times, whiteness, worst_windows

Ts = 0.001
# P-PI drive of thesis Table 3.3 ("Actual" column), eq. 3.3 parameters
THETA = np.array([372.76, 62009.83, 1527104.87, 0.0, 0.0, 11106.33, 441.0, -302.0])


def point_to_point(seed: int, T: float = 3.0, span: float = 5.0, v_max: float = 100.0, a_max: float = 2000.0,
                   dwell: tuple[int, int] = (5, 40)) -> np.ndarray:
    """A random trapezoidal point-to-point command, mm, sampled every Ts, dwelling ``dwell``
    samples (low, high) at each target."""
    rng = np.random.default_rng(seed)
    n = int(T / Ts)
    out = np.zeros(n)
    k, x = 0, 0.0
    while k < n:
        tgt = rng.uniform(-span, span)
        D = abs(tgt - x)
        ta = min(v_max / a_max, np.sqrt(D / a_max))
        vp = a_max * ta
        tc = max(D - vp * ta, 0.0) / vp if vp > 0 else 0.0
        tt = 2 * ta + tc
        tau = np.minimum(np.arange(1, max(int(np.ceil(tt / Ts)), 1) + 1) * Ts, tt)
        pos = np.where(tau < ta, 0.5 * a_max * tau**2,
                       np.where(tau < ta + tc, 0.5 * a_max * ta**2 + vp * (tau - ta), D - 0.5 * a_max * (tt - tau) ** 2))
        seg = x + np.sign(tgt - x) * pos
        e = min(n, k + seg.size)
        out[k:e] = seg[: e - k]
        k, x = e, tgt
        stay = int(rng.integers(*dwell))
        out[k : k + stay] = x
        k += stay
    return out


def sim(x_r: np.ndarray, effects: dict[str, float] | None = None, modes=(0, 0, 0)) -> np.ndarray:
    ep = np.zeros(N_EP)
    flags = np.zeros(6, dtype=np.int64)
    names = {"gap_mm": 0, "static_to_coulomb_ratio": 1, "stribeck_velocity_mm_s": 1, "freq_hz": 2, "damping": 2,
             "gain": 2, "delay_s": 3, "period_mm": 4, "amplitude_sin": 4, "amplitude_cos": 4, "limit": 5}
    for k, v in (effects or {}).items():
        ep[EP_INDEX[k]] = v
        flags[names[k]] = 1
    return simulate_augmented(x_r, x_r, Ts, THETA, flags=flags, ep=ep, modes=np.array(modes))


@pytest.fixture(scope="module")
def x_r() -> np.ndarray:
    return point_to_point(3)


def test_effects_switched_off_or_zero_give_the_base_model(x_r):
    base = sim(x_r)
    assert np.allclose(sim(x_r, {"gap_mm": 0.0}), base, atol=1e-12)
    assert np.allclose(sim(x_r, {"delay_s": 0.0}), base, atol=1e-12)
    assert np.allclose(sim(x_r, {"static_to_coulomb_ratio": 1.0, "stribeck_velocity_mm_s": 1.0}), base, atol=1e-12)


def test_base_model_follows_the_command_and_settles_on_it(x_r):
    held = np.concatenate([x_r, np.full(2000, x_r[-1])])  # 2 s at rest after the last move
    x = sim(held)
    e = held - x
    assert np.all(np.isfinite(x))
    assert np.max(np.abs(e)) < 5.0  # mm: the P-PI drive of Table 3.3 lags but follows
    assert abs(e[-1]) < 0.01  # the integral action removes the friction offset


def test_capture_delay_shifts_the_recorded_position(x_r):
    base = sim(x_r)
    delayed = sim(x_r, {"delay_s": 0.005}, modes=(0, 0, 0))
    assert np.allclose(delayed[100:], base[95:-5], atol=1e-9)


def test_backlash_output_stays_within_half_the_gap_of_the_motor(x_r):
    gap = 0.02
    base = sim(x_r)
    table = sim(x_r, {"gap_mm": gap}, modes=(0, 0, 0))
    assert np.max(np.abs(table - base)) <= gap / 2 + 1e-12
    assert np.max(np.abs(table - base)) > 0.9 * gap / 2


def test_cyclic_position_error_adds_a_sine_of_position(x_r):
    base = sim(x_r)
    y = sim(x_r, {"period_mm": 2.0, "amplitude_sin": 0.003}, modes=(0, 0, 0))
    assert np.allclose(y - base, 0.003 * np.sin(2 * np.pi * base / 2.0), atol=1e-12)


def test_saturation_slows_the_fastest_moves(x_r):
    u = np.empty(x_r.size)
    simulate_augmented(x_r, x_r, Ts, THETA, nsub=8, u_out=u)
    limited = sim(x_r, {"limit": 0.5 * np.max(np.abs(u))})
    assert np.linalg.norm(limited - sim(x_r)) > 1e-3


def test_a_set_that_is_no_model_applies_no_force(x_r):
    # a diverged step's parameters are not simulated: its u is NaN, not whatever the
    # caller's buffer held (callers keep only the finite samples)
    u = np.full(x_r.size, 123.0)
    y = simulate_augmented(x_r, x_r, Ts, THETA * np.array([np.nan, 1, 1, 1, 1, 1, 1, 1]), nsub=8, u_out=u)
    assert np.isnan(y).all() and np.isnan(u).all()


def test_output_error_fit_recovers_a_perturbed_base_model(x_r):
    x = sim(x_r)
    chunk = make_chunk(x_r, x, Ts, segment_starts(x_r.size, None))
    start = ModelSpec(THETA * np.array([1.1, 0.9, 1.1, 1, 1, 0.95, 1.2, 0.8]))
    fitted = fit_spec(fit_spec(start, chunk, max_iter=30, cfg=DEFAULT), chunk, max_iter=30, cfg=DEFAULT)
    assert sse(fitted, chunk) < 1e-3 * sse(start, chunk)


def test_reversals_are_found_where_the_commanded_direction_changes():
    v = np.array([0, 1, 1, 0, 0, 1, -1, -1, 0, -1, 1.0])
    idx = reversal_times(v, segment_starts(v.size, None), 0.5)
    assert idx.tolist() == [6, 10]


def test_worst_windows_point_at_the_burst():
    r = np.zeros(1000)
    r[600:620] = 1.0
    w = worst_windows(r, np.arange(1000) * Ts, 0.05, count=2)
    assert w[0]["t_start_s"] <= 0.600 and w[0]["t_end_s"] >= 0.619
    assert w[0]["energy_share"] == pytest.approx(1.0)


def test_position_periodogram_finds_the_period():
    x = np.linspace(-5, 5, 4000)
    r = 0.002 * np.sin(2 * np.pi * x / 1.7 + 0.3) + 1e-4 * np.random.default_rng(0).standard_normal(x.size)
    periods = np.geomspace(0.5, 5, 400)
    share, _ = position_periodogram(x, r, periods)
    assert periods[np.argmax(share)] == pytest.approx(1.7, rel=0.02)
    assert share.max() > 0.95


def test_position_periodogram_is_the_least_squares_fit_of_every_period():
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.standard_normal(3000)) * 0.01  # a wandering axis, not a grid
    r = 0.3 + 0.002 * np.cos(2 * np.pi * x / 0.9) + 1e-3 * rng.standard_normal(x.size)
    periods = np.geomspace(0.05, 2 * np.ptp(x), 37)
    for constant in (True, False):
        share, amp = position_periodogram(x, r, periods, constant=constant)
        y = r - r.mean() if constant else r
        for P, sh, c in zip(periods, share, amp):
            ph = 2 * np.pi * x / P
            A = np.column_stack([np.sin(ph), np.cos(ph)] + ([np.ones_like(x)] if constant else []))
            coef, *_ = np.linalg.lstsq(A, y, rcond=None)
            fit = A @ coef
            # to the resolution of the sines (taken in float32, ~2e-7 of the amplitude)
            assert sh == pytest.approx(float(fit @ fit) / float(y @ y), rel=1e-4, abs=1e-9)
            assert c == pytest.approx(coef[0] + 1j * coef[1], rel=1e-4, abs=1e-9)


def test_whiteness_passes_noise_and_fails_a_smooth_residual():
    rng = np.random.default_rng(1)
    u = rng.standard_normal(5000)
    assert whiteness(rng.standard_normal(5000), u)["white"]
    smooth = np.convolve(rng.standard_normal(5000), np.ones(50) / 50, mode="same")
    res = whiteness(smooth, u)
    assert not res["white"]
    assert res["autocorrelation_lag1"] > 0.9


def test_localise_concentrates_a_reversal_residual_after_reversals(x_r):
    v = np.gradient(x_r, Ts)
    a = np.gradient(v, Ts)
    starts = segment_starts(x_r.size, None)
    rev = reversal_times(v, starts, 1e-3)
    r = np.zeros_like(x_r)
    for k in rev:
        r[k : k + 20] = 1e-3
    loc = localise(r, x_r, x_r, v, a, Ts, starts)
    assert loc["after_reversal_30ms_share"] > 0.95
    assert loc["after_reversal_30ms_time_share"] < 0.5


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"x": np.zeros(10)}, "samples"),
        ({"Ts": -1.0}, "sample period"),
        ({"x": np.full(3000, np.nan)}, "NaN"),
        ({"model": {"a1": 1.0}}, "parameters"),
    ],
)
def test_bad_input_gives_a_one_line_error(x_r, kwargs, match):
    args = {"x_r": x_r, "x": x_r.copy(), "Ts": Ts, "model": dict(zip(BASE_KEYS, THETA))}
    args.update(kwargs)
    with pytest.raises(InputError, match=match) as exc:
        diagnose(args.pop("x_r"), args.pop("x"), args.pop("Ts"), args.pop("model"))
    assert "\n" not in str(exc.value)


def _recording(seed: int, effects: dict[str, float] | None = None, modes=(0, 0, 0), noise: float = 5e-5):
    """A 3 s 'recording' of the augmented model itself: command, actual + encoder noise (mm)."""
    x_r = point_to_point(seed)
    x = sim(x_r, effects, modes) + noise * np.random.default_rng(seed).standard_normal(x_r.size)
    return x_r, x


MODEL = dict(zip(BASE_KEYS, THETA))


def test_clean_model_data_give_none_and_a_complete_json():
    x_r, x = _recording(11)
    val = _recording(12)
    d = diagnose(x_r, x, Ts, MODEL, validation=(val[0], val[1], None))
    assert d.verdict == "none", d.summary
    js = d.to_dict()
    assert js["verdict"] == "none" and len(js["candidates"]) >= 6
    assert "Left out: none" in d.summary


def test_a_position_periodic_disturbance_is_named_with_its_period():
    fx = {"period_mm": 2.5, "amplitude_sin": 400.0}
    x_r, x = _recording(21, fx, modes=(0, 0, 1))
    val = _recording(22, fx, modes=(0, 0, 1))
    d = diagnose(x_r, x, Ts, MODEL, validation=(val[0], val[1], None))
    assert d.verdict == "cyclic_error", d.summary
    cand = [c for c in d.candidates if c.accepted][0]
    assert cand.parameters["period_mm"] == pytest.approx(2.5, rel=0.05)
    assert d.fit_after_pct > d.fit_before_pct
    assert "cyclic error" in d.summary


def test_against_a_simulated_recording_localises_their_difference():
    x_r, x = _recording(31)
    other = sim(x_r, {"delay_s": 0.004}, modes=(0, 0, 0))
    d = diagnose(x_r, x, Ts, MODEL, against=other, effects=("time_delay",))
    assert d.mismatch["compared_with"] == "simulated recording"
    assert d.mismatch["rms_mm"] == pytest.approx(float(np.sqrt(np.mean((other - x) ** 2))), rel=1e-9)


# --- sampled controller, motor-read position term, dead-time profile, summary words ---------

SAMPLED = (0, 0, 0, 0, 1)


def test_sampled_controller_follows_the_command_close_to_the_continuous_one(x_r):
    cont = sim(x_r)
    samp = sim(x_r, modes=SAMPLED)
    assert np.all(np.isfinite(samp))
    # the hold and the backward-difference velocity add about a sample of lag, no more
    err_c, err_s = x_r - cont, x_r - samp
    assert 0.0 < np.max(np.abs(samp - cont)) < 0.2 * np.max(np.abs(err_c))
    assert np.std(err_s) == pytest.approx(np.std(err_c), rel=0.2)


def test_two_mass_backlash_position_term_can_read_the_motor(x_r):
    ep = np.zeros(N_EP)
    ep[EP_INDEX["gap_mm"]] = 0.03
    ep[EP_INDEX["motor_fraction"]] = 0.8
    flags = np.array([1, 0, 0, 0, 0, 0])
    on_table = simulate_augmented(x_r, x_r, Ts, THETA, flags=flags, ep=ep, modes=np.array([1, 0, 0, 0, 0]))
    ep[EP_INDEX["position_motor_share"]] = 0.8
    on_motor = simulate_augmented(x_r, x_r, Ts, THETA, flags=flags, ep=ep, modes=np.array([1, 0, 0, 0, 0]))
    assert np.all(np.isfinite(on_motor))
    # a loop closed on the motor leaves the table lagging by up to the half gap, not closed
    assert np.max(np.abs(on_motor - on_table)) > 0.3 * 0.03 / 2


def _one_move(D: float = 5.0, a: float = 2000.0, rest_s: float = 1.0) -> np.ndarray:
    """One move of D mm: accelerate, brake at the same rate (triangular velocity), then rest."""
    ta = np.sqrt(D / a)
    t = np.arange(int(2 * ta / Ts) + 1) * Ts
    pos = np.where(t < ta, 0.5 * a * t**2, D - 0.5 * a * (2 * ta - t) ** 2)
    return np.concatenate([np.zeros(100), pos, np.full(int(rest_s / Ts), D)])


def test_a_semi_closed_table_with_inertia_runs_across_the_gap_when_the_motor_brakes():
    # loop on the motor, table recorded: a massless table stopped by its friction stays half a
    # gap behind the motor (mode 0); a table with inertia and almost no friction is pulled
    # back by the motor's far side while braking, so it rests half a gap *ahead* (mode 2)
    gap = 0.1
    x_r = _one_move()
    theta = THETA.copy()
    theta[6:] = (1.0, -1.0)  # almost no friction
    ep = np.zeros(N_EP)
    ep[EP_INDEX["gap_mm"]] = gap
    ep[EP_INDEX["motor_fraction"]] = 0.5
    flags = np.array([1, 0, 0, 0, 0, 0])
    massless = simulate_augmented(x_r, x_r, Ts, theta, flags=flags, ep=ep, modes=np.array([0, 0, 0, 0, 0, 0]))
    inertia = simulate_augmented(x_r, x_r, Ts, theta, flags=flags, ep=ep, modes=np.array([2, 0, 0, 0, 0, 0]))
    assert massless[-1] == pytest.approx(x_r[-1] - gap / 2, abs=0.1 * gap)
    assert inertia[-1] == pytest.approx(x_r[-1] + gap / 2, abs=0.1 * gap)


def test_the_sub_steps_of_a_two_mass_gap_are_the_same_for_fits_and_scores():
    from ident.diagnosis.augmented import CONTACT_HZ, CONTACT_STEP_RAD, model_substeps, substeps
    from ident.diagnosis.spec import sim_substeps

    contact = math.ceil(Ts * 2.0 * math.pi * CONTACT_HZ / CONTACT_STEP_RAD)
    for mode in (1, 2):  # both two-mass variants keep the stiff contact stable
        s = ModelSpec(THETA.copy()).with_effect("backlash", {"gap_mm": 0.1, "motor_fraction": 0.5}, mode)
        # fit_spec (sim_substeps) and simulate_spec (the simulator's default) agree
        assert sim_substeps(s, Ts) == model_substeps(s.theta, Ts, s.flags(), s.ep, s.modes)
        assert sim_substeps(s, Ts) == max(substeps(s.theta, Ts), contact)


def test_at_the_contacts_own_sub_steps_the_gap_model_is_within_a_percent_of_what_the_gap_changes(x_r):
    """The contact is integrated for stability, not phase accuracy (its stiffness stands for
    "stiff"): at the sub-steps it sets, the gap model is within 1 % of what the gap changes
    of a 64-sub-step reference."""
    from ident.diagnosis.spec import sim_substeps

    def run(spec, nsub):
        return simulate_augmented(x_r, x_r, Ts, spec.theta, flags=spec.flags(), ep=spec.ep, modes=spec.modes,
                                  nsub=nsub)

    # a soft loop (poles within 70 rad/s: one sub-step of its own), so the contact alone
    # sets the sub-steps
    k = 0.3
    theta = THETA * np.array([k, k * k, k ** 3, 1.0, k, 1.0, 1.0, 1.0])
    theta[5] = theta[1]
    base = ModelSpec(theta)
    for mode in (1, 2):
        s = base.with_effect("backlash", {"gap_mm": 0.02, "motor_fraction": 0.5}, mode)
        n = sim_substeps(s, Ts)
        assert n > sim_substeps(base, Ts) == 1
        ref = run(s, 64)
        no_gap = base.with_effect("backlash", {"gap_mm": 0.0, "motor_fraction": 0.5}, mode)
        effect = np.sqrt(np.mean((ref - run(no_gap, 64)) ** 2))
        err = np.sqrt(np.mean((run(s, n) - ref) ** 2))
        assert effect > 1e-3 and np.isfinite(err) and err <= 1e-2 * effect


def _actuation_delay_recording(x_r: np.ndarray, delay_s: float):
    """A chunk recorded from the P-PI drive on the sampled controller with a dead time on u."""
    ep = np.zeros(N_EP)
    ep[EP_INDEX["delay_s"]] = delay_s
    x = simulate_augmented(x_r, x_r, Ts, THETA, flags=np.array([0, 0, 0, 1, 0, 0]), ep=ep,
                           modes=np.array([0, 1, 0, 0, 1]))
    return make_chunk(x_r, x, Ts, segment_starts(x_r.size, None))


def test_the_search_recovers_an_actuation_dead_time_on_the_sampled_controller(x_r):
    from ident.diagnosis.candidates import search

    chunk = _actuation_delay_recording(x_r, 0.0013)
    start = ModelSpec(THETA.copy())
    start.modes[4] = 1
    fitted = search(start, "time_delay", chunk, {}, DEFAULT)
    assert fitted.modes[1] == 1  # actuation, not capture
    assert fitted.ep[EP_INDEX["delay_s"]] == pytest.approx(0.0013, rel=0.1)


def _capture_delay_recording(x_r: np.ndarray, delay_s: float):
    """A chunk from the P-PI drive on the sampled controller, recorded late by a dead time,
    read by a 1 µm scale (the quantisation is what leaves the delay weakly determined)."""
    ep = np.zeros(N_EP)
    ep[EP_INDEX["delay_s"]] = delay_s
    x = simulate_augmented(x_r, x_r, Ts, THETA, flags=np.array([0, 0, 0, 1, 0, 0]), ep=ep,
                           modes=np.array([0, 0, 0, 0, 1]))
    return make_chunk(x_r, np.round(x, 3), Ts, segment_starts(x_r.size, None))


def test_a_weakly_determined_capture_delay_is_moved_to_the_middle_of_the_delays_that_fit_as_well(x_r):
    from ident.diagnosis.candidates import centre_delay, effect_parameters

    chunk = _capture_delay_recording(x_r, 0.003)
    low = ModelSpec(THETA.copy(), ("time_delay",))
    low.modes[4] = 1
    low.ep[EP_INDEX["delay_s"]] = 0.0018  # where a fit on the flat side of the profile stops
    low = fit_spec(low, chunk, fit_effects=False, cfg=DEFAULT)
    centred = centre_delay(low, chunk, DEFAULT)
    p = effect_parameters(centred, "time_delay")
    lo, hi = p["delay_range_s"]
    assert lo < 0.003 < hi  # the truth fits as well as the start
    assert p["delay_s"] == pytest.approx(0.5 * (lo + hi))
    assert p["delay_s"] == pytest.approx(0.003, rel=0.25)
    assert sse(centred, chunk) <= 1.02 * sse(low, chunk)


@pytest.mark.parametrize("where, controller, lag", [(1, 0, 1e-3), (1, 1, 0.0), (1, 2, 0.0), (0, 0, 0.0)])
def test_a_dead_time_is_told_without_the_lag_of_sampling_its_model_carries(where, controller, lag):
    """Inside the loop of the continuous controller a fitted delay also takes up the hold
    and the sampled velocity of the digital drive (one sample); the sampled controller
    simulates them, and a capture delay lies outside the loop.  ``delay_s`` is the drive's
    dead time; the model simulates ``delay_s + sampling_lag_s``."""
    from ident.diagnosis.effects import TimeDelay, effect_parameters

    spec = ModelSpec(THETA.copy()).with_effect("time_delay", {"delay_s": 0.0025}, where)
    spec.modes[4] = controller
    p = effect_parameters(spec, "time_delay", 1e-3)
    assert p["delay_s"] == pytest.approx(0.0025 - lag)
    assert p.get("sampling_lag_s", 0.0) == pytest.approx(lag)
    assert TimeDelay().words(p).startswith(f"time delay {1e3 * (0.0025 - lag):.2f} ms")
    ep, modes = np.zeros(N_EP), spec.modes.copy()
    TimeDelay().set_arrays(p, ep, modes)
    assert ep[EP_INDEX["delay_s"]] == pytest.approx(0.0025)  # read back, the model's own delay
    assert effect_parameters(spec, "time_delay")["delay_s"] == 0.0025  # no sample period: the model's
    # within the lag of sampling: a dead time of at most one sample beyond what the model carries
    spec.ep[EP_INDEX["delay_s"]] = 0.0019
    assert TimeDelay.within_inherent_lag(spec, 1e-3) == bool(lag)


def test_a_two_mass_mode_is_told_with_the_frequency_the_table_rings_at_against_a_held_motor():
    """f·√μ: motor share μ = 0.36 of the inertia, free-free mode 50 Hz → 30 Hz."""
    from ident.diagnosis.effects import EFFECT_MODELS, effect_parameters

    spec = ModelSpec(THETA.copy()).with_effect("resonance", {"freq_hz": 50.0, "damping": 0.02,
                                                             "motor_fraction": 0.36}, 1)
    p = effect_parameters(spec, "resonance")
    assert p["locked_motor_hz"] == pytest.approx(30.0)
    assert "the table rings at 30.0 Hz with the motor held" in EFFECT_MODELS["resonance"].words(p)
    assert "locked_motor_hz" not in effect_parameters(spec.with_effect("resonance", variant=0), "resonance")


def test_a_parameter_with_a_range_is_held_by_later_fits(x_r):
    chunk = _capture_delay_recording(x_r, 0.003)
    spec = ModelSpec(THETA.copy(), ("time_delay",))
    spec.modes[4] = 1
    spec.ep[EP_INDEX["delay_s"]] = 0.002
    spec.ranges["delay_s"] = (0.0015, 0.0025)
    assert fit_spec(spec, chunk, max_iter=5, cfg=DEFAULT).ep[EP_INDEX["delay_s"]] == 0.002
    spec.ranges.clear()
    assert fit_spec(spec, chunk, max_iter=5, cfg=DEFAULT).ep[EP_INDEX["delay_s"]] != 0.002


def test_the_motor_share_of_the_position_term_follows_from_the_controller_structure():
    from ident.diagnosis.effects import cascade_motor_share, motor_shares

    # P-PI cascade of Table 3.3, no feed-forward: ψ = Ki/(Kd·Kp + Ki) = 1 − b2/a2 (b2 = K·Kp·Kd)
    assert cascade_motor_share(THETA) == pytest.approx(1.0 - 11106.33 / 62009.83, rel=0.005)
    assert motor_shares(THETA) == (pytest.approx(1.0 - 11106.33 / 62009.83),)
    # a cascade Kv 300, Kp 30, Ki 15 000 (per unit mass) with velocity feed-forward 0.9:
    # Ki·kvff·x_r joins b2, so 1 − b2/a2 is no longer ψ = Ki/a2 = 0.625; the roots still are
    kv, kp, ki, kvff = 300.0, 30.0, 15000.0, 0.9
    theta_ff = np.array([kv, kv * kp + ki, ki * kp, 0.0, kv * kvff, kv * kp + ki * kvff, 0.0, 0.0])
    assert cascade_motor_share(theta_ff) == pytest.approx(0.625)
    assert motor_shares(theta_ff) == (pytest.approx(0.0625), pytest.approx(0.625))
    # PID of Table 3.4 on the scale: b2 = a2, ψ = 0 is the first reading
    assert motor_shares(np.array([192.65, 44356.0, 316830.0, 0.0, 190.1, 44356.0, 441.0, -302.0]))[0] == 0.0
    assert cascade_motor_share(np.array([1.0, -5.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0])) == 0.0


def test_a_delay_range_is_said_only_when_the_recording_leaves_it_open():
    from ident.diagnosis.diagnose import _param_words
    from ident.report import _param_text

    wide = {"delay_s": 0.003, "where": "capture", "delay_range_s": [0.0013, 0.0047]}
    sharp = {"delay_s": 0.001, "where": "actuation", "delay_range_s": [0.001, 0.001]}
    assert _param_words("time_delay", wide) == "time delay 3.00 ms (capture; 1.30–4.70 ms fit equally well)"
    assert _param_words("time_delay", sharp) == "time delay 1.00 ms (actuation)"
    assert _param_text(wide["delay_range_s"]) == "0.0013–0.0047"
    assert _param_text(sharp["delay_range_s"]) == "0.001"


def test_an_effect_must_explain_more_than_the_measurement_noise():
    from ident.diagnosis.config import DEFAULT
    from ident.diagnosis.diagnose import _above_noise, _Scored

    rng = np.random.default_rng(0)
    noise = rng.normal(0.0, 0.4e-3, 20000)                       # 0.4 µm sensor scatter
    periodic = 1.3e-3 * np.sin(np.linspace(0.0, 40.0 * np.pi, noise.size))

    def scored(r: np.ndarray) -> _Scored:
        return _Scored([], [r], [r], [0.0])

    base = scored(noise + periodic)
    # the residual is only ~2.5x the noise, yet the effect removes a systematic 0.9 µm rms
    ok, why = _above_noise(scored(noise), base, 0.4e-3, DEFAULT)
    assert ok and why == ""
    # an effect that removes a sliver of it changes the prediction by less than the scatter
    ok, why = _above_noise(scored(noise + 0.97 * periodic), base, 0.4e-3, DEFAULT)
    assert not ok and "within the measurement noise" in why


def test_the_report_says_diverged_for_a_candidate_whose_free_run_exploded():
    from ident.report import _fit_cell

    assert _fit_cell(-9.6e89) == "diverged"
    assert _fit_cell(-35.2) == "-35.2"
    assert _fit_cell(99.5) == "99.5"
    assert _fit_cell(float("nan")) == "n/a"


def test_summary_words_show_a_change_that_rounds_away_at_one_decimal():
    from ident.diagnosis.diagnose import _fit_words, _rms_words

    assert _fit_words(99.801, 99.862) == "99.80 % → 99.86 %"
    assert _fit_words(91.4, 95.9) == "91.4 % → 95.9 %"
    assert _rms_words(0.0024, 0.0019) == "residual rms 2.4 → 1.9 µm (−21 %)"


def _two_mass_recording(x_r: np.ndarray, freq_hz: float) -> np.ndarray:
    """P-PI drive with a lightly damped two-mass mode, sampled controller (position term on the motor)."""
    ep = np.zeros(N_EP)
    ep[EP_INDEX["freq_hz"]] = freq_hz
    ep[EP_INDEX["damping"]] = 0.02
    ep[EP_INDEX["motor_fraction"]] = 0.8
    ep[EP_INDEX["position_motor_share"]] = 0.8
    return simulate_augmented(x_r, x_r, Ts, THETA, flags=np.array([0, 0, 1, 0, 0, 0]), ep=ep,
                              modes=np.array([0, 0, 0, 1, 1]))


def test_a_mode_started_at_the_residual_spectrum_peak_is_found_there(x_r):
    from ident.diagnosis.candidates import search

    x = _two_mass_recording(x_r, 120.0)
    chunk = make_chunk(x_r, x, Ts, segment_starts(x_r.size, None))
    base = ModelSpec(THETA.copy())
    base.modes[4] = 1
    # the closed-loop peak of a two-mass mode lies a little below its free-free frequency
    evidence = {"spectrum_peaks": [{"freq_hz": 4.0, "share_above_20_hz": 0.0},
                                   {"freq_hz": 110.0, "share_above_20_hz": 0.3}]}
    fitted = search(base, "resonance", chunk, evidence, DEFAULT)
    assert fitted.ep[EP_INDEX["freq_hz"]] == pytest.approx(120.0, rel=0.05)
    assert sse(fitted, chunk) < 0.01 * sse(base, chunk)


def test_a_resonance_is_a_lightly_damped_mode_below_nyquist_by_definition():
    from ident.diagnosis.config import DEFAULT
    from ident.diagnosis.effects import EFFECT_MODELS

    res = EFFECT_MODELS["resonance"]
    spec = ModelSpec(THETA.copy(), ("resonance",))
    spec.modes[3] = 1
    chunk = make_chunk(np.linspace(0, 1, 300), np.linspace(0, 1, 300), Ts, segment_starts(300, None))
    # beyond 0.45/Ts is no mode the sampling shows; ζ on the upper bound of the definition is
    # a better-damped pole pair the fit asked for (a filter), no mode
    for f, zeta, ok in ((105.0, 0.02, True), (105.0, 0.4, False), (600.0, 0.02, False),
                        (105.0, DEFAULT.max_mode_damping, False)):
        spec.ep[EP_INDEX["freq_hz"]] = f
        spec.ep[EP_INDEX["damping"]] = zeta
        assert (res.implausible(spec, chunk, DEFAULT) == "") is ok
    # the fit is held to lightly damped modes: the damping's bound is that figure
    assert res.bounds("damping", 0.05, chunk, DEFAULT)[1] == DEFAULT.max_mode_damping


def test_a_cyclic_error_shows_a_whole_period_within_the_travel_recorded():
    from ident.diagnosis.effects import EFFECT_MODELS

    x = np.linspace(0.0, 20.0, 300)  # 20 mm of travel
    chunk = make_chunk(x, x, Ts, segment_starts(300, None))
    spec = ModelSpec(THETA.copy(), ("cyclic_error",))
    for period, ok in ((5.0, True), (15.0, True), (20.0, True), (25.0, False), (60.0, False)):
        spec.ep[EP_INDEX["period_mm"]] = period
        assert (EFFECT_MODELS["cyclic_error"].implausible(spec, chunk, DEFAULT) == "") is ok


def test_regression_with_the_delay_starts_near_the_true_gains(x_r):
    from ident.diagnosis.candidates import delayed_regression_start

    chunk = _actuation_delay_recording(x_r, 0.002)
    # 2 ms actuation dead time + about a sample of hold and sampled velocity = 3 samples
    near = delayed_regression_start(chunk, 3)
    # a1 and a2 (velocity and position gains); the integral gain a3 is weakly determined by
    # an equation-error fit and left to the output-error fit that follows
    assert near.theta[:2] == pytest.approx(THETA[:2], rel=0.2)
    # the regression without the delay puts the loop's gains far off (a2 > 2x)
    far = delayed_regression_start(chunk, 0)
    assert far.theta[1] > 2.0 * THETA[1]


def test_regression_that_pairs_the_command_earlier_knows_a_capture_delay(x_r):
    from ident.diagnosis.effects import TimeDelay

    # continuous P-PI drive recorded 4 ms late: a grid start of the capture delay knows it
    ep = np.zeros(N_EP)
    ep[EP_INDEX["delay_s"]] = 0.004
    x = simulate_augmented(x_r, x_r, Ts, THETA, flags=np.array([0, 0, 0, 1, 0, 0]), ep=ep, modes=np.array([0, 0, 0, 0, 0]))
    chunk = make_chunk(x_r, x, Ts, segment_starts(x_r.size, None))
    near = TimeDelay._capture_start(chunk, 4)
    assert near.theta[:2] == pytest.approx(THETA[:2], rel=0.2)
    starts = TimeDelay().starts(ModelSpec(THETA.copy()), chunk, {}, DEFAULT)
    capture = [s for s in starts if s.origin == "delayed regression" and s.modes[1] == 0]
    assert {round(s.ep[EP_INDEX["delay_s"]] / Ts) for s in capture} >= {1, 3, 5}
    # the start at the true delay simulates the recording far better than the base
    # identified as if there were no delay, held at that delay
    at_truth = TimeDelay._capture_start(chunk, 4).with_effect("time_delay", {"delay_s": 0.004}, 0)
    unaware = TimeDelay._capture_start(chunk, 0).with_effect("time_delay", {"delay_s": 0.004}, 0)
    assert sse(at_truth, chunk) < 0.5 * sse(unaware, chunk)


def test_evidence_strength_charges_the_parameters_an_effect_adds():
    from ident.diagnosis.diagnose import _Scored, evidence

    rng = np.random.default_rng(0)
    r0 = [rng.normal(size=4000)]
    r1 = [0.9 * r0[0]]
    ref, sc = _Scored([], r0, r0, [1.0]), _Scored([], r1, r1, [1.0])
    one, three = evidence(sc, ref, 1, DEFAULT), evidence(sc, ref, 3, DEFAULT)
    assert one["likelihood_ratio"] == pytest.approx(three["likelihood_ratio"])
    assert one["minus_log10_p"] > three["minus_log10_p"] > 0  # same gain, fewer parameters: stronger


def test_an_effect_that_fits_the_training_data_worse_than_its_reference_earns_nothing():
    from dataclasses import replace

    from ident.diagnosis.config import DEFAULT
    from ident.diagnosis.diagnose import _Scored, evidence

    rng = np.random.default_rng(1)
    r0 = [rng.normal(size=4000)]
    r1 = [0.5 * r0[0]]  # held out: the residual halved, far beyond the χ² threshold
    ref = _Scored([], r0, r0, [1.0])
    better = evidence(_Scored([], r1, r1, [0.9]), ref, 1, DEFAULT)
    worse = evidence(_Scored([], r1, r1, [1.1]), ref, 1, DEFAULT)  # another valley of the base
    assert better["significant"] and better["fits_training"]
    assert not worse["significant"] and not worse["fits_training"]
    assert evidence(_Scored([], r1, r1, [1.1]), ref, 1, replace(DEFAULT, nested_training=False))["significant"]


def _slow_residual(rng: np.random.Generator, n: int) -> np.ndarray:
    """A residual like a base model's mismatch: noise through a 10 Hz-ish low-pass (τ ≈ 100 samples)."""
    from scipy.signal import lfilter

    return lfilter([0.02], [1.0, -0.98], rng.normal(size=n))


def test_ar_whitener_recovers_an_ar_process_and_whitens_it():
    from scipy.signal import lfilter

    from ident.diagnosis.diagnose import ar_whitener, correlation_time

    rng = np.random.default_rng(3)
    e = rng.normal(size=20_000)
    r = lfilter([1.0], [1.0, -1.5, 0.7], e)  # AR(2)
    a = ar_whitener(r, 10)
    assert a.size - 1 == 2  # BIC picks the true order
    assert a[1:] == pytest.approx([-1.5, 0.7], abs=0.03)
    assert correlation_time(r) > 4.0
    assert correlation_time(lfilter(a, [1.0], r)) == pytest.approx(1.0, abs=0.2)


def test_a_sharp_effect_on_a_slow_residual_is_heard_once_the_residuals_are_whitened():
    from dataclasses import replace

    from ident.diagnosis.config import DEFAULT
    from ident.diagnosis.diagnose import _Scored, evidence

    rng = np.random.default_rng(4)
    n = 3000
    slow = _slow_residual(rng, n)
    # a gap's signature: short steps at reversals, a tenth of the residual norm
    gap = np.zeros(n)
    for i in rng.choice(n - 30, 12, replace=False):
        gap[i : i + 30] += rng.choice([-1.0, 1.0])
    gap *= 0.12 * np.linalg.norm(slow) / np.linalg.norm(gap)
    ref, sc = _Scored([], [slow + gap], [slow + gap], [1.0]), _Scored([], [slow], [slow], [1.0])
    ev = evidence(sc, ref, 2, DEFAULT)
    assert ev["significant"] and ev["statistic"].startswith("AR-whitened")
    # counted as N/τ samples of the slow residual the same gain is not significant
    assert not evidence(sc, ref, 2, replace(DEFAULT, ar_order_max=0))["significant"]


def test_a_slow_gain_is_heard_by_the_slow_noise_model():
    from ident.diagnosis.diagnose import _Scored, evidence

    # like friction at low speed: the effect takes out most of a smooth 0.5 Hz wave, which
    # whitening by the residual's own AR filter (nearly a difference) all but removes
    rng = np.random.default_rng(6)
    rest = _slow_residual(rng, 6000)
    part = np.sqrt(2.0) * np.std(rest) * np.sin(2.0 * np.pi * 0.5 * 1e-3 * np.arange(6000))
    r0, r1 = rest + part, rest + 0.2 * part
    ev = evidence(_Scored([], [r1], [r1], [1.0]), _Scored([], [r0], [r0], [1.0]), 2, DEFAULT)
    assert ev["significant"] and ev["statistic"].startswith("N/τ")


def test_fitting_k_parameters_to_a_slow_residual_alone_is_rarely_significant():
    from ident.diagnosis.diagnose import _Scored, evidence

    from scipy.signal import lfilter

    # the null hypothesis: the "effect" is k = 2 regressors of no meaning fitted to the
    # held-out residual itself, by least squares in the whitened metric the rule uses (the
    # most a fit could take out of it): its likelihood ratio is then χ²(2)
    rng = np.random.default_rng(5)
    lr = []
    for _ in range(40):
        r0 = _slow_residual(rng, 3000)
        X = np.column_stack([_slow_residual(rng, 3000) + 0.02 * rng.normal(size=3000) for _k in range(2)])
        w = lambda v: lfilter([1.0, -0.98], [1.0], v, axis=0)  # noqa: E731  (the residual's own whitener)
        r1 = r0 - X @ np.linalg.lstsq(w(X), w(r0), rcond=None)[0]
        lr.append(evidence(_Scored([], [r1], [r1], [1.0]), _Scored([], [r0], [r0], [1.0]), 2, DEFAULT)["likelihood_ratio"])
    assert 0.5 < np.mean(lr) < 5.0  # χ²(2) has mean 2
    assert sum(v > 10.6 for v in lr) <= 1  # χ²(2)'s 99.5 % quantile (the rule's own threshold, at α/4, is higher)


def test_evidence_strength_stays_finite_and_ordered_where_the_p_value_underflows():
    from ident.diagnosis.diagnose import _minus_log10_sf

    s = [_minus_log10_sf(x, 2) for x in (100.0, 1000.0, 1500.0, 5000.0)]
    assert all(np.isfinite(s)) and s == sorted(s)
    assert _minus_log10_sf(1500.0, 1) > _minus_log10_sf(1500.0, 3)


def test_a_released_spec_frees_what_a_range_held_and_leaves_the_original_alone():
    spec = ModelSpec(THETA.copy(), ("time_delay",))
    spec.ranges["delay_s"] = (0.001, 0.002)
    free = spec.released()
    assert free.ranges == {} and spec.ranges == {"delay_s": (0.001, 0.002)}
    assert free.effects == spec.effects and np.array_equal(free.theta, spec.theta)


# PID drive with velocity feed-forward (the fadal-pid preset's loop), eq. 3.3 parameters
THETA_PID = np.array([192.65, 44356.0, 316830.0, 0.0, 190.1, 44356.0, 441.0, -302.0])


@pytest.mark.parametrize("exact", [False, True], ids=["differences", "exact"])
@pytest.mark.parametrize("start_gap_mm", [0.03, 0.08])
def test_a_backlash_gap_started_off_by_half_moves_to_the_true_gap(x_r, start_gap_mm, exact):
    # the contact's instants are resolved inside the sub-step (ident.kernel._contact_push):
    # the cost is smooth enough over the gap that differences and exact slopes both reach
    # the noise floor (a contact switched for whole sub-steps rippled the cost, and a fit
    # stopped 2-4 % short of the gap at about 1 % of the start's cost).  From 0.09 mm the
    # joint fit falls into another valley (0.047 mm, a1 and a2 4-10 % low, a3 15-35 %): the search's starts
    # (Backlash.start_gaps_mm) are what covers that.
    ep = np.zeros(N_EP)
    ep[EP_INDEX["gap_mm"]] = 0.06
    ep[EP_INDEX["motor_fraction"]] = 0.75
    modes = np.array([1, 0, 0, 0, 1])  # two-mass backlash, sampled controller
    x = simulate_augmented(x_r, x_r, Ts, THETA_PID, flags=np.array([1, 0, 0, 0, 0, 0]), ep=ep, modes=modes)
    x = x + np.random.default_rng(0).normal(0.0, 5e-5, x.size)
    chunk = make_chunk(x_r, x, Ts, segment_starts(x_r.size, None))
    start = ModelSpec(THETA_PID.copy())
    start.effects = ("backlash",)
    start.ep[EP_INDEX["gap_mm"]] = start_gap_mm
    start.ep[EP_INDEX["motor_fraction"]] = 0.75
    start.modes[: modes.size] = modes
    from dataclasses import replace

    fitted = fit_spec(start, chunk, cfg=replace(DEFAULT, exact_fine=exact, exact_rough=exact))
    assert fitted.ep[EP_INDEX["gap_mm"]] == pytest.approx(0.06, rel=0.01)
    assert sse(fitted, chunk) < 0.002 * sse(start, chunk)


def _full_closed_gap() -> tuple:
    """A full-closed drive across a 20 µm gap whose position term reads the motor in part
    (ψ = 0.25), and a start with ψ at a reading of θ (here 0.85), as the search starts."""
    x_r = point_to_point(3)
    ep = np.zeros(N_EP)
    ep[EP_INDEX["gap_mm"]] = 0.02
    ep[EP_INDEX["motor_fraction"]] = 0.5
    ep[EP_INDEX["position_motor_share"]] = 0.25
    modes = np.array([1, 0, 0, 0, 1])  # two-mass full-closed backlash, sampled controller
    x = simulate_augmented(x_r, x_r, Ts, THETA, flags=np.array([1, 0, 0, 0, 0, 0]), ep=ep, modes=modes)
    x = x + np.random.default_rng(0).normal(0.0, 2e-4, x.size)
    chunk = make_chunk(x_r, x, Ts, segment_starts(x_r.size, None))
    start = ModelSpec(THETA.copy(), ("backlash",), ep.copy())
    start.modes[: modes.size] = modes
    start.ep[EP_INDEX["position_motor_share"]] = 0.85
    return chunk, start


def _held_psi(spec: ModelSpec) -> ModelSpec:
    held = spec.copy()
    psi = float(spec.ep[EP_INDEX["position_motor_share"]])
    held.ranges["position_motor_share"] = (psi, psi)  # a parameter in ranges is held
    return held


def test_a_full_closed_gap_is_sized_with_the_position_terms_motor_share_fitted_beside_it():
    # the gap trades with ψ: held at the start's reading the fit sizes the gap about half;
    # fitted beside it, ψ moves to the drive's and the gap comes within 25 %
    chunk, start = _full_closed_gap()
    held = fit_spec(_held_psi(start), chunk, cfg=DEFAULT)
    assert held.ep[EP_INDEX["gap_mm"]] < 0.75 * 0.02
    fitted = fit_spec(start, chunk, cfg=DEFAULT)
    assert abs(fitted.ep[EP_INDEX["position_motor_share"]] - 0.25) < 0.5 * abs(0.85 - 0.25)
    assert fitted.ep[EP_INDEX["gap_mm"]] == pytest.approx(0.02, rel=0.25)


def test_the_profile_over_the_gap_moves_a_gap_left_short_to_the_cheaper_point():
    # a fit that stopped short of the gap (here held there by ψ): the accepted model's
    # profile over the gap (candidates.profile_gap) must size it within 25 % at lower cost
    from ident.diagnosis.candidates import profile_gap

    chunk, start = _full_closed_gap()
    short = fit_spec(_held_psi(start), chunk, cfg=DEFAULT).released()
    profiled = profile_gap(short, chunk, DEFAULT)
    assert profiled.ep[EP_INDEX["gap_mm"]] == pytest.approx(0.02, rel=0.25)
    assert sse(profiled, chunk) < sse(short, chunk)


@pytest.mark.parametrize("start_gap_mm", [0.014, 0.026])
def test_the_accepted_models_estimate_is_a_stationary_point_of_its_cost(start_gap_mm):
    # the re-estimation (candidates.segment_variance_fit) ends with exact slopes: at its end
    # every parameter's sensitivity is orthogonal to the residual (the first-order condition
    # of least squares, the cosine MINPACK's gtol bounds); difference steps stopped at a
    # cosine of 1e-3 on this drive, the gap already right
    from ident.diagnosis.candidates import segment_variance_fit
    from ident.diagnosis.spec import residual, residual_jacobian

    chunk, start = _full_closed_gap()
    start.ep[EP_INDEX["gap_mm"]] = start_gap_mm
    start.ep[EP_INDEX["position_motor_share"]] = 0.25
    fitted = segment_variance_fit(start, chunk, DEFAULT)
    names = ("gap_mm", "position_motor_share", "motor_fraction")
    d_theta, d_ep = np.zeros((8 + len(names), 8)), np.zeros((8 + len(names), N_EP))
    d_theta[np.arange(8), np.arange(8)] = np.abs(fitted.theta)
    for j, name in enumerate(names):
        d_ep[8 + j, EP_INDEX[name]] = abs(fitted.ep[EP_INDEX[name]])
    J, r = residual_jacobian(fitted, chunk, d_theta, d_ep), residual(fitted, chunk)
    cosines = np.abs(J @ r) / (np.linalg.norm(J, axis=1) * np.linalg.norm(r))
    assert cosines.max() < 1e-4
    assert fitted.ep[EP_INDEX["gap_mm"]] == pytest.approx(0.02, rel=0.05)


def test_the_search_finds_a_gap_the_base_model_has_absorbed(x_r):
    # the search starts from a base identified without the gap, which has taken part of
    # it up (Coulomb offset, integral gain): base and gap must move back together
    from ident.diagnosis.candidates import search
    from ident.diagnosis.diagnose import fit_base

    ep = np.zeros(N_EP)
    ep[EP_INDEX["gap_mm"]] = 0.02
    ep[EP_INDEX["motor_fraction"]] = 0.85
    modes = np.array([1, 0, 0, 0, 1])  # two-mass drive across the gap, sampled controller
    x = simulate_augmented(x_r, x_r, Ts, THETA_PID, flags=np.array([1, 0, 0, 0, 0, 0]), ep=ep, modes=modes)
    x = x + np.random.default_rng(1).normal(0.0, 2e-4, x.size)
    chunk = make_chunk(x_r, x, Ts, segment_starts(x_r.size, None))
    start = ModelSpec(THETA_PID.copy())
    start.modes[4] = 1
    base = fit_base(start, chunk, cfg=DEFAULT)
    fitted = search(base, "backlash", chunk, {}, DEFAULT)
    assert fitted.ep[EP_INDEX["gap_mm"]] == pytest.approx(0.02, rel=0.25)
    assert sse(fitted, chunk) < 0.5 * sse(base, chunk)


def test_the_race_of_a_long_recording_fits_no_more_than_race_seconds_of_it(x_r, monkeypatch):
    # a ranking needs a number of moves, not a share of the recording: the race's rounds
    # fit (¼, ½, 1) of race_seconds, and only the winner's polish sees every sample
    from dataclasses import replace

    import ident.diagnosis.candidates as cand
    from ident.diagnosis.config import DEFAULT

    ep = np.zeros(N_EP)
    ep[EP_INDEX["gap_mm"]] = 0.02
    x = simulate_augmented(x_r, x_r, Ts, THETA_PID, flags=np.array([1, 0, 0, 0, 0, 0]), ep=ep)
    chunk = make_chunk(x_r, x, Ts, segment_starts(x_r.size, None))
    cap_s = 0.3 * x_r.size * Ts
    sizes = []
    fit = cand.fit_spec
    monkeypatch.setattr(cand, "fit_spec", lambda spec, ch, **kw: sizes.append(ch.n) or fit(spec, ch, **kw))
    cand.search(ModelSpec(THETA_PID.copy()), "backlash", chunk, {}, replace(DEFAULT, race_seconds=cap_s))
    race, polish = sizes[:-1], sizes[-1]
    assert polish == x_r.size
    # every round's windows hold its share of race_seconds, plus each window's lead-in
    # (at most 2 × race_lead_s before its first scored sample)
    for frac, n in zip(DEFAULT.race_fidelity, sorted(set(race))):
        m = max(1, round(frac * cap_s / DEFAULT.race_window_s))
        assert frac * cap_s / Ts - 2 <= n <= frac * cap_s / Ts + m * 2 * DEFAULT.race_lead_s / Ts + 1


# the P-PI drive above with full velocity and acceleration feed-forward (b0 = 1, b1 = a1,
# b2 = a2): the feed-forward reads the command's derivatives, so how the drive takes them shows
THETA_FF = np.concatenate([THETA[:3], [1.0, THETA[0], THETA[1]], THETA[6:]])


def _backward_differences(x_r: np.ndarray, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    v, a = np.zeros_like(x_r), np.zeros_like(x_r)
    bounds = np.append(np.flatnonzero(starts), x_r.size)
    for s, e in zip(bounds[:-1], bounds[1:]):
        v[s + 1:e] = np.diff(x_r[s:e]) / Ts
        a[s + 1:e] = np.diff(v[s:e]) / Ts
    return v, a


def test_the_causal_feed_forward_is_the_sampled_law_fed_backward_differences(x_r):
    starts = segment_starts(x_r.size, (np.arange(x_r.size) > x_r.size // 2).astype(int))
    causal = simulate_augmented(x_r, x_r, Ts, THETA_FF, modes=np.array([0, 0, 0, 0, 2]), starts=starts)
    fed = simulate_augmented(x_r, x_r, Ts, THETA_FF, modes=np.array([0, 0, 0, 0, 1]), starts=starts,
                             derivs=_backward_differences(x_r, starts))
    ahead = simulate_augmented(x_r, x_r, Ts, THETA_FF, modes=np.array([0, 0, 0, 0, 1]), starts=starts)
    np.testing.assert_allclose(causal, fed, rtol=0, atol=1e-12)
    # half a sample late in velocity, a sample in acceleration: a tracking error of its own
    assert np.max(np.abs(causal - ahead)) > 0.1 * np.max(np.abs(x_r - ahead))


def test_the_base_model_takes_the_control_law_the_drive_uses(x_r):
    from ident.diagnosis.candidates import base_variants

    x = simulate_augmented(x_r, x_r, Ts, THETA_FF, modes=np.array([0, 0, 0, 0, 2]))
    chunk = make_chunk(x_r, x, Ts, segment_starts(x_r.size, None))
    start = ModelSpec(THETA_FF * np.array([1.1, 0.9, 1.2, 1.0, 1.1, 0.9, 1.0, 1.0]))
    variants = base_variants(start, chunk, cfg=DEFAULT)
    assert [int(v.modes[4]) for v in sorted(variants, key=lambda v: v.modes[4])] == [0, 1, 2]
    assert variants[0].modes[4] == 2
    assert sse(variants[0], chunk) < 0.5 * sse(variants[1], chunk)


def test_the_position_gains_parametrisation_is_one_of_three_named_settings():
    from ident.diagnosis.config import DEFAULT, DiagnosisConfig

    assert DEFAULT.fit_beta == "all"
    with pytest.raises(ValueError, match="fit_beta"):
        DiagnosisConfig(fit_beta=True)


def test_reweighting_by_segment_gives_every_segment_the_weight_of_its_own_residual_variance():
    # two segments, the model's residual 1 µm rms in the first and 10 µm in the second:
    # weights σ/σ_seg, so each segment's weighted residual has the same rms (the
    # Gaussian likelihood with a variance per segment), the restart transients unscored
    n = 2000
    starts = np.zeros(n, dtype=bool)
    starts[[0, 1000]] = True
    x_r = np.linspace(0.0, 10.0, n)
    chunk = make_chunk(x_r, x_r, Ts, starts)
    rng = np.random.default_rng(1)
    r = np.concatenate([1e-3 * rng.standard_normal(1000), 1e-2 * rng.standard_normal(1000)])
    w = chunk.reweighted(r).w
    assert np.all(w[:1000] == w[0]) and np.all(w[1000:] == w[1000])
    sc = chunk.score
    a, b = (w * r)[:1000][sc[:1000]], (w * r)[1000:][sc[1000:]]
    assert np.sqrt(np.mean(a ** 2)) == pytest.approx(np.sqrt(np.mean(b ** 2)), rel=1e-9)
    assert w[0] / w[1000] == pytest.approx(10.0, rel=0.1)

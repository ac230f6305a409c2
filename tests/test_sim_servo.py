"""The servo loop: linear response = eq. 3.3, integration converges, encoder, seeds, bad input."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import signal

from core.errors import InputError
from virtual_cnc.drive import Encoder, closed_loop_parameters
from virtual_cnc.effects import Backlash, Resonance, Stribeck
from virtual_cnc.presets import load_machine
from virtual_cnc.servo import simulate_axis, simulate_axis_response, simulate_machine

import _moves

TS = 0.001


def point_to_point(targets, a_max=2000.0, v_max=200.0, dwell=0.03, x0=0.0):
    """The shared exact-stop command (tests/_moves.py) with this module's shorter dwell."""
    return _moves.point_to_point(targets, a_max=a_max, v_max=v_max, dwell=dwell, x0=x0)


def ideal(axis):
    """The axis without friction, quantisation or noise: the linear model of eq. 3.3."""
    return replace(axis, plant=replace(axis.plant, d_plus=0.0, d_minus=0.0), encoder=Encoder(), dac_resolution=0.0)


@pytest.mark.parametrize("preset", ["fadal-ppi", "fadal-pid", "fadal-smc"])
def test_linear_response_matches_the_continuous_closed_loop_of_eq_3_3(preset):
    axis = ideal(load_machine(preset).axes["X"])
    t = np.arange(3000) * TS
    x_r = 5.0 * (1 - np.cos(2 * np.pi * 2.0 * t))  # smooth, up to 63 mm/s and 790 mm/s²
    p = closed_loop_parameters(axis)
    # G_track of eq. 3.1 multiplied through by s
    num = np.trim_zeros([p["b0"], p["b1"], p["b2"], p["a3"]], "f")  # b0 = b1 = 0 for P-PI
    g_track = signal.lti(num, [1.0, p["a1"], p["a2"], p["a3"]])
    _, x_model, _ = signal.lsim(g_track, x_r, t)
    x_sim = simulate_axis(x_r, axis)
    diff = np.max(np.abs(x_sim - x_model))
    # the digital loop (ZOH, difference quotients at 1 ms) differs from the continuous model by
    # much less than one servo period of motion ...
    assert diff < 0.25 * TS * np.max(np.abs(np.gradient(x_r, TS)))
    # ... and, where the tracking error is large (P-PI), by under 2 % of it
    if preset == "fadal-ppi":
        assert diff < 0.02 * np.max(np.abs(x_r - x_model))


def test_ppi_follows_a_ramp_with_the_velocity_error_of_eq_3_3():
    axis = ideal(load_machine("fadal-ppi").axes["X"])
    t = np.arange(3000) * TS
    x = simulate_axis(50.0 * t, axis)
    p = closed_loop_parameters(axis)
    # final-value theorem on eq. 3.3: e_ss = v (a2 - b2) / a3 = v / Kp
    assert (50.0 * t - x)[-1] == pytest.approx(50.0 * (p["a2"] - p["b2"]) / p["a3"], rel=0.01)


@pytest.mark.parametrize("preset", ["fadal-ppi", "fadal-pid"])
def test_halving_the_integration_step_changes_a_drive_with_friction_and_a_100hz_mode_negligibly(preset):
    axis = replace(load_machine(preset).axes["X"], encoder=Encoder(), dac_resolution=0.0)
    rng = np.random.default_rng(3)
    # tiny moves (many friction reversals) then larger ones
    x_r = point_to_point(list(np.cumsum(rng.uniform(-0.05, 0.05, 10))) + list(rng.uniform(-5, 5, 4)))
    effects = [Resonance(freq_hz=100.0, damping=0.05), Stribeck(1.5, 1.0)]
    x20 = simulate_axis(x_r, replace(axis, substeps=20), effects)
    x40 = simulate_axis(x_r, replace(axis, substeps=40), effects)
    assert np.abs(x_r - x20).max() > 0.05  # the response is not trivial
    # tolerance: 0.01 µm, a tenth of the presets' encoder resolution
    assert np.abs(x20 - x40).max() < 1e-5


def test_rigid_drive_with_coulomb_friction_converges_with_the_step():
    axis = replace(load_machine("fadal-ppi").axes["X"], encoder=Encoder(), dac_resolution=0.0)
    x_r = point_to_point([0.02, -0.01, 0.03, -3.0, 2.0])
    x = {n: simulate_axis(x_r, replace(axis, substeps=n)) for n in (10, 20, 40)}
    assert np.abs(x[20] - x[40]).max() < 1e-8
    assert np.abs(x[10] - x[20]).max() < 1e-8


def test_friction_holds_the_axis_still_at_rest_without_chattering():
    axis = replace(load_machine("fadal-ppi").axes["X"], encoder=Encoder(), dac_resolution=0.0)
    x_r = np.concatenate([point_to_point([0.5]), np.full(1500, 0.5)])
    r = simulate_axis_response(x_r, axis, [Stribeck(2.0, 1.0)])
    tail = r.table[-500:]
    # held at rest: the integrator settles u at the breakaway force, motion stays at round-off level
    assert np.abs(np.diff(tail)).sum() < 1e-9
    assert abs(tail[-1] - 0.5) < 0.005


def test_encoder_quantises_the_reading_and_adds_noise():
    base = load_machine("fadal-pid").axes["X"]
    x_r = point_to_point([1.0, -2.0])
    r = simulate_axis_response(x_r, replace(base, encoder=Encoder(resolution=0.001)))
    assert np.allclose(r.actual / 0.001, np.round(r.actual / 0.001), atol=1e-6)
    assert np.abs(r.actual - r.table).max() <= 0.0005 + 1e-12
    noisy = simulate_axis_response(np.zeros(4000), replace(base, encoder=Encoder(noise_std=0.002)),
                                   rng=np.random.default_rng(7))
    assert np.std(noisy.actual - noisy.table) == pytest.approx(0.002, rel=0.1)


def test_actuator_command_is_held_within_the_limit_and_dac_steps():
    axis = load_machine("fadal-ppi").axes["X"]
    r = simulate_axis_response(point_to_point([8.0, -8.0]), axis)
    step = axis.dac_resolution
    assert np.abs(r.u).max() <= axis.plant.u_max
    assert np.allclose(r.u / step, np.round(r.u / step))


def test_machine_simulation_is_reproducible_per_seed_and_axis():
    m = load_machine("fadal-ppi")
    cmd = {"X": point_to_point([2.0]), "Y": point_to_point([-1.0])}
    a = simulate_machine(cmd, m, seed=5)
    b = simulate_machine(cmd, m, seed=5)
    c = simulate_machine(cmd, m, seed=6)
    only_y = simulate_machine({"Y": cmd["Y"]}, m, seed=5)
    assert np.array_equal(a["X"], b["X"]) and np.array_equal(a["Y"], b["Y"])
    assert not np.array_equal(a["X"], c["X"])
    assert np.array_equal(a["Y"], only_y["Y"])


def test_effect_for_one_axis_leaves_the_other_alone():
    m = load_machine("fadal-ppi")
    cmd = {"X": point_to_point([0.5, -0.5]), "Y": point_to_point([0.5, -0.5])}
    plain = simulate_machine(cmd, m, seed=1)
    with_x = simulate_machine(cmd, m, [Backlash(gap_mm=0.02, axis="X")], seed=1)
    assert np.array_equal(plain["Y"], with_x["Y"])
    assert np.abs(plain["X"] - with_x["X"]).max() > 0.005


@pytest.mark.parametrize(
    "call,match",
    [
        (lambda m: simulate_machine({"Z": np.zeros(10)}, m), r"axis 'Z' is not on machine 'fadal-ppi' \(axes: X, Y\)"),
        (lambda m: simulate_machine({"X": np.zeros(10)}, m, [Backlash(0.01, axis="A")]), r"names axis 'A'"),
        (lambda m: simulate_axis(np.array([0.0, np.nan]), m.axes["X"]), r"not finite at sample 1"),
        (lambda m: simulate_axis(np.zeros((3, 2)), m.axes["X"]), r"1-D array"),
        (lambda m: simulate_axis(np.zeros(5), m.axes["X"], [Backlash(0.01), Backlash(0.02)]), r"given twice"),
        (lambda m: simulate_axis(np.zeros(5), m.axes["X"], [Resonance(freq_hz=3000.0)]),
         r"mode at 3000 Hz is too fast for the plant step 5e-05 s; use at least 30 substeps"),
    ],
)
def test_bad_simulation_input_is_a_one_line_error(call, match):
    with pytest.raises(InputError, match=match):
        call(load_machine("fadal-ppi"))

"""A resonance's mode is stepped exactly where the kernel can: its frequency sets no sub-step.

* A two-mass mode under the sampled controller (kernel._two_mass_step): the controller's
  output is held over the sample, so between samples the drive is linear but for the
  table's friction — the centre of mass a double integrator, the deflection the free-free
  mode, both advanced by their flows; the table's reversals and breakaways are located
  inside the sub-step.
* The filter of mode 0 on the recorded position on the continuous controller's exact step:
  driven by the mass's mean acceleration over each sub-step, advanced by its flow.

The runs therefore hardly depend on how finely the sample is cut.  A two-mass mode under the
continuous controller takes kick-and-drift sub-steps, second order.
"""

from __future__ import annotations

import numpy as np
import pytest

from ident.diagnosis.augmented import EFFECTS, EP_INDEX, N_EP, model_substeps, simulate_augmented
from tests.test_diagnosis_lockstep import THETA, _chunk

#: A gravity-loaded axis: the table's stick band [d1, d0] does not hold zero.
FRICTION = {"symmetric": (150.0, -150.0), "gravity loaded": (400.0, 80.0)}


def _run(freq_hz: float, mode: int, controller: int, nsub: int, friction=(150.0, -150.0), stribeck: bool = False):
    """The run (and the rigid drive's) on two segments from rest, and on windows of them restarted mid-move."""
    return tuple(np.concatenate(pair) for pair in zip(*(_one(ch, freq_hz, mode, controller, nsub, friction, stribeck)
                                                        for ch in _chunk())))


def _one(ch, freq_hz, mode, controller, nsub, friction, stribeck):
    theta = np.array(THETA, dtype=float)
    theta[6], theta[7] = friction
    flags = np.zeros(len(EFFECTS), dtype=np.int64)
    flags[EFFECTS.index("resonance")] = 1
    ep = np.zeros(N_EP)
    ep[EP_INDEX["freq_hz"]], ep[EP_INDEX["damping"]], ep[EP_INDEX["motor_fraction"]] = freq_hz, 0.03, 0.6
    if stribeck:
        flags[EFFECTS.index("stribeck")] = 1
        ep[EP_INDEX["static_to_coulomb_ratio"]], ep[EP_INDEX["stribeck_velocity_mm_s"]] = 2.0, 1.0
    modes = np.array([0, 0, 0, mode, controller, 0])
    run = dict(starts=ch.starts, derivs=ch.derivs, warm=ch.warm, nsub=nsub)
    y = simulate_augmented(ch.x_r, ch.x, ch.Ts, theta, flags=flags, ep=ep, modes=modes, **run)
    flags[EFFECTS.index("resonance")] = 0
    rigid = simulate_augmented(ch.x_r, ch.x, ch.Ts, theta, flags=flags, ep=ep, modes=modes, **run)
    return y, rigid


@pytest.mark.parametrize("friction", FRICTION.values(), ids=FRICTION.keys())
@pytest.mark.parametrize("mode", [1, 2, 3])
@pytest.mark.parametrize("freq_hz", [80.0, 150.0])
def test_two_sub_steps_a_sample_give_the_run_of_sixty_four(freq_hz, mode, friction):
    """Within 2 % of what the mode changes."""
    coarse, rigid = _run(freq_hz, mode, 1, 2, friction)
    fine, _ = _run(freq_hz, mode, 1, 64, friction)
    effect = np.sqrt(np.mean((fine - rigid) ** 2))
    assert effect > 1e-4  # the mode shows (mm)
    assert np.sqrt(np.mean((coarse - fine) ** 2)) < 2e-2 * effect


@pytest.mark.parametrize("mode", [1, 2, 3])
def test_under_the_continuous_controller_a_two_mass_mode_is_second_order_in_the_sub_step(mode):
    """Kick and drift with every force read at the kick's instant (the velocities a half
    step on by the last kick, the command's acceleration linear between samples, the
    integral by the midpoint, a half kick after a restart): the error quarters as the
    sub-steps double."""
    fine, rigid = _run(80.0, mode, 0, 512, FRICTION["gravity loaded"])
    err = {n: np.sqrt(np.mean((_run(80.0, mode, 0, n, FRICTION["gravity loaded"])[0] - fine) ** 2))
           for n in (4, 8, 16)}
    assert 3.2 < err[4] / err[8] < 4.8 and 3.2 < err[8] / err[16] < 4.8
    assert err[16] < 1e-2 * np.sqrt(np.mean((fine - rigid) ** 2))


def test_a_stribeck_curve_on_the_table_is_first_order_in_the_sub_step():
    """The friction level is held at each phase's starting speed (as on the single mass):
    the error halves as the sub-steps double, the mode itself adds none."""
    fine, rigid = _run(60.0, 3, 2, 256, FRICTION["gravity loaded"], stribeck=True)
    effect = np.sqrt(np.mean((fine - rigid) ** 2))
    err = {n: np.sqrt(np.mean((_run(60.0, 3, 2, n, FRICTION["gravity loaded"], stribeck=True)[0] - fine) ** 2))
           for n in (2, 4, 8)}
    assert 1.6 < err[2] / err[4] < 2.4 and 1.6 < err[4] / err[8] < 2.4
    assert err[8] < 2e-2 * effect


@pytest.mark.parametrize("freq_hz", [40.0, 150.0, 300.0])
def test_the_filter_of_mode_0_at_two_sub_steps_is_the_run_of_sixty_four(freq_hz):
    """Within 4 % of what the filter adds."""
    ch, _ = _chunk()
    theta = np.array(THETA, dtype=float)
    theta[6], theta[7] = FRICTION["gravity loaded"]
    flags = np.zeros(len(EFFECTS), dtype=np.int64)
    flags[EFFECTS.index("resonance")] = 1
    ep = np.zeros(N_EP)
    ep[EP_INDEX["freq_hz"]], ep[EP_INDEX["damping"]], ep[EP_INDEX["gain"]] = freq_hz, 0.03, 0.5
    run = dict(ep=ep, modes=np.zeros(6, dtype=np.int64), starts=ch.starts, derivs=ch.derivs)
    coarse = simulate_augmented(ch.x_r, ch.x, ch.Ts, theta, flags=flags, nsub=2, **run)
    fine = simulate_augmented(ch.x_r, ch.x, ch.Ts, theta, flags=flags, nsub=64, **run)
    rigid = simulate_augmented(ch.x_r, ch.x, ch.Ts, theta, nsub=64, **run)
    assert np.sqrt(np.mean((coarse - fine) ** 2)) < 4e-2 * np.sqrt(np.mean((fine - rigid) ** 2))


@pytest.mark.parametrize("mode, controller, exact", [(3, 1, True), (3, 2, True), (0, 0, True),
                                                     (3, 0, False), (0, 1, False)])
def test_a_mode_stepped_exactly_sets_no_sub_step(mode, controller, exact):
    theta = np.array(THETA, dtype=float)
    flags = np.zeros(len(EFFECTS), dtype=np.int64)
    flags[EFFECTS.index("resonance")] = 1
    ep = np.zeros(N_EP)
    ep[EP_INDEX["motor_fraction"]] = 0.6
    steps = {}
    for f in (40.0, 300.0):
        ep[EP_INDEX["freq_hz"]] = f
        steps[f] = model_substeps(theta, 1e-3, flags, ep, np.array([0, 0, 0, mode, controller, 0]))
    # the others (a two-mass mode on the continuous controller, the filter on the sampled
    # one) take Euler's step, whose sub-step the mode's frequency sets
    assert (steps[40.0] == steps[300.0]) == exact

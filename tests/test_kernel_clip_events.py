"""A saturation on the kernel's exact step (single mass, continuous controller) locates the clip's
onset and release, and the integral's freeze with them, inside the sub-step, as the friction's
reversal and breakaway are located: the free run is continuous in the parameters, so its
complex-step derivative is the slope of the run's trend, the same as a central difference over
a step far wider than a sub-step's switch would show.  Stepped with the clip decided at each
sub-step's start (and held over it), the run jumps wherever a parameter moves a switch across a
sub-step boundary and the complex-step derivative misses every jump."""

from __future__ import annotations

import numpy as np
import pytest

from ident.diagnosis.augmented import EP_INDEX, N_EP, segment_starts, sensitivities, simulate_augmented
from ident.diagnosis.spec import ModelSpec, make_chunk, sim_substeps
from tests.test_diagnosis_units import point_to_point

TS = 1e-3
#: A PID drive with velocity feed-forward (the fadal-pid preset's loop), eq. 3.3 parameters.
THETA = np.array([192.65, 44356.0, 316830.0, 0.0, 190.1, 44356.0, 441.0, -302.0])
#: Limits the loop's output runs into at every start and stop of the 2000 mm/s² point-to-point
#: moves (their friction and the loop's transients on top of the acceleration).
CLIPS = {
    "anti-windup": ({"limit": 2800.0}, 0),
    "no anti-windup": ({"limit": 2800.0}, 1),
    "falling with speed": ({"limit": 3000.0, "limit_slope": 5.0}, 0),
    "psi-share": ({"limit": 2800.0, "position_motor_share": 0.5}, 0),
}


def _run(spec, chunk, u=None):
    return simulate_augmented(chunk.x_r, chunk.x, chunk.Ts, spec.theta, flags=spec.flags(), ep=spec.ep,
                              modes=spec.modes, starts=chunk.starts, derivs=chunk.derivs,
                              nsub=sim_substeps(spec, chunk.Ts), u_out=u)


def _case(name):
    params, variant = CLIPS[name]
    x_r = point_to_point(3)
    chunk = make_chunk(x_r, x_r, TS, segment_starts(x_r.size, None))
    return ModelSpec(THETA.copy()).with_effect("saturation", params, variant), chunk


@pytest.mark.parametrize("name", list(CLIPS))
@pytest.mark.parametrize("parameter", ["limit", "limit_slope"])
def test_the_saturated_free_runs_exact_derivative_is_its_slope_over_a_wide_step(name, parameter):
    spec, chunk = _case(name)
    j = EP_INDEX[parameter]
    u = np.empty(chunk.n)
    _run(spec, chunk, u)
    lim, slope = spec.ep[EP_INDEX["limit"]], spec.ep[EP_INDEX["limit_slope"]]
    v = np.gradient(_run(spec, chunk), TS)
    assert np.sum(np.abs(u + slope * v) >= lim - 1e-6) >= 5  # the clip bites (at the samples' starts)
    d_ep = np.zeros((1, N_EP))
    d_ep[0, j] = 1.0
    exact = sensitivities(chunk.x_r, chunk.x, chunk.Ts, spec.theta, spec.ep, np.zeros((1, 8)), d_ep,
                          flags=spec.flags(), modes=spec.modes, starts=chunk.starts, derivs=chunk.derivs,
                          nsub=sim_substeps(spec, chunk.Ts))[0]
    # a step of 0.1 % of the limit (0.1 /s of the slope) moves every switch across many sub-steps
    delta = 3e-4 * (lim if parameter == "limit" else 100.0)
    runs = []
    for sign in (1.0, -1.0):
        s = spec.copy()
        s.ep[j] += sign * delta
        runs.append(_run(s, chunk))
    central = (runs[0] - runs[1]) / (2.0 * delta)
    assert np.linalg.norm(central) > 0.0
    assert np.linalg.norm(exact - central) <= 0.05 * np.linalg.norm(central)


@pytest.mark.parametrize("name", ["anti-windup", "no anti-windup"])
def test_a_small_change_of_the_limit_moves_the_free_run_by_as_little(name):
    """Lipschitz in the limit: over 200 limits 0.01 mm/s² apart no neighbours differ by more
    than a few times the run's median change per step (a jump of a switch crossing a sub-step
    boundary is many times it)."""
    spec, chunk = _case(name)
    j = EP_INDEX["limit"]
    lim = spec.ep[j]
    prev, steps = None, []
    for i in range(200):
        s = spec.copy()
        s.ep[j] = lim + 0.01 * i
        y = _run(s, chunk)
        if prev is not None:
            steps.append(np.max(np.abs(y - prev)))
        prev = y
    steps = np.array(steps)
    assert steps.max() <= 5.0 * np.median(steps) + 1e-12

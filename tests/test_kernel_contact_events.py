"""The two-mass backlash's contact is resolved inside the sub-step: the free run is continuous
in the gap, and its exact (complex-step) slope is the slope a difference reads.

A contact switched on or off for whole sub-steps moves the run by a jump whenever the gap moves
a contact instant across a sub-step boundary; the exact slope of such a run is that of one step
of its staircase (ident.kernel._contact_push; benchmarks/bench_cost_ripple.py measures the cost).
"""

from __future__ import annotations

import numpy as np
import pytest

from ident.diagnosis.augmented import EP_INDEX, N_EP, segment_starts, sensitivities
from ident.diagnosis.spec import ModelSpec, make_chunk, sim_substeps, simulate_spec
from tests.test_diagnosis_units import point_to_point

TS = 1e-3
#: A PID drive with velocity feed-forward (benchmarks/bench_cost_ripple.py's), eq. 3.3.
THETA = np.array([192.65, 44356.0, 316830.0, 0.0, 190.1, 44356.0, 441.0, -302.0])
GAP = 0.06
G = EP_INDEX["gap_mm"]


def _two_mass(controller: int):
    """A full-closed loop across a 60 µm gap (backlash mode 1) on three point-to-point moves."""
    spec = ModelSpec(THETA.copy()).with_effect("backlash", {"gap_mm": GAP, "motor_fraction": 0.75}, 1)
    spec.modes[4] = controller
    x_r = point_to_point(3)
    return spec, make_chunk(x_r, x_r, TS, segment_starts(x_r.size, None))


def _run(spec: ModelSpec, chunk, gap: float) -> np.ndarray:
    s = spec.copy()
    s.ep[G] = gap
    return simulate_spec(s, chunk)


def _exact_slope(spec: ModelSpec, chunk) -> np.ndarray:
    d_ep = np.zeros((1, N_EP))
    d_ep[0, G] = 1.0
    return sensitivities(chunk.x_r, chunk.x, TS, spec.theta, spec.ep, np.zeros((1, 8)), d_ep,
                         flags=spec.flags(), modes=spec.modes, starts=chunk.starts, derivs=chunk.derivs,
                         nsub=sim_substeps(spec, TS), warm=chunk.warm)[0]


@pytest.mark.parametrize("controller", [0, 1], ids=["continuous", "sampled"])
def test_the_two_mass_free_run_moves_with_the_gap_by_the_change_of_the_gap(controller):
    spec, chunk = _two_mass(controller)
    y = _run(spec, chunk, GAP)
    for d in (1e-8, 1e-7):
        # a table that moves tens of times the change of the gap is a contact switched
        # on a sub-step grid, not the physics
        assert np.abs(_run(spec, chunk, GAP + d) - y).max() < 20.0 * d


@pytest.mark.parametrize("controller", [0, 1], ids=["continuous", "sampled"])
def test_the_exact_slope_of_the_two_mass_run_in_the_gap_is_the_slope_a_difference_reads(controller):
    spec, chunk = _two_mass(controller)
    exact = _exact_slope(spec, chunk)

    def central(rel: float) -> np.ndarray:
        d = rel * GAP
        return (_run(spec, chunk, GAP + d) - _run(spec, chunk, GAP - d)) / (2.0 * d)

    def off(c: np.ndarray) -> float:
        return float(np.linalg.norm(exact - c) / np.linalg.norm(c))

    # Contact instants crossing sub-step boundaries and the table's stick leave kinks in
    # the run, not jumps: at 6 nm and at 1 % of the gap (0.6 µm) the difference reads the
    # exact slope to 16 % and 66 %.  A contact switched for whole sub-steps is 2-3 times
    # off at 6 nm and 30-60 times at 0.6 µm: its exact slope is a stair's.
    assert off(central(1e-4)) < 0.5
    assert off(central(1e-2)) < 1.0


@pytest.mark.parametrize("mode", [1, 2])
@pytest.mark.parametrize("controller", [0, 1])
def test_the_two_mass_drive_across_a_gap_is_second_order_in_the_sub_step(mode, controller):
    """Kick and drift with the contact's mean push over the kick's span, centred on its
    instant, and the velocities read there: the error quarters as the sub-steps double."""
    spec = ModelSpec(THETA.copy()).with_effect("backlash", {"gap_mm": GAP, "motor_fraction": 0.75}, mode)
    spec.modes[4] = controller
    x_r = point_to_point(3)
    chunk = make_chunk(x_r, x_r, TS, segment_starts(x_r.size, None))
    n0 = sim_substeps(spec, chunk.Ts)
    fine = simulate_spec(spec, chunk, nsub=32 * n0)
    err = {m: np.sqrt(np.mean((simulate_spec(spec, chunk, nsub=m * n0) - fine) ** 2)) for m in (2, 4, 8)}
    assert err[2] / err[4] > 2.8 and err[4] / err[8] > 2.8  # first order would halve it

"""The identified model's free run (:func:`ident.simulation.simulate`) is the saved one
(fixtures/simulation/reference.npz, scripts/make_simulation_reference.py) to 1e-9 of the
tracking error's spread (and to the rounding of positions of a few mm, 1e-11 of the
largest: the saved runs' own discretisation rounds to that): friction that sticks, breaks away and reverses, several segments,
recorded start positions, an external load, one to eight sub-steps, a stiff and a real
(EMPS) model.  Whatever kernel runs it, the simulated identified model stays the one the
exact first-order-hold discretisation gives."""

from __future__ import annotations

import numpy as np
import pytest

from scripts.make_simulation_reference import OUT, runs

REF = np.load(OUT)


@pytest.mark.parametrize("key, y, x_r", list(runs()), ids=lambda v: v if isinstance(v, str) else "")
def test_the_free_run_is_the_saved_one_to_1e9_of_the_tracking_error_spread(key, y, x_r):
    ref = REF[key]
    spread = np.ptp(x_r - ref)
    assert np.max(np.abs(y - ref)) <= 1e-9 * spread + 1e-11 * np.abs(ref).max()

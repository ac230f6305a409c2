"""Fit metric (ident/metrics.py) and output-error refinement (ident/refine.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ident.metrics import FitResult, fit_result, tracking_error_fit_pct, tracking_error_rms
from ident.model import Bounds, DriveModel
from ident.preprocessing import shift_command
from ident.refine import model_fit, refine
from ident.regression import build_regression
from ident.simulation import simulate

TS = 1e-3
WN, ZETA, P = 2 * np.pi * 33, 0.45, 2 * np.pi * 1.17  # thesis Table 4.1
A2 = WN**2 + 2 * P * ZETA * WN
TRUE = DriveModel.from_search(WN, ZETA, P, 1.0, 190.1 / A2, 0.0, 441.0 / A2, -302.0 / A2)


def command(seed=0, n=5000):
    """Smoothed random back-and-forth command, mm."""
    rng = np.random.default_rng(seed)
    v = np.repeat(rng.uniform(-40, 40, n // 250 + 1), 250)[:n]  # mm/s plateaus
    v = np.convolve(v, np.ones(40) / 40, mode="same")
    v[:50] = 0.0
    return np.cumsum(v) * TS


# ---------------------------------------------------------------- metric


def test_fit_metric_of_spec_5():
    e = np.array([1.0, -1.0, 2.0, 0.0])
    assert tracking_error_fit_pct(e, e) == 100.0
    assert tracking_error_fit_pct(e, np.full(4, e.mean())) == pytest.approx(0.0)
    e_hat = e + np.array([0.1, -0.1, 0.0, 0.0])
    expect = 100 * (1 - np.linalg.norm(e - e_hat) / np.linalg.norm(e - e.mean()))
    assert tracking_error_fit_pct(e, e_hat) == pytest.approx(expect)
    assert tracking_error_rms(e, e_hat) == pytest.approx(np.sqrt(0.02 / 4))
    r = fit_result(e, e_hat)
    assert isinstance(r, FitResult)
    assert r.to_dict() == {"tracking_error_fit_pct": r.tracking_error_fit_pct,
                           "tracking_error_rms_mm": r.tracking_error_rms_mm}
    with pytest.raises(ValueError, match="4 samples but e_hat has 3"):
        tracking_error_fit_pct(e, e[:3])


# ---------------------------------------------------------------- refinement


def test_model_fit_is_the_metric_on_the_free_run():
    x_r = command()
    x = simulate(TRUE, shift_command(x_r, 1), TS)
    assert model_fit(TRUE, x_r, x, TS, shift=1).tracking_error_fit_pct == pytest.approx(100.0)
    other = DriveModel.from_search(WN * 1.1, ZETA, P, 1.0, 190.1 / A2, 0.0, 441.0 / A2, -302.0 / A2)
    expect = fit_result(x_r - x, x_r - simulate(other, shift_command(x_r, 1), TS, x0=x))
    assert model_fit(other, x_r, x, TS, shift=1) == expect


@pytest.mark.parametrize("optimizer", ["lm", "trf"])
def test_refinement_recovers_the_free_run_from_a_perturbed_start(optimizer):
    x_r = command(1)
    x = simulate(TRUE, x_r, TS)
    start = DriveModel.from_search(WN * 1.25, ZETA * 0.7, P * 2.0, 0.98, 1.3 * 190.1 / A2, 0.0,
                                   0.6 * 441.0 / A2, 1.4 * -302.0 / A2)
    res = refine(start, x_r, x, TS, max_evals=None, optimizer=optimizer)
    assert res.fit_before.tracking_error_fit_pct < 90.0
    assert res.fit_after.tracking_error_fit_pct > 99.5
    assert res.improved and res.fit_after == model_fit(res.model, x_r, x, TS)
    wn, zeta, p = res.model.search_variables()
    assert wn / (2 * np.pi) == pytest.approx(33, rel=0.05)


def test_refinement_keeps_poles_inside_the_bounds():
    # The truth has a real pole at 0.05 Hz, below p_min = 0.2 Hz: the refined model must
    # stay at the bound and say so.
    slow = DriveModel.from_search(WN, ZETA, 2 * np.pi * 0.05, 1.0, 190.1 / A2, 0.0, 441.0 / A2, -302.0 / A2)
    x_r = command(2)
    x = simulate(slow, x_r, TS)
    bounds = Bounds()
    res = refine(slow, x_r, x, TS, bounds=bounds, regression=build_regression(x_r, x, TS, shift=0),
                 max_evals=None)
    wn, zeta, p = res.model.search_variables(bounds, TS)
    assert p >= bounds.p_min * (1 - 1e-9)
    assert bounds.wn_min <= wn <= bounds.f_max(TS)
    assert bounds.zeta_min <= zeta <= bounds.zeta_max
    assert "p_min" in res.active_constraints
    assert res.fit_before.tracking_error_fit_pct == pytest.approx(100.0)  # the unconstrained truth
    start_fit = model_fit(res.start_model, x_r, x, TS).tracking_error_fit_pct
    assert res.fit_after.tracking_error_fit_pct > max(start_fit, 80.0)  # the price of the bound


def test_unstable_start_is_moved_inside_the_bounds_first():
    x_r = command(3)
    x = simulate(TRUE, x_r, TS)
    unstable = DriveModel(a1=TRUE.a1, a2=TRUE.a2, a3=-500.0, b0=0.0, b1=TRUE.b1, b2=TRUE.b2,
                          d0=TRUE.d0, d1=TRUE.d1)
    res = refine(unstable, x_r, x, TS, max_evals=None)
    assert all(d > 0 for _, d in res.start_model.poles())
    assert all(d > 0 for _, d in res.model.poles())
    assert res.fit_after.tracking_error_fit_pct > 99.0
    assert math.isfinite(res.elapsed_s) and res.nfev > 0


def test_unknown_optimizer_is_an_input_error():
    from core.errors import InputError

    x_r = command(4, n=500)
    with pytest.raises(InputError, match="optimizer must be 'lm' or 'trf'"):
        refine(TRUE, x_r, simulate(TRUE, x_r, TS), TS, optimizer="newton")


def test_the_search_budget_is_a_count_of_simulations_and_the_best_point_is_kept():
    # the budget runs out after 30 simulations, raised from inside the residual in the middle
    # of the optimiser's iterations; a count, not a wall time, so that the result does not
    # depend on the machine or its load: two runs give the same model
    x_r = command(1)
    x = simulate(TRUE, x_r, TS)
    start = DriveModel.from_search(WN * 1.25, ZETA * 0.7, P * 2.0, 0.98, 1.3 * 190.1 / A2, 0.0,
                                   0.6 * 441.0 / A2, 1.4 * -302.0 / A2)
    res = refine(start, x_r, x, TS, max_evals=30)
    assert res.message == "budget of 30 simulations reached"
    assert res.nfev == 30
    assert res.improved
    assert res.fit_after.tracking_error_fit_pct > model_fit(res.start_model, x_r, x, TS).tracking_error_fit_pct
    assert refine(start, x_r, x, TS, max_evals=30).model == res.model

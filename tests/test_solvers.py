"""Least squares (eq. 3.12) and the exact constrained solver (eq. 3.12 under eq. 3.8).

Data: the continuous model of eq. 3.3 simulated on a random point-to-point command
(tests/_synthetic.py), 4 s at 1 kHz, regression columns from positions only with the
central differences of eq. 3.9 and 0.1 um position noise, unless stated otherwise.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from _synthetic import PID_X, PPI_X, build_regression, simulate
from core.errors import IdentificationError, InputError, RapidIdentWarning
from ident.model import Bounds, DriveModel, alphas_from_search
from ident.solvers import ReducedObjective, solve, solve_exact, solve_ls
from ident.solvers.common import cost_eq312
from ident.solvers.exact import kkt_certificate

TS = 1e-3
TWO_PI = 2 * math.pi


@pytest.fixture(scope="module")
def pid_sim():
    return simulate(PID_X, duration=4.0, Ts=TS, seed=3)


@pytest.fixture(scope="module")
def pid_data(pid_sim):
    return build_regression(pid_sim, noise_mm=1e-4, seed=1)


@pytest.fixture(scope="module")
def ppi_data():
    return build_regression(simulate(PPI_X, duration=4.0, Ts=TS, seed=5), noise_mm=1e-4, seed=2)


def brute_force_min(Phi, Y, lo, hi, n=(28, 24, 28)):
    """Independent check: min of eq. 3.12 over a (log wn, zeta, log p) grid, theta_2 by projection.

    theta_2 is eliminated by projecting onto the orthogonal complement of Phi_2 (QR of
    Phi_2 alone), then the cost is summed over all N rows for every grid point.
    """
    Q2, _ = np.linalg.qr(Phi[:, 3:])
    Yt = Y - Q2 @ (Q2.T @ Y)
    P1 = Phi[:, :3] - Q2 @ (Q2.T @ Phi[:, :3])
    W, Z, P = np.meshgrid(np.geomspace(lo[0], hi[0], n[0]), np.linspace(lo[1], hi[1], n[1]),
                          np.geomspace(lo[2], hi[2], n[2]), indexing="ij")
    th1 = np.stack(alphas_from_search(W.ravel(), Z.ravel(), P.ravel()), axis=1)
    best = math.inf
    for i in range(0, th1.shape[0], 2000):
        R = Yt[:, None] - P1 @ th1[i:i + 2000].T
        best = min(best, float(0.5 * np.min(np.einsum("ij,ij->j", R, R))))
    return best


# ---- input checks -------------------------------------------------------------------------
def test_bad_regressions_give_one_line_errors(pid_data):
    Phi, Y = pid_data
    with pytest.raises(InputError, match=r"shape \(N, 8\)"):
        solve_ls(Phi[:, :7], Y)
    with pytest.raises(InputError, match="Y must have shape"):
        solve_ls(Phi, Y[:-1])
    bad = Phi.copy()
    bad[10, 2] = np.nan
    with pytest.raises(InputError, match="-xddot contains NaN"):
        solve_exact(bad, Y, Bounds(), sample_period=TS)
    no_neg = Phi.copy()
    no_neg[:, 7] = 0.0
    with pytest.raises(IdentificationError, match="negative direction"):
        solve_ls(no_neg, Y)
    with pytest.raises(IdentificationError, match="at least 16"):
        solve_ls(Phi[:5], Y[:5])
    with pytest.raises(InputError, match="unknown solver 'lm'"):
        solve("lm", Phi, Y)


def test_exact_needs_an_upper_frequency_bound(pid_data):
    with pytest.raises(InputError, match="upper frequency bound"):
        solve_exact(*pid_data, Bounds())


# ---- least squares ------------------------------------------------------------------------
def test_ls_recovers_true_parameters_when_the_regression_is_exact(pid_sim):
    Phi, Y = build_regression(pid_sim, exact=True)
    res = solve_ls(Phi, Y)
    true = PID_X.theta
    assert res.theta[[0, 1, 2, 3, 4, 6, 7]] == pytest.approx(true[[0, 1, 2, 3, 4, 6, 7]], rel=1e-6)
    assert abs(res.theta[5]) < 1e-9  # b0 = 0
    assert res.cost < 1e-12 and res.solver == "ls"


def test_ls_from_positions_only_recovers_the_dominant_dynamics(pid_data):
    res = solve_ls(*pid_data, Bounds(), sample_period=TS)
    (f1, d1), _, _ = res.model.poles()
    assert f1 == pytest.approx(33.0, rel=0.03) and d1 == pytest.approx(0.447, rel=0.05)
    # the slow real pole (1.17 Hz) is nearly cancelled by a zero and poorly excited in 4 s;
    # what matters, the tracking response, is close over the command's band
    f = np.array([0.5, 2.0, 10.0, 20.0])
    assert np.abs(res.model.freqresp(f)[0] - PID_X.freqresp(f)[0]) == pytest.approx(0.0, abs=0.02)
    assert res.details["violated_constraints"] == []
    assert 1 < res.condition_number < 1e4


def test_ls_warns_when_ill_conditioned(pid_data):
    Phi, Y = pid_data
    Phi = Phi.copy()
    rng = np.random.default_rng(0)
    Phi[:, 4] = Phi[:, 1] * -1.0 + 1e-9 * rng.standard_normal(Phi.shape[0])  # xdot_r ~ xdot
    with pytest.warns(RapidIdentWarning, match="ill-conditioned"):
        res = solve_ls(Phi, Y)
    assert res.condition_number > 1e8


def test_reduced_objective_equals_eq_3_12_and_the_thesis_gram_form(pid_data):
    obj = ReducedObjective(*pid_data)
    v = (np.array([150.0, 210.0, 900.0]), np.array([0.3, 0.45, 1.6]), np.array([3.0, 7.4, 40.0]))
    direct = obj.cost_direct(*v)
    assert obj.cost(*v) == pytest.approx(direct, rel=1e-9)
    assert obj.cost_gram(*v) == pytest.approx(direct, rel=1e-5)  # eq. 4.12 literal: cancellation
    # theta_2 of eq. 4.11 is the least-squares fit of Y - Phi_1 theta_1
    Phi, Y = pid_data
    th = obj.theta(210.0, 0.45, 7.4)
    th2_ref = np.linalg.lstsq(Phi[:, 3:], Y - Phi[:, :3] @ th[:3], rcond=None)[0]
    assert th[3:] == pytest.approx(th2_ref, rel=1e-7, abs=1e-12)


# ---- exact constrained solver --------------------------------------------------------------
def test_exact_equals_ls_when_ls_is_feasible(pid_data):
    ls = solve_ls(*pid_data)
    ex = solve_exact(*pid_data, Bounds(), sample_period=TS)
    assert ex.details["case1"] and ex.details["kkt_case"] == 1
    assert ex.active_constraints == ()
    assert ex.theta == pytest.approx(ls.theta, rel=1e-8)
    assert ex.cost == pytest.approx(ls.cost, rel=1e-10)
    assert ex.details["certificate"]["kkt_ok"]


CASES = [  # bounds that exclude the (true and LS) PID poles: 33 Hz, zeta 0.45, p 1.17 Hz
    (Bounds(zeta_max=0.3), "zeta_max", 9),
    (Bounds(zeta_min=0.8), "zeta_min", 2),
    (Bounds(wn_min_hz=50.0), "wn_min", 3),
    (Bounds(p_min_hz=5.0), "p_min", 5),
    (Bounds(f_max_hz=20.0), "f_max", 1),
]


@pytest.mark.parametrize("bounds,name,case", CASES, ids=[c[1] for c in CASES])
def test_exact_is_inside_bounds_certified_and_beats_a_brute_force_grid(pid_data, bounds, name, case):
    Phi, Y = pid_data
    ex = solve_exact(Phi, Y, bounds, sample_period=TS)
    assert bounds.check(ex.model, sample_period=TS) == []
    assert name in ex.active_constraints
    assert ex.details["kkt_case"] == case
    cert = ex.details["certificate"]
    assert cert["kkt_ok"] and cert["local_ok"] and cert["grid_ok"]
    assert all(m >= 0 for m in cert["multipliers"].values())
    assert ex.cost > solve_ls(Phi, Y).cost  # a binding constraint costs something
    lo, hi = bounds.box(TS)
    assert ex.cost <= brute_force_min(Phi, Y, lo, hi) * (1 + 1e-9)
    assert ex.cost == pytest.approx(cost_eq312(Phi, Y, ex.theta))


def test_exact_finds_real_pole_solutions(pid_data):
    b = Bounds(zeta_min=1.3)
    ex = solve_exact(*pid_data, b, sample_period=TS)
    assert all(d == pytest.approx(1.0) for _, d in ex.model.poles())
    assert b.check(ex.model, sample_period=TS) == []
    assert ex.details["certificate"]["kkt_ok"]
    assert ex.cost <= brute_force_min(*pid_data, *b.box(TS)) * (1 + 1e-9)


def test_exact_on_ppi_with_two_active_constraints(ppi_data):
    b = Bounds(zeta_max=0.5, wn_min_hz=45.0)  # true P-PI pair: 36.3 Hz, zeta 0.75
    ex = solve_exact(*ppi_data, b, sample_period=TS)
    assert b.check(ex.model, sample_period=TS) == []
    assert ex.details["certificate"]["kkt_ok"]
    assert ex.cost <= brute_force_min(*ppi_data, *b.box(TS)) * (1 + 1e-9)


def test_kkt_certificate_rejects_a_point_that_is_not_optimal(pid_data):
    obj = ReducedObjective(*pid_data)
    lo, hi = Bounds().box(TS)
    cert = kkt_certificate(obj, np.array([150.0, 0.6, 20.0]), lo, hi)
    assert not cert["kkt_ok"]
    # a lower bound held with a negative multiplier is not a KKT point either
    cert = kkt_certificate(obj, np.array([lo[0], 0.45, 7.0]), lo, hi)
    assert not cert["kkt_ok"] and cert["multipliers"]["wn_min"] < 0


def test_solve_dispatches_by_name(pid_data):
    res = solve("exact", *pid_data, Bounds(zeta_max=0.3), sample_period=TS)
    assert res.solver == "exact" and isinstance(res.model, DriveModel)
    d = res.to_dict()
    assert d["active_constraints"] == ["zeta_max"] and set(d["theta"]) >= {"alpha_i", "delta_minus"}

"""Exact constrained optimum of thesis eq. 3.12 under eq. 3.8, found numerically and certified.

Problem::

    minimise  f(theta) = 1/2 (Y - Phi theta)^T (Y - Phi theta)                    (eq. 3.12)
    subject to p >= p_min, wn >= wn_min, zeta_min <= zeta <= zeta_max             (eq. 3.8)
               wn <= f_max, p <= f_max  (f_max = Nyquist by default, section 4.2)

where (wn, zeta, p) factorise the characteristic polynomial (eq. 3.7).  The thesis solved
it with Lagrange multipliers, enumerating the 16 Kuhn-Tucker cases of Table 3.1 in a
symbolic toolbox.  Here the same optimum is found numerically:

1. theta_2 = [beta_0 .. delta-] is eliminated by least squares (eq. 4.9): for fixed
   (wn, zeta, p) the denominator theta_1 is fixed (eq. 3.14) and the best theta_2 is linear
   in it, so f becomes the 3-variable reduced cost of eq. 4.12
   (:class:`~ident.solvers.common.ReducedObjective`, independent of N after one pass).
2. Case 1 (no constraint active): if the unconstrained least-squares polynomial has a
   factorisation inside the bounds, it is the optimum.
3. Otherwise a global search: the reduced cost on a dense grid, log-spaced in wn and p,
   linear in zeta (including zeta >= 1, real pole pairs), then a bounded local solve
   (projected Levenberg–Marquardt with the analytic Jacobian, in a fixed order of
   operations: the reduced cost is a 3-residual least-squares problem) from the best
   separated grid points and from the least-squares poles clipped to the box; variables that reach a bound are snapped onto it and the rest re-polished, and a
   real-pole result is re-expressed in the canonical factorisation and refined again (a
   local search can stall on a fold of the (wn, zeta, p) chart, see
   :func:`ident.model.canonical_search`).
4. Certificate: the Kuhn-Tucker conditions at the optimum -- zero gradient of the reduced
   cost along free variables, multipliers of the correct sign (>= 0) on active bounds --
   plus a local probe (no feasible neighbour is lower) and the grid check (no grid point is
   lower).  ``details["certificate"]`` records it; ``details["kkt_case"]`` is the case
   number of Table 3.1 (f_max, absent from the thesis's table, is reported separately).

Global optimality is as good as the grid is dense: the reduced cost is smooth and has few
basins, and the grid (default 121 x 49 x 121 points) resolves them at ~7 % steps in wn and p.
"""

from __future__ import annotations

import math
import time
import warnings
from typing import Any

import numpy as np

from core.errors import IdentificationError, InputError, RapidIdentWarning
from ident.least_squares import bounded_lm
from ident.model import Bounds, DriveModel, canonical_search
from ident.portable_math import exp, geomspace
from ident.solvers.common import ReducedObjective, SolverResult, resolve_box

__all__ = ["solve_exact", "kkt_certificate"]

_NAMES_LOWER = ("wn_min", "zeta_min", "p_min")
_NAMES_UPPER = ("f_max (wn)", "zeta_max", "f_max (p)")


def _to_u(v: np.ndarray) -> np.ndarray:
    """(wn, zeta, p) -> optimisation coordinates (ln wn, zeta, ln p)."""
    v = np.asarray(v, dtype=float)
    return np.array([math.log(v[0]), v[1], math.log(v[2])])


def _from_u(u: np.ndarray) -> np.ndarray:
    return np.array([math.exp(u[0]), u[1], math.exp(u[2])])


def _grid_search(obj: ReducedObjective, lo: np.ndarray, hi: np.ndarray, shape: tuple[int, int, int],
                 n_starts: int) -> tuple[list[np.ndarray], float, int]:
    """Reduced cost on a (log wn, zeta, log p) grid; best ``n_starts`` separated points."""
    n_w, n_z, n_p = shape
    wn = geomspace(lo[0], hi[0], n_w)
    zeta = np.linspace(lo[1], hi[1], n_z)
    p = geomspace(lo[2], hi[2], n_p)
    F = obj.cost(wn[:, None, None], zeta[None, :, None], p[None, None, :])
    flat = F.ravel()
    k = min(flat.size, 20 * n_starts + 200)
    cand = np.argpartition(flat, k - 1)[:k]
    cand = cand[np.argsort(flat[cand])]
    chosen: list[tuple[int, int, int]] = []
    sep = np.array([max(2, n_w // 20), max(2, n_z // 10), max(2, n_p // 20)])
    for c in cand:
        idx = np.unravel_index(c, F.shape)
        if all(np.any(np.abs(np.subtract(idx, o)) > sep) for o in chosen):
            chosen.append(idx)
        if len(chosen) >= n_starts:
            break
    starts = [np.array([wn[i], zeta[j], p[m]]) for i, j, m in chosen]
    return starts, float(flat[cand[0]]), flat.size


def _refine(obj: ReducedObjective, v0: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Bounded local minimisation of the reduced cost from v0; snaps and re-polishes at bounds.

    The local solve is the projected Levenberg–Marquardt of :func:`ident.least_squares.bounded_lm`
    with the analytic Jacobian: its products and solves run in a fixed order, where a
    trust-region method on LAPACK's SVD ended in other last bits under another CPU's BLAS
    kernels — and the output-error refinement amplifies those bits.
    """
    ulo, uhi = _to_u(lo), _to_u(hi)
    u = np.clip(_to_u(v0), ulo, uhi)
    free = np.ones(3, dtype=bool)
    for _ in range(3):
        fixed_u = u.copy()

        def fun(x):
            uu = fixed_u.copy()
            uu[free] = x
            return obj.residual(*_from_u(uu))

        def jac(x, cols):
            uu = fixed_u.copy()
            uu[free] = x
            v = _from_u(uu)
            J = obj.jacobian(*v) * np.array([v[0], 1.0, v[2]])  # chain rule to (ln wn, zeta, ln p)
            return J[:, free][:, cols].T

        if free.any():
            x0 = np.clip(u[free], ulo[free], uhi[free])
            sol = bounded_lm(fun, x0, ulo[free], uhi[free], max_iter=400, ftol=1e-15, ftol_iter=2, xtol=1e-15,
                             jac=jac)
            u[free] = sol.z
        # snap variables that ended (numerically) on a bound; keep the snap only if not worse
        span = uhi - ulo
        near_lo = (u - ulo) <= 1e-6 * span
        near_hi = (uhi - u) <= 1e-6 * span
        snapped = np.where(near_lo, ulo, np.where(near_hi, uhi, u))
        if obj.cost(*_from_u(snapped)) <= obj.cost(*_from_u(u)) * (1 + 1e-12):
            u = snapped
        new_free = ~((u == ulo) | (u == uhi))
        if np.array_equal(new_free, free):
            break
        free = new_free
    return _from_u(u)


def kkt_certificate(obj: ReducedObjective, v: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                    tol: float = 1e-6) -> dict[str, Any]:
    """Kuhn-Tucker check of the reduced cost at v = (wn rad/s, zeta, p rad/s) in the box [lo, hi].

    Stationarity is measured per variable as |dF/du_i| / (|dr/du_i| |r|), the cosine between
    residual and Jacobian column in u = (ln wn, zeta, ln p) (the MINPACK gtol measure); it
    must be <= tol on free variables.  On an active bound the multiplier must be >= 0:
    dF/du_i >= 0 at a lower bound, <= 0 at an upper bound (both with the same tolerance).
    Multipliers are reported in natural units (mm^2 per rad/s, or per unit zeta).
    """
    r = obj.residual(*v)
    J = obj.jacobian(*v)
    g_nat = J.T @ r  # dF/d(wn, zeta, p)
    Ju = J * np.array([v[0], 1.0, v[2]])
    g_u = Ju.T @ r
    rn = float(np.linalg.norm(r))
    scale = np.linalg.norm(Ju, axis=0) * max(rn, 1e-300)
    floor = 1e-13 * np.linalg.norm(Ju, axis=0) * float(np.linalg.norm(obj.M[:, 0]))  # rounding floor
    cos = np.abs(g_u) / np.maximum(scale, 1e-300)
    ok = True
    free_cos = []
    multipliers: dict[str, float] = {}
    at_lo = np.isclose(v, lo, rtol=1e-12, atol=0.0)
    at_hi = np.isclose(v, hi, rtol=1e-12, atol=0.0)
    for i in range(3):
        if at_lo[i]:
            multipliers[_NAMES_LOWER[i]] = float(g_nat[i])
            ok &= bool(g_u[i] >= -(tol * scale[i] + floor[i]))
        elif at_hi[i]:
            multipliers[_NAMES_UPPER[i]] = float(-g_nat[i])
            ok &= bool(-g_u[i] >= -(tol * scale[i] + floor[i]))
        else:
            free_cos.append(float(cos[i]))
            ok &= bool(abs(g_u[i]) <= tol * scale[i] + floor[i])
    return {"kkt_ok": bool(ok), "gradient": g_nat.tolist(), "stationarity_free": free_cos,
            "multipliers": multipliers, "tolerance": tol}


def _local_probe(obj: ReducedObjective, v: np.ndarray, lo: np.ndarray, hi: np.ndarray, seed: int = 0) -> bool:
    """No feasible point in a small neighbourhood of v (steps 1e-5 .. 1e-2 in u) is lower."""
    rng = np.random.default_rng(seed)
    ulo, uhi = _to_u(lo), _to_u(hi)
    u0 = _to_u(v)
    f0 = float(obj.cost(*v))
    dirs = np.vstack([np.eye(3), -np.eye(3), rng.standard_normal((40, 3))])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    U = np.concatenate([np.clip(u0 + h * dirs, ulo, uhi) for h in (1e-5, 1e-4, 1e-3, 1e-2)])
    F = obj.cost(exp(U[:, 0]), U[:, 1], exp(U[:, 2]))
    return bool(np.all(F >= f0 * (1 - 1e-11)))


def _kkt_case(active: tuple[str, ...]) -> int:
    """Case number of thesis Table 3.1 from the active set (f_max ignored)."""
    return 1 + 1 * ("zeta_min" in active) + 2 * ("wn_min" in active) + 4 * ("p_min" in active) \
        + 8 * ("zeta_max" in active)


def solve_exact(Phi: np.ndarray, Y: np.ndarray, bounds: Bounds, *, sample_period: float | None = None,
                grid: tuple[int, int, int] = (121, 49, 121), n_starts: int = 8, kkt_tol: float = 1e-6,
                objective: ReducedObjective | None = None) -> SolverResult:
    """Constrained least-squares optimum of eq. 3.12 under eq. 3.8 (see module docstring).

    Parameters
    ----------
    Phi : ndarray, shape (N, 8)
        Regressor of eq. 3.11.
    Y : ndarray, shape (N,)
        Actual position, mm.
    bounds : Bounds
        Pole constraints (Hz); ``f_max_hz=None`` needs ``sample_period``.
    sample_period : float, optional
        T_s in s; sets the upper frequency bound to Nyquist 1/(2 T_s) when f_max_hz is None.
    grid : (n_wn, n_zeta, n_p)
        Global-search grid size (log-spaced wn and p, linear zeta).
    n_starts : int
        Number of separated grid minima refined locally.
    kkt_tol : float
        Stationarity tolerance of the certificate (cosine measure, see :func:`kkt_certificate`).
    objective : ReducedObjective, optional
        Reuse precomputed matrices of eq. 4.12 (e.g. when running several solvers).

    Returns
    -------
    SolverResult
        ``solver="exact"``; details hold ``search_variables`` (Hz), ``certificate``,
        ``kkt_case`` (Table 3.1) and ``case1`` (True when the unconstrained LS was feasible).
    """
    t0 = time.perf_counter()
    if any(int(n) < 2 for n in grid) or n_starts < 1:
        raise InputError(f"exact solver grid must have >= 2 points per axis and n_starts >= 1, got {grid}, {n_starts}")
    lo, hi = resolve_box(bounds, sample_period)
    obj = objective if objective is not None else ReducedObjective(Phi, Y)

    # Case 1: the unconstrained optimum, if some factorisation of its denominator is feasible.
    ls_model = None
    try:
        ls_model = DriveModel.from_theta(obj.theta_ls)
    except IdentificationError:
        pass
    if ls_model is not None:
        v_ls = np.array(ls_model.search_variables(bounds, sample_period))
        if not bounds.violated(*v_ls, sample_period=sample_period):
            cert = kkt_certificate(obj, v_ls, lo, hi, kkt_tol)
            cert.update(local_ok=True, grid_ok=True, case1=True)
            return obj.result(obj.theta_ls, "exact", bounds, sample_period, tuple(v_ls),
                              time.perf_counter() - t0,
                              {"certificate": cert, "kkt_case": 1, "case1": True,
                               "reduced_cost": float(obj.cost(*v_ls))})

    # Global search, then bounded local refinement from several starts.
    starts, grid_best, n_grid = _grid_search(obj, lo, hi, tuple(int(n) for n in grid), n_starts)
    if ls_model is not None:
        for c in ls_model.factorisations():
            if all(math.isfinite(x) and x > 0 for x in c):
                starts.append(np.clip(np.array(c), lo, hi))
    best_v, best_f = None, math.inf
    for v0 in starts:
        v = _refine(obj, v0, lo, hi)
        f = float(obj.cost(*v))
        for _ in range(3):  # leave folds of the real-pole chart (see canonical_search)
            vc = np.array([float(x) for x in canonical_search(*v, lo, hi)])
            if np.allclose(vc, v, rtol=1e-9, atol=0.0):
                break
            v2 = _refine(obj, vc, lo, hi)
            f2 = float(obj.cost(*v2))
            if not f2 < f:
                break
            v, f = v2, f2
        if f < best_f:
            best_v, best_f = v, f
    assert best_v is not None
    cert = kkt_certificate(obj, best_v, lo, hi, kkt_tol)
    cert["local_ok"] = _local_probe(obj, best_v, lo, hi)
    cert["grid_ok"] = bool(best_f <= grid_best * (1 + 1e-12))
    cert.update(grid_points=n_grid, grid_best_cost=grid_best, starts=len(starts), case1=False)
    if not (cert["kkt_ok"] and cert["local_ok"] and cert["grid_ok"]):
        warnings.warn(f"exact solver could not certify its optimum (kkt_ok={cert['kkt_ok']}, "
                      f"local_ok={cert['local_ok']}, grid_ok={cert['grid_ok']})", RapidIdentWarning, stacklevel=2)
    theta = obj.theta(*best_v)
    active = bounds.active(*best_v, sample_period=sample_period)
    return obj.result(theta, "exact", bounds, sample_period, tuple(best_v), time.perf_counter() - t0,
                      {"certificate": cert, "kkt_case": _kkt_case(active), "case1": False,
                       "reduced_cost": best_f})

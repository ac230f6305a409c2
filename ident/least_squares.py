"""Bounded nonlinear least squares: the Levenberg–Marquardt of the output-error fits.

The output-error refinement (:mod:`ident.refine`) and the candidate fits of the diagnosis
(:mod:`ident.diagnosis.candidates`) minimise a simulation's mismatch over a handful of
parameters inside a box.  Both use :func:`bounded_lm`; :func:`secant_lm`, its secant
version, spends fewer simulations an iteration where a budget matters more than accuracy.
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ident.fixed_order import matvec, normal_products, solve, sum_squares

__all__ = ["LMResult", "bounded_lm", "secant_lm"]

#: Damping schedule: starting λ, its floor, the factor it grows by after a rejected trial
#: step, the factor it shrinks by after an accepted one, and the trials per iteration.
_LAM0, _LAM_MIN, _LAM_UP, _LAM_DOWN, _TRIALS = 1e-3, 1e-9, 6.0, 5.0, 6


@dataclass(frozen=True)
class LMResult:
    """Outcome of :func:`bounded_lm`.

    Attributes
    ----------
    z : ndarray (n,)
        The best point found (inside the box).
    cost : float
        ½‖r(z)‖² at ``z``.
    nfev : int
        Residual evaluations, the finite-difference Jacobians' included.
    message : str
        Why the search stopped.
    """

    z: np.ndarray
    cost: float
    nfev: int
    message: str


def bounded_lm(resid, z0, lb, ub, *, max_iter: int = 25, step=1e-3, relative_step: bool = False,
               ftol: float = 1e-5, ftol_iter: int = 2, xtol: float = 1e-8, parallel: bool = False,
               resid_many=None, jac=None, jac_skip=()) -> LMResult:
    """Minimise ½‖r(z)‖² subject to lb ≤ z ≤ ub by a projected Levenberg–Marquardt.

    Each iteration takes a forward-difference Jacobian J (one residual evaluation per
    parameter) and tries damped Gauss–Newton steps, solving
    ``(JᵀJ + λ diag(JᵀJ)) δ = −Jᵀr`` (Marquardt's scaling: the damping is invariant to
    the parameters' units), λ growing ×6 after each rejected trial (six trials at most) and
    shrinking ÷5 after an accepted step, from 10⁻³.

    Parameters
    ----------
    resid : callable
        ``resid(z) -> ndarray (m,)``, the residual vector.  It should return finite values
        (a large constant residual for points that make no sense); a trial point with a
        non-finite cost is rejected.  Exceptions it raises propagate: a caller can stop the
        search from inside it (a time budget) and keep its own record of the best point.
    z0 : array_like (n,)
        Starting point; projected onto the box first.
    lb, ub : array_like (n,)
        Bounds; ``±inf`` for none.
    max_iter : int
        Iterations (Jacobians) at most.
    step : float or array_like (n,)
        Forward-difference step, per parameter if an array.  Taken towards the inside of
        the box at an upper bound.
    relative_step : bool
        False (default): the step is absolute, in the units of z.  True: parameter j is
        stepped by ``step[j] * max(1, |z[j]|)``.
    ftol : float
        Stop after ``ftol_iter`` consecutive iterations each lowering the cost by less than
        this fraction.
    ftol_iter : int
        See ``ftol`` (default 2: a rough cost, e.g. a simulation with friction switching,
        can give one small decrease well away from its minimum).
    xtol : float
        Stop when an accepted step moves every parameter by at most
        ``xtol * (xtol + |z[j]|)``.
    parallel : bool
        Take the Jacobian's columns in two threads (:func:`_jacobian`): for a ``resid`` that
        is safe to call from several threads at once and spends its time outside the GIL
        (a compiled simulation).  The result is the same bit for bit.
    resid_many : callable, optional
        ``resid_many(Z) -> ndarray (P, m)``: row p exactly ``resid(Z[p])``, for several
        points at once (the Jacobian's columns; a simulation of several parameter sets in
        one pass is faster than one after the other).  The result is the same bit for bit.
    jac : callable, optional
        ``jac(z, cols) -> ndarray (len(cols), m)``: the exact derivatives ``∂r/∂z_j`` for j in
        ``cols`` (e.g. complex-step sensitivities of a simulation,
        :func:`ident.diagnosis.augmented.sensitivities`), used in place of the differences
        (``step``, ``relative_step`` and ``resid_many`` then go unused for J; each
        column counts as one evaluation in ``nfev``).  With an exact J there is no smaller
        step to retry with: when no damping gives a descent the search stops.
    jac_skip : sequence of int
        Columns ``jac`` does not give: forward differences at ``step`` (a parameter whose
        cost ripples, read through the ripple on purpose).

    Returns
    -------
    LMResult

    Notes
    -----
    Bounds: trial points are projected (clipped) onto the box, and a parameter on a bound
    whose gradient Jᵀr points out of the box is held there for the iteration (left out of
    the step) so that the others take the step that is best with it fixed, rather than one
    computed as if it could move and then cut off.

    Rough costs: when no damping gives a descent, the Jacobian is taken again with a step
    ten times smaller and λ reset, once, before the search gives up (a coarse difference
    on a cost that ripples, as a simulation with friction or contact events does, reads
    the ripple rather than the slope near the minimum).  After an accepted step the given
    difference step is used again.

    Why the normal equations and not a factorisation of J (QR in MINPACK, an SVD in
    scipy's trust-region reflective method): the residual vector is long (up to tens of
    thousands of samples) and the parameters few (≤ 14), so JᵀJ costs one pass over J and
    the n×n solve nothing, where a factorisation of the m×n J dominates the run time, the
    more so as multi-threaded BLAS is slow on a loaded machine.  Squaring J's condition
    number is tolerable here: the Marquardt damping keeps the system positive definite, and
    J itself is a finite difference, accurate to a few digits at best.  J is stored by
    columns (each difference is one column); its products and the damped solve are
    compiled loops in a fixed order (:mod:`ident.fixed_order`), not BLAS/LAPACK, whose
    order of operations — and so the search's path — depends on the machine.
    """
    z, lb, ub, step = _box(z0, lb, ub, step)
    n = z.size
    nfev = 1
    r = resid(z)
    cost = 0.5 * sum_squares(r)
    lam = _LAM0
    h0 = step
    small = 0  # consecutive accepted steps with a relative decrease below ftol
    retried = False  # the last iteration found no descent: its Jacobian was re-taken with h0 = step / 10
    for it in range(max_iter):
        J = _jacobian(resid, z, r, h0, ub, relative_step, parallel, resid_many, jac, jac_skip)
        nfev += n
        A, g = _normal(J, r)
        free = _free(z, g, lb, ub)
        if free.size == 0:
            return LMResult(z, cost, nfev, "every parameter is held at a bound")
        for _ in range(_TRIALS):
            z_new = _trial(z, A, g, free, lam, lb, ub)
            if z_new is None:
                lam *= 10.0
                continue
            nfev += 1
            r_new = resid(z_new)
            cost_new = 0.5 * sum_squares(r_new)
            if np.isfinite(cost_new) and cost_new < cost:
                break
            lam *= _LAM_UP
        else:
            if jac is not None and not jac_skip:
                return LMResult(z, cost, nfev, "no step decreases the cost")
            if retried:
                return LMResult(z, cost, nfev,
                                "no step decreases the cost, also with a 10x smaller difference step")
            retried = True
            lam = _LAM0
            h0 = step * 0.1
            continue
        rel = (cost - cost_new) / cost if cost > 0 else 0.0
        dz = np.abs(z_new - z)
        z, r, cost = z_new, r_new, cost_new
        lam = max(lam / _LAM_DOWN, _LAM_MIN)
        retried = False
        h0 = step
        small = small + 1 if rel < ftol else 0
        if small >= ftol_iter:
            return LMResult(z, cost, nfev,
                            f"ftol: relative cost decrease {rel:.1e} < {ftol:g} after {it + 1} iterations")
        if np.all(dz <= xtol * (xtol + np.abs(z))):
            return LMResult(z, cost, nfev, f"xtol: step below {xtol:g} after {it + 1} iterations")
    return LMResult(z, cost, nfev, f"max_iter: {max_iter} iterations")


def secant_lm(resid, z0, lb, ub, *, max_nfev: int = 100, step=1e-3, ftol: float = 1e-5,
              ftol_iter: int = 2, parallel: bool = False, resid_many=None, jac=None,
              jac_skip=()) -> LMResult:
    """:func:`bounded_lm` with a secant Jacobian: one or two residual evaluations per iteration.

    The secant version of Marquardt's method (Madsen, Nielsen & Tingleff, *Methods for
    non-linear least squares problems*, 2004, §3.4): the Jacobian is taken by forward
    differences once, then every trial point — accepted or not — updates it by Broyden's
    rank-one formula ``J += (r(z+δ) − r(z) − Jδ) δᵀ / δᵀδ``, and one column per
    iteration, in turn, is refreshed by a forward difference where the steps have not
    explored that direction (|δ_j| < 0.8‖δ‖), so that J does not drift from the slope.
    A trial is one iteration: λ grows ×6 after a rejected trial and shrinks ÷5 after an
    accepted one, as in :func:`bounded_lm`.  When ``_TRIALS`` trials in a row fail, the
    Jacobian is taken afresh by differences.

    For a residual that costs a simulation and has ``n`` parameters, an iteration costs
    1–2 evaluations instead of ``n + 1``: a fixed budget of evaluations (``max_nfev``,
    the differences included) goes several times further from a poor start, at the price
    of less accurate steps near the minimum (polish with :func:`bounded_lm`).  Bounds,
    ``step``, ``ftol``, ``ftol_iter``, ``parallel``, ``resid_many``, ``jac`` and ``jac_skip`` as in
    :func:`bounded_lm` (the step absolute, in the units of z; with ``jac`` the fresh
    Jacobians and the refreshed columns are exact).
    """
    z, lb, ub, step = _box(z0, lb, ub, step)
    n = z.size
    r = resid(z)
    nfev = 1
    cost = 0.5 * sum_squares(r)

    def jacobian() -> np.ndarray:
        nonlocal nfev
        nfev += n
        return _jacobian(resid, z, r, step, ub, False, parallel, resid_many, jac, jac_skip)

    J = jacobian()
    lam = _LAM0
    small = fails = 0
    col = 0
    while nfev < max_nfev:
        A, g = _normal(J, r)
        free = _free(z, g, lb, ub)
        if free.size == 0:
            return LMResult(z, cost, nfev, "every parameter is held at a bound")
        z_new = _trial(z, A, g, free, lam, lb, ub) if np.all(np.isfinite(A)) else None
        if z_new is None:  # no usable step from this J: differences again, or give up
            if fails >= _TRIALS or nfev + n > max_nfev:
                return LMResult(z, cost, nfev, "no usable step: the Jacobian gives no finite damped step")
            J = jacobian()
            lam, fails = lam * 10.0, fails + 1
            continue
        r_new = resid(z_new)
        nfev += 1
        cost_new = 0.5 * sum_squares(r_new)
        delta = z_new - z
        dd = sum_squares(delta)
        if np.all(np.isfinite(r_new)) and dd > 0.0:
            J += np.outer(r_new - r - matvec(J, delta), delta / dd)
        if np.isfinite(cost_new) and cost_new < cost:
            rel = (cost - cost_new) / cost if cost > 0 else 0.0
            z, r, cost = z_new, r_new, cost_new
            lam = max(lam / _LAM_DOWN, _LAM_MIN)
            fails = 0
            small = small + 1 if rel < ftol else 0
            if small >= ftol_iter:
                return LMResult(z, cost, nfev, f"ftol: relative cost decrease {rel:.1e} < {ftol:g}")
        else:
            lam *= _LAM_UP
            fails += 1
            if fails >= _TRIALS:  # the secant has lost the slope: differences again
                if nfev + n > max_nfev:
                    break
                J = jacobian()
                lam, fails = _LAM0, 0
                continue
        # keep J honest: refresh, in turn, a column the steps have not explored
        j = col % n
        col += 1
        if abs(delta[j]) < 0.8 * np.sqrt(dd) and nfev < max_nfev:
            J[:, j] = (_fd_column(resid, z, r, j, step, ub, False) if jac is None or j in jac_skip
                       else jac(z, [j])[0])
            nfev += 1
    return LMResult(z, cost, nfev, f"max_nfev: {nfev} evaluations")


def _box(z0, lb, ub, step):
    z = np.clip(np.asarray(z0, dtype=float), lb, ub)
    lb = np.broadcast_to(np.asarray(lb, dtype=float), z.shape)
    ub = np.broadcast_to(np.asarray(ub, dtype=float), z.shape)
    step = np.broadcast_to(np.asarray(step, dtype=float), z.shape)
    return z, lb, ub, step


def _normal(J: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``JᵀJ`` and ``Jᵀr`` of the Gauss–Newton normal equations (fixed order: :mod:`ident.fixed_order`)."""
    return normal_products(J, r)


#: Helper threads of :func:`_jacobian` (made on first use; shared by every caller).
_HELPERS: ThreadPoolExecutor | None = None
_HELPERS_LOCK = threading.Lock()


def _helpers() -> ThreadPoolExecutor:
    global _HELPERS
    with _HELPERS_LOCK:
        if _HELPERS is None:
            _HELPERS = ThreadPoolExecutor(max_workers=2, thread_name_prefix="lm-jacobian")
        return _HELPERS


def _jacobian(resid, z, r, h0, ub, relative_step, parallel, resid_many=None, jac=None,
              jac_skip=()) -> np.ndarray:
    """The forward-difference Jacobian (columns as :func:`_fd_column`), stored by columns.

    ``resid_many``: the columns' points evaluated together (see :func:`bounded_lm`); ``jac``:
    the exact columns instead but those in ``jac_skip`` (see :func:`bounded_lm`).
    ``parallel``: the columns in two groups, which the calling thread and a helper thread
    take in turn from a shared counter, so the caller never waits for a helper that has not
    started (on a busy machine the caller then takes both groups itself).  Each column is
    the same computation whichever thread makes it, so J is the same bit for bit.  Why
    threads here: a fit that runs alone (the diagnosis's base and reference re-fits, its
    re-estimation) would otherwise leave the second core idle; the diagnosis's searches,
    which run side by side in two workers already, do not split theirs.
    """
    n = z.size
    J = np.empty((r.size, n), order="F")

    def columns(js) -> None:
        if jac is not None:
            exact = [j for j in js if j not in jac_skip]
            if exact:
                J[:, exact] = jac(z, exact).T
            js = [j for j in js if j in jac_skip]
            if not js:
                return
        if resid_many is None:
            for j in js:
                J[:, j] = _fd_column(resid, z, r, j, h0, ub, relative_step)
            return
        hs = [_fd_step(z, j, h0, ub, relative_step) for j in js]
        Z = np.repeat(z[None, :], len(hs), axis=0)
        for i, (j, h) in enumerate(zip(js, hs)):
            Z[i, j] += h
        R = resid_many(Z)
        for i, (j, h) in enumerate(zip(js, hs)):  # (R[i] − r)/h, written into J's column
            np.subtract(R[i], r, out=J[:, j])
            J[:, j] /= h

    if not parallel or n < 2:
        columns(range(n))
        return J
    groups = [range(0, (n + 1) // 2), range((n + 1) // 2, n)]
    lock = threading.Lock()
    state = {"next": 0, "done": 0, "error": None}
    finished = threading.Event()

    def take() -> None:
        while True:
            with lock:
                g = state["next"]
                if g >= len(groups) or state["error"] is not None:
                    return
                state["next"] = g + 1
            try:
                columns(groups[g])
            except BaseException as exc:  # handed to the caller, which raises it
                with lock:
                    state["error"] = exc
                finished.set()
                return
            with lock:
                state["done"] += 1
                if state["done"] == len(groups):
                    finished.set()

    _helpers().submit(_help, take)
    take()
    finished.wait()
    if state["error"] is not None:
        raise state["error"]
    return J


def _help(take) -> None:
    """A helper thread's share of a Jacobian (a function of its own: a benchmark can time it)."""
    take()


def _fd_step(z, j, h0, ub, relative_step) -> float:
    """The difference step along parameter j (towards the inside at an upper bound)."""
    h = h0[j] * max(1.0, abs(z[j])) if relative_step else h0[j]
    return -h if z[j] + h > ub[j] else h


def _fd_column(resid, z, r, j, h0, ub, relative_step) -> np.ndarray:
    """Forward difference of the residual along parameter j (towards the inside at an upper bound)."""
    h = _fd_step(z, j, h0, ub, relative_step)
    zj = z.copy()
    zj[j] += h
    return (resid(zj) - r) / h


def _free(z, g, lb, ub) -> np.ndarray:
    """Parameters not held: one on a bound whose gradient points out of the box is held."""
    held = ((z <= lb) & (g > 0)) | ((z >= ub) & (g < 0))
    return np.flatnonzero(~held)


def _trial(z, A, g, free, lam, lb, ub):
    """The damped Gauss–Newton trial point ``(JᵀJ + λ diag(JᵀJ)) δ = −Jᵀr`` in the box, or None."""
    Af, gf = A[np.ix_(free, free)], g[free]
    d = np.maximum(np.diag(Af), 1e-12 * max(1.0, float(np.max(np.diag(Af)))))
    try:
        delta = solve(Af + lam * np.diag(d), -gf)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(delta)):
        return None
    z_new = z.copy()
    z_new[free] += delta
    return np.clip(z_new, lb, ub)

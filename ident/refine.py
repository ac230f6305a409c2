"""Output-error refinement of an identified drive model on its free-run response (SPEC §5).

The solvers fit eq. 3.12, an *equation* error: one-step predictions from measured
ẋ, ẍ and e_i.  What the user judges is the *free-run* tracking error (SPEC §5): the model
driven by the commanded trajectory alone.  Starting from a constrained equation-error
solution, this stage minimises the output error::

    J = Σ_k (x̂_k − x_k)²  =  ‖e − ê‖²,      x̂ = simulate(model, x_r)

over the eight parameters, written as search variables (thesis eq. 3.7, 3.14) and the
normalised numerator/friction of eq. 3.10::

    q = (ln ω_n, ζ, ln p, β_0, β_1, β_2, δ⁺, δ⁻)

with box bounds ``ω_n,min ≤ ω_n ≤ f_max``, ``ζ_min ≤ ζ ≤ ζ_max``, ``p_min ≤ p ≤ f_max``
(eq. 3.8, :class:`ident.model.Bounds`), so every iterate has its poles inside the
constraint region.  A projected Levenberg–Marquardt with a finite-difference Jacobian
(:func:`ident.least_squares.bounded_lm`; or, on request, ``scipy.optimize.least_squares``'
trust-region reflective method) does the search on a coarser simulator (``substeps_search``
friction sub-steps; the linear part is exact either way) and on every k-th residual; the
before/after fit is computed with the default simulator on all samples.  The refined
model is returned only if it improves the fit of the (bounded) starting model.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from core.errors import InputError
from ident.fixed_order import lstsq, matvec, sum_squares
from ident.least_squares import bounded_lm
from ident.metrics import FitResult, fit_result
from ident.model import Bounds, DriveModel, alphas_from_search, base_vector
from ident.preprocessing import shift_command
from ident.simulation import DEFAULT_SUBSTEPS, FreeRun, simulate

__all__ = ["RefineResult", "refine", "model_fit"]


@dataclass(frozen=True)
class RefineResult:
    """Outcome of :func:`refine`.

    Attributes
    ----------
    model : DriveModel
        Refined model (poles inside the bounds).
    start_model : DriveModel
        The equation-error model moved inside the bounds: where the search started.
    fit_before, fit_after : FitResult
        Free-run fit (SPEC §5) of the model given to :func:`refine` and of ``model``.
    nfev : int
        Simulations used by the search (function and finite-difference Jacobian evaluations).
    elapsed_s : float
        Wall time, s (reported only: nothing in the result depends on it).
    improved : bool
        False when the search did not beat the starting model (``model`` is then the start).
    message : str
        The optimiser's termination message.
    active_constraints : tuple of str
        Bounds the refined search variables sit on (names of ``ident.model.CONSTRAINT_NAMES``).
    """

    model: DriveModel
    start_model: DriveModel
    fit_before: FitResult
    fit_after: FitResult
    nfev: int
    elapsed_s: float
    improved: bool
    message: str
    active_constraints: tuple[str, ...]


def model_fit(model, x_r: np.ndarray, x: np.ndarray, Ts: float, *, segment=None, shift: int = 0,
              substeps: int = DEFAULT_SUBSTEPS) -> FitResult:
    """Free-run tracking-error fit (SPEC §5) of ``model`` on a recording.

    Parameters
    ----------
    model : DriveModel-like
    x_r, x : ndarray (N,)
        Commanded (as recorded, unshifted) and actual position, mm.
    Ts : float
        Sample period, s.
    segment : ndarray of int (N,), optional
        Segment ids (the simulation restarts at each from the recorded position).
    shift : int
        Preview shift the model was identified with, samples (applied to the command
        driving the simulation; e and ê both use the recorded command).
    """
    x_r = np.asarray(x_r, dtype=float)
    x = np.asarray(x, dtype=float)
    x_hat = simulate(model, shift_command(x_r, shift, segment), Ts, segment=segment, x0=x, substeps=substeps)
    return fit_result(x_r - x, x_r - x_hat)


def _start_point(model, bounds: Bounds, Ts: float, regression=None) -> np.ndarray:
    """Search vector q of the model, with its poles clipped into the bounds.

    When the poles had to move and the regression (eq. 3.11) is given, the numerator and
    friction θ2 = (β0, β1, β2, δ⁺, δ⁻) are re-fitted by least squares for the clipped
    denominator (as eq. 4.9 does for every candidate denominator).
    """
    if not isinstance(model, DriveModel):  # any object with the eight fields
        model = DriveModel(*base_vector(model))
    wn, zeta, p = model.search_variables(bounds, Ts)
    f_max = bounds.f_max(Ts)
    wn_c = bounds.wn_min if not math.isfinite(wn) else min(max(wn, bounds.wn_min), f_max)
    p_c = bounds.p_min if not math.isfinite(p) else min(max(p, bounds.p_min), f_max)
    zeta_c = bounds.zeta_min if not math.isfinite(zeta) else min(max(zeta, bounds.zeta_min), bounds.zeta_max)
    moved = (wn_c, zeta_c, p_c) != (wn, zeta, p)
    if moved and regression is not None:
        theta1 = np.array([float(v) for v in alphas_from_search(wn_c, zeta_c, p_c)])
        Phi2 = regression.Phi[:, 3:]
        rest = lstsq(Phi2, regression.Y - matvec(regression.Phi[:, :3], theta1))
    else:
        a2 = float(model.a2)
        rest = np.array([model.b2, model.b1, model.b0, model.d0, model.d1], dtype=float) / a2
    return np.concatenate([[math.log(wn_c), zeta_c, math.log(p_c)], rest])


def _model(q: np.ndarray) -> DriveModel:
    """Search vector → model (eq. 3.7, 3.10): a1 = p + 2ζω_n, a2 = ω_n² + 2pζω_n, a3 = pω_n²."""
    wn, zeta, p = math.exp(q[0]), float(q[1]), math.exp(q[2])
    a2 = wn * wn + 2.0 * p * zeta * wn
    beta0, beta1, beta2, dp, dm = (float(v) * a2 for v in q[3:])
    return DriveModel(a1=p + 2.0 * zeta * wn, a2=a2, a3=p * wn * wn, b0=beta2, b1=beta1, b2=beta0, d0=dp, d1=dm)


def _active(q: np.ndarray, lb: np.ndarray, ub: np.ndarray) -> tuple[str, ...]:
    names = []
    tol = 1e-6
    if q[2] <= lb[2] + tol:
        names.append("p_min")
    if q[0] <= lb[0] + tol:
        names.append("wn_min")
    if q[1] <= lb[1] + tol:
        names.append("zeta_min")
    if q[1] >= ub[1] - tol:
        names.append("zeta_max")
    if q[0] >= ub[0] - tol or q[2] >= ub[2] - tol:
        names.append("f_max")
    return tuple(names)


def refine(
    model,
    x_r: np.ndarray,
    x: np.ndarray,
    Ts: float,
    *,
    segment: np.ndarray | None = None,
    shift: int = 0,
    bounds: Bounds | None = None,
    max_nfev: int = 100,
    substeps_search: int = 2,
    max_evals: int | None = 800,
    ftol: float = 1e-6,
    max_residuals: int | None = 2000,
    regression=None,
    optimizer: str = "lm",
) -> RefineResult:
    """Refine ``model`` by minimising the free-run tracking-error mismatch under the pole bounds.

    Parameters
    ----------
    model : DriveModel-like
        Starting point, normally the constrained equation-error solution; a model with
        poles outside ``bounds`` is moved inside first.
    x_r, x : ndarray (N,)
        Commanded (as recorded) and actual position, mm, on the regular grid.
    Ts : float
        Sample period, s.
    segment : ndarray of int (N,), optional
        Segment ids.
    shift : int
        Preview shift of the command used at identification, samples (kept fixed).
    bounds : Bounds, optional
        Pole constraints (default ``Bounds()``: 0.2 Hz, ζ ∈ [0.2, 2], f ≤ Nyquist).
    max_nfev : int
        Budget of optimiser iterations (each costs eight simulations for the
        finite-difference Jacobian plus one or more trial steps, ~1–3 ms each per
        25 000 samples).
    substeps_search : int
        Friction sub-steps of the simulator during the search (the final fit uses the default).
    max_evals : int or None
        Stop the search after this many simulations (the best point so far is kept).  A
        count, not a wall time, so that the result does not depend on the machine or its
        load; 800 is about a second on a 2-core machine for 23 000 samples, and past the
        ~550 simulations (50 iterations) a typical recording converges in.
    ftol : float
        Relative decrease of ‖e − ê‖² at which the search stops (1e-6: the fit % is then
        settled to ~1e-4 %).
    max_residuals : int or None
        During the search, compare every k-th sample so that at most about this many
        residuals enter the optimiser (None: all).  The fit reported uses every sample.
    regression : ident.regression.Regression, optional
        The eq. 3.11 regression of this recording: used to re-fit the numerator and
        friction when the starting model's poles had to be moved into the bounds.
    optimizer : "lm" | "trf"
        The projected Levenberg–Marquardt :func:`ident.least_squares.bounded_lm` (default) or
        ``scipy.optimize.least_squares``' trust-region reflective method.
    """
    t0 = time.perf_counter()
    bounds = bounds or Bounds()
    x_r = np.asarray(x_r, dtype=float)
    x = np.asarray(x, dtype=float)
    command = shift_command(x_r, shift, segment)
    fit_before = model_fit(model, x_r, x, Ts, segment=segment, shift=shift)

    f_max = bounds.f_max(Ts)
    lb = np.array([math.log(bounds.wn_min), bounds.zeta_min, math.log(bounds.p_min)] + [-np.inf] * 5)
    ub = np.array([math.log(f_max), bounds.zeta_max, math.log(f_max)] + [np.inf] * 5)
    q0 = np.clip(_start_point(model, bounds, Ts, regression), lb, ub)
    start_model = _model(q0)

    best = {"cost": math.inf, "q": q0.copy(), "n": 0}
    # Residuals on every k-th sample during the search keep the optimiser's linear algebra
    # (m×8 Jacobians) small; the simulation itself always runs on every sample, and the
    # final fit uses all of them.
    stride = max(1, x.size // max_residuals) if max_residuals else 1

    class _Budget(Exception):
        pass

    free_run = FreeRun(command, Ts, segment=segment, x0=x, substeps=substeps_search)

    def residual(q: np.ndarray) -> np.ndarray:
        if max_evals is not None and best["n"] >= max_evals:
            raise _Budget
        best["n"] += 1
        try:
            m = _model(q)
        except Exception:  # parameters that make no model (a2 = 0): a large residual
            return np.full(x[::stride].size, 1e3)
        r = (free_run(m) - x)[::stride]
        if not np.all(np.isfinite(r)):
            return np.full(x[::stride].size, 1e3)
        c = sum_squares(r)
        if c < best["cost"]:
            best["cost"], best["q"] = c, q.copy()
        return r

    try:
        if optimizer == "lm":
            message = bounded_lm(residual, q0, lb, ub, max_iter=max_nfev, step=1e-5, relative_step=True,
                                 ftol=ftol, ftol_iter=1, xtol=1e-6).message
        elif optimizer == "trf":
            from scipy.optimize import least_squares  # only for optimizer='trf': 0.3–0.6 s to import

            message = least_squares(residual, q0, bounds=(lb, ub), x_scale="jac", diff_step=1e-5,
                                    ftol=ftol, xtol=1e-6, max_nfev=max_nfev, method="trf").message
        else:
            raise InputError(f"optimizer must be 'lm' or 'trf', got {optimizer!r}")
    except _Budget:
        message = f"budget of {max_evals} simulations reached"
    nfev = best["n"]
    q = best["q"]
    refined = _model(q)
    fit_start = model_fit(start_model, x_r, x, Ts, segment=segment, shift=shift)
    fit_after = model_fit(refined, x_r, x, Ts, segment=segment, shift=shift)
    improved = fit_after.tracking_error_fit_pct > fit_start.tracking_error_fit_pct
    if not improved:
        refined, fit_after, q = start_model, fit_start, q0
    return RefineResult(
        model=refined,
        start_model=start_model,
        fit_before=fit_before,
        fit_after=fit_after,
        nfev=nfev,
        elapsed_s=time.perf_counter() - t0,
        improved=improved,
        message=str(message),
        active_constraints=_active(q, lb, ub),
    )

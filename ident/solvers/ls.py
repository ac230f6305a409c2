"""Unconstrained least squares of thesis eq. 3.12 (Case 1 of Table 3.1).

    minimise f(theta) = 1/2 (Y - Phi theta)^T (Y - Phi theta)

Solved on the column-scaled regressor Phi D^-1 (D = column 2-norms) by Householder QR in a
fixed order of operations (:func:`ident.fixed_order.lstsq`: the same bits on any machine) --
never by inverting Phi^T Phi, whose condition number is the square of Phi's; its singular
values give the rank and condition number.  The columns of Phi span many decades
(e_i ~ 1e-2 mm s, xddot ~ 1e3 mm/s^2), so the scaling is what makes the reported condition
number meaningful.  Nothing keeps the poles
inside the bounds: the result may be unstable or poorly damped (thesis section 3.3); its
violated constraints are listed in ``details["violated_constraints"]``.
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np

from core.errors import IdentificationError, RapidIdentWarning
from ident.fixed_order import lstsq, unit_columns
from ident.model import Bounds, DriveModel
from ident.solvers.common import SolverResult, check_regression, cost_eq312

__all__ = ["solve_ls"]


def solve_ls(Phi: np.ndarray, Y: np.ndarray, bounds: Bounds | None = None, *,
             sample_period: float | None = None, cond_warn: float = 1e8) -> SolverResult:
    """Unconstrained least-squares estimate of theta (eq. 3.12).

    Parameters
    ----------
    Phi : ndarray, shape (N, 8)
        Regressor of eq. 3.11.
    Y : ndarray, shape (N,)
        Actual axis position x_k, mm.
    bounds : Bounds, optional
        Only used to report which constraints of eq. 3.8 the estimate violates.
    sample_period : float, optional
        T_s in s, for the Nyquist bound when ``bounds.f_max_hz`` is None.
    cond_warn : float
        Warn (RapidIdentWarning) when the condition number of the scaled Phi exceeds this.

    Returns
    -------
    SolverResult
        ``solver="ls"``; ``active_constraints`` is empty (nothing is enforced).
    """
    t0 = time.perf_counter()
    Phi, Y = check_regression(Phi, Y)
    Phi_s, D = unit_columns(Phi)  # no zero column: check_regression refuses one
    sv = np.linalg.svd(Phi_s, compute_uv=False)  # reported: the rank and condition number
    rank = int(np.sum(sv > max(Phi.shape) * np.finfo(float).eps * sv[0]))
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    if rank < 8:
        raise IdentificationError(f"regressor Phi is rank deficient (rank {rank} of 8): the recording "
                                  "does not excite all parameters")
    if cond > cond_warn:
        warnings.warn(f"least squares is ill-conditioned: condition number of scaled Phi = {cond:.3g}",
                      RapidIdentWarning, stacklevel=2)
    theta = lstsq(Phi_s, Y) / D  # in a fixed order: the same θ on any machine
    model = DriveModel.from_theta(theta)
    details: dict = {"singular_values_scaled": sv.tolist()}
    if bounds is not None:
        wn, zeta, p = model.search_variables(bounds, sample_period)
        details["search_variables"] = {"wn_hz": wn / (2 * math.pi), "zeta": zeta, "p_hz": p / (2 * math.pi)}
        details["violated_constraints"] = bounds.violated(wn, zeta, p, sample_period)
    return SolverResult(model=model, theta=theta, cost=cost_eq312(Phi, Y, theta), solver="ls",
                        active_constraints=(), condition_number=cond,
                        elapsed_s=time.perf_counter() - t0, details=details)

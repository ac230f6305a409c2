"""What the three solvers share: input checks, the result type and the reduced objective.

Regression (thesis eq. 3.11-3.12)::

    Y = Phi theta + residual,      f(theta) = 1/2 (Y - Phi theta)^T (Y - Phi theta)

Reduced objective (eq. 4.8-4.12).  theta = [theta_1; theta_2] with theta_1 = [alpha_i,
alpha_1, alpha_2] fixed by the search variables (wn, zeta, p) through eq. 3.14; theta_2 =
[beta_0, beta_1, beta_2, delta+, delta-] then follows by linear least squares (eq. 4.9),
``theta_2 = R* - P* theta_1`` (eq. 4.11), and the cost is a quadratic form in
mu = [1, alpha_i, alpha_1, alpha_2] (eq. 4.10)::

    f(v) = 1/2 (mu^T A mu + B mu + Gamma)                          (eq. 4.12)

:class:`ReducedObjective` precomputes everything in one pass over the N rows, so a cost
evaluation no longer depends on N.  It evaluates the same quadratic in square-root form:
one Householder QR of the column-scaled ``[Phi_2, Phi_1, Y]`` gives a 9x9 triangle R, and

    f(v) = 1/2 (|| M mu ||^2 + rho^2),   M = [-r_1y, R_11 S_1]  (3x4),   rho = R[8, 8]

where rho^2/2 is the unconstrained least-squares minimum.  ``A = M^T M + rho^2 e_1 e_1^T``,
B = 0, Gamma = 0 is thus one exact rewriting of eq. 4.12; the thesis's own A, B, Gamma
(built from P = Phi^T Phi, R = Phi^T Y, Gamma = Y^T Y of eq. 3.19) are also provided
(:meth:`ReducedObjective.gram_form`) and agree to rounding.  The square-root form avoids the
cancellation of mu^T A mu + B mu + Gamma, three terms of size Y^T Y summing to a cost that
can be 1e-9 of it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from core.errors import IdentificationError, InputError
from ident.fixed_order import matvec, qr_r, solve_upper, sum_squares
from ident.model import THETA_NAMES, Bounds, DriveModel, alphas_from_search, alphas_jacobian

__all__ = ["SolverResult", "ReducedObjective", "check_regression", "cost_eq312", "resolve_box"]

#: Human names of the regressor columns of eq. 3.11, for error messages.
COLUMN_NAMES = ("e_i", "-xdot", "-xddot", "x_r", "xdot_r", "xddot_r", "-PV(xdot)", "-NV(xdot)")


@dataclass(frozen=True)
class SolverResult:
    """Outcome of one solver run.

    Attributes
    ----------
    model : DriveModel
        Identified model (physical parameters of eq. 3.3).
    theta : ndarray, shape (8,)
        Normalised parameters of eq. 3.11.
    cost : float
        f of eq. 3.12, 1/2 sum (Y - Phi theta)^2, mm^2, evaluated on the full Phi.
    solver : str
        "ls", "exact" or "ga".
    active_constraints : tuple of str
        Constraint names (``ident.model.CONSTRAINT_NAMES``) the solution lies on.
    condition_number : float
        2-norm condition number of the column-scaled Phi.
    elapsed_s : float
        Wall time of the solver in s.
    details : dict
        Solver-specific record (search variables, certificate, history, ...).
    """

    model: DriveModel
    theta: np.ndarray
    cost: float
    solver: str
    active_constraints: tuple[str, ...]
    condition_number: float
    elapsed_s: float
    details: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the solver part of SPEC section 6)."""
        return {"solver": self.solver, "cost": float(self.cost),
                "active_constraints": list(self.active_constraints),
                "condition_number": float(self.condition_number), "elapsed_s": float(self.elapsed_s),
                "theta": {n: float(v) for n, v in zip(THETA_NAMES, self.theta)}}


def check_regression(Phi, Y) -> tuple[np.ndarray, np.ndarray]:
    """Validate and return (Phi (N, 8) float, Y (N,) float); one-line errors naming the problem."""
    try:
        Phi = np.asarray(Phi, dtype=float)
        Y = np.asarray(Y, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"Phi and Y must be numeric arrays ({exc})") from exc
    if Phi.ndim != 2 or Phi.shape[1] != 8:
        raise InputError(f"Phi must have shape (N, 8) (eq. 3.11), got {Phi.shape}")
    if Y.ndim != 1 or Y.shape[0] != Phi.shape[0]:
        raise InputError(f"Y must have shape ({Phi.shape[0]},) to match Phi, got {Y.shape}")
    if Phi.shape[0] < 16:
        raise IdentificationError(f"regression has only {Phi.shape[0]} rows; need at least 16 samples")
    if not np.all(np.isfinite(Phi)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(Phi), axis=0))[0])
        raise InputError(f"Phi column {COLUMN_NAMES[bad]} contains NaN or inf")
    if not np.all(np.isfinite(Y)):
        raise InputError("Y (actual position) contains NaN or inf")
    norms = np.linalg.norm(Phi, axis=0)
    if np.any(norms == 0.0):
        bad = int(np.flatnonzero(norms == 0.0)[0])
        hint = {6: " (no motion in the positive direction?)", 7: " (no motion in the negative direction?)"}
        raise IdentificationError(f"regressor column {COLUMN_NAMES[bad]} is all zero{hint.get(bad, '')}")
    return Phi, Y


def cost_eq312(Phi: np.ndarray, Y: np.ndarray, theta: np.ndarray) -> float:
    """f of eq. 3.12: 1/2 ||Y - Phi theta||^2 (mm^2), on the full regression."""
    return 0.5 * sum_squares(Y - matvec(Phi, np.asarray(theta, dtype=float)))


def resolve_box(bounds: Bounds, sample_period: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Search box over (wn rad/s, zeta, p rad/s); f_max from bounds or the Nyquist frequency."""
    if not isinstance(bounds, Bounds):
        raise InputError(f"bounds must be an ident.model.Bounds, got {type(bounds).__name__}")
    return bounds.box(sample_period)


class ReducedObjective:
    """Precomputed reduced objective of eq. 4.12 for one regression (see module docstring).

    Parameters
    ----------
    Phi : ndarray, shape (N, 8)
        Regressor of eq. 3.11 (columns e_i mm s, -xdot mm/s, -xddot mm/s^2, x_r mm,
        xdot_r mm/s, xddot_r mm/s^2, -PV, -NV).
    Y : ndarray, shape (N,)
        Actual position, mm.
    """

    def __init__(self, Phi: np.ndarray, Y: np.ndarray):
        Phi, Y = check_regression(Phi, Y)
        self.Phi, self.Y = Phi, Y
        self._PhiT: np.ndarray | None = None  # row-major copy for cost_direct, made on first use
        self.scale = np.linalg.norm(Phi, axis=0)  # column scaling: theta_scaled = scale * theta
        s1, s2 = self.scale[:3], self.scale[3:]
        Z = np.column_stack([Phi[:, 3:] / s2, Phi[:, :3] / s1, Y])  # [Phi_2, Phi_1, Y]
        R = qr_r(Z)  # positive diagonal; a fixed order of operations: the same R on any machine
        self.R = R
        d8 = np.abs(np.diag(R[:8, :8]))
        self.condition_number = float(np.linalg.cond(R[:8, :8])) if d8.min() > 0 else math.inf
        if not d8.min() > 1e-13 * d8.max():
            raise IdentificationError("regressor Phi is rank deficient: the recording does not excite "
                                      f"all 8 parameters (condition number {self.condition_number:.3g})")
        R22, R21, r2y = R[:5, :5], R[:5, 5:8], R[:5, 8]
        R11, r1y = R[5:8, 5:8], R[5:8, 8]
        self.rho2 = float(R[8, 8] ** 2)
        # f = 1/2 (||M mu||^2 + rho^2), mu = [1, alpha_i, alpha_1, alpha_2]   (eq. 4.10)
        self.M = np.column_stack([-r1y, R11 * s1])
        # theta_2 = R* - P* theta_1  (eq. 4.11), both unscaled
        self.R_star = solve_upper(R22, r2y) / s2
        self.P_star = solve_upper(R22, R21 * s1) / s2[:, None]
        # unconstrained least squares (Case 1 of Table 3.1)
        theta1 = solve_upper(R11, r1y) / s1
        self.theta_ls = np.concatenate([theta1, self.theta2(theta1)])

    # ---- the pieces of eq. 4.11-4.12 ----------------------------------------------------
    @property
    def T(self) -> np.ndarray:
        """theta = T mu (eq. 4.11), T = [[0, I3], [R*, -P*]], shape (8, 4)."""
        T = np.zeros((8, 4))
        T[:3, 1:] = np.eye(3)
        T[3:, 0] = self.R_star
        T[3:, 1:] = -self.P_star
        return T

    def gram_form(self) -> tuple[np.ndarray, np.ndarray, float]:
        """The thesis's (A 4x4, B 1x4, Gamma) of eq. 4.12 from P = Phi^T Phi, R = Phi^T Y, Y^T Y."""
        T = self.T
        P = self.Phi.T @ self.Phi
        Rv = self.Phi.T @ self.Y
        return T.T @ P @ T, -2.0 * Rv @ T, float(self.Y @ self.Y)

    def theta2(self, theta1: np.ndarray) -> np.ndarray:
        """[beta_0..delta-] from theta_1 (eq. 4.9/4.11); theta1 shape (3,) or (n, 3)."""
        # einsum's own loops, not a BLAS product: the same θ₂ bits on any machine
        return self.R_star - np.einsum("...j,ij->...i", np.asarray(theta1, dtype=float), self.P_star)

    def theta(self, wn, zeta, p) -> np.ndarray:
        """Full theta (eq. 3.11) for search variables (rad/s, -, rad/s); shape (8,) or (n, 8)."""
        th1 = np.stack(alphas_from_search(wn, zeta, p), axis=-1)
        return np.concatenate([th1, self.theta2(th1)], axis=-1)

    # ---- costs ---------------------------------------------------------------------------------
    def residual(self, wn, zeta, p) -> np.ndarray:
        """r = M mu, shape (..., 3): f = 1/2 (|r|^2 + rho^2)."""
        ai, a1, a2 = alphas_from_search(wn, zeta, p)
        M = self.M
        return np.stack([M[k, 0] + M[k, 1] * ai + M[k, 2] * a1 + M[k, 3] * a2 for k in range(3)], axis=-1)

    def cost(self, wn, zeta, p) -> np.ndarray:
        """Reduced cost f (eq. 4.12), vectorised over search variables (wn rad/s, zeta, p rad/s)."""
        r = self.residual(wn, zeta, p)
        return 0.5 * (np.sum(r * r, axis=-1) + self.rho2)

    def cost_gram(self, wn, zeta, p) -> np.ndarray:
        """Same cost through the thesis's literal A, B, Gamma (eq. 4.12); for cross-checks."""
        A, B, G = self.gram_form()
        ai, a1, a2 = alphas_from_search(wn, zeta, p)
        mu = np.stack(np.broadcast_arrays(np.ones_like(ai), ai, a1, a2), axis=-1)
        return 0.5 * (np.einsum("...i,ij,...j->...", mu, A, mu) + mu @ B + G)

    def cost_direct(self, wn, zeta, p, chunk: int = 64) -> np.ndarray:
        """Same cost evaluated "directly" by eq. 3.12 on the full Phi (N rows per candidate).

        theta_2 still comes from eq. 4.11; then Phi theta - Y and its square are formed over
        all N rows (the 9N + 23 multiplications of section 4.2.5), a BLAS product per chunk
        of candidates.
        """
        if self._PhiT is None:
            self._PhiT = np.ascontiguousarray(self.Phi.T)
        th = np.atleast_2d(self.theta(np.ravel(wn), np.ravel(zeta), np.ravel(p)))
        out = np.empty(th.shape[0])
        for i in range(0, th.shape[0], chunk):
            res = th[i:i + chunk] @ self._PhiT
            res -= self.Y
            out[i:i + chunk] = 0.5 * np.einsum("ij,ij->i", res, res)
        return out.reshape(np.shape(wn))

    def gradient(self, wn: float, zeta: float, p: float) -> np.ndarray:
        """d f / d(wn, zeta, p) at one point (units 1/(rad/s), 1, 1/(rad/s) times mm^2)."""
        r = self.residual(wn, zeta, p)
        J = self.jacobian(wn, zeta, p)  # d r / d(wn, zeta, p)
        return np.einsum("ki,k->i", J, r)

    def jacobian(self, wn: float, zeta: float, p: float) -> np.ndarray:
        """d r / d(wn, zeta, p), shape (3, 3)."""
        return np.einsum("ij,jk->ik", self.M[:, 1:], alphas_jacobian(wn, zeta, p))

    def result(self, theta: np.ndarray, solver: str, bounds: Bounds | None, sample_period: float | None,
               search: tuple[float, float, float] | None, elapsed_s: float,
               details: dict[str, Any]) -> SolverResult:
        """Package a solution: model, eq. 3.12 cost on the full Phi, active constraints."""
        theta = np.asarray(theta, dtype=float)
        model = DriveModel.from_theta(theta)
        active: tuple[str, ...] = ()
        if bounds is not None and search is not None:
            active = bounds.active(*(float(x) for x in search), sample_period=sample_period)
        if search is not None:
            details = {"search_variables": {"wn_hz": float(search[0]) / (2 * math.pi), "zeta": float(search[1]),
                                            "p_hz": float(search[2]) / (2 * math.pi)}, **details}
        return SolverResult(model=model, theta=theta, cost=cost_eq312(self.Phi, self.Y, theta), solver=solver,
                            active_constraints=active, condition_number=self.condition_number,
                            elapsed_s=elapsed_s, details=details)

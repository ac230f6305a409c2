"""Gauss–Newton steps to the stationary point of an output-error cost, where a covariance holds.

The 95 % intervals (:mod:`ident.uncertainty` for the base model of eq. 3.3,
:mod:`ident.diagnosis.intervals` for an accepted effect) linearise the residual at the
estimate, ``r(p) ≈ r(p̂) + J (p − p̂)``; the covariance built from J is that of the
estimator only where ``Jᵀr = 0``.  The searches that produced the estimate stop on a
relative decrease or an iteration count (on a subsampled or weighted cost, or a curved
valley), which can leave it a standard error or more from that point.  A few full
Gauss–Newton steps on the cost the covariance is computed from close the gap.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ident.fixed_order import dot, normal_products, solve, sum_squares

__all__ = ["to_stationary_point"]

#: Times a step is halved before the search gives up on it (the cost did not fall).
_HALVINGS = 5


def to_stationary_point(v: np.ndarray, jacobian: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                        residual: Callable[[np.ndarray], np.ndarray | None], *,
                        scale: Callable[[np.ndarray], np.ndarray],
                        project: Callable[[np.ndarray], np.ndarray] | None = None,
                        max_steps: int = 3, rel_decrease: float = 1e-6, min_linear_decrease: float = 0.0,
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gauss–Newton steps on ``‖r(v)‖²`` until the cost stops falling.

    Each step solves the linearised least-squares problem ``min ‖r + J·diag(s)·δz‖`` in the
    parameters' own units (``s = scale(v)``, so the normal equations are not dominated by
    the parameters' sizes) and moves ``v + s·δz``, projected onto the feasible set; it is
    halved up to five times until the cost falls.  The normal equations ``JₛᵀJₛ δz = −Jₛᵀr``
    are formed and solved in a fixed order of operations (:mod:`ident.fixed_order`), not by
    LAPACK, so the point reached does not depend on the machine's BLAS kernel.

    Parameters
    ----------
    v : (n,) the estimate.
    jacobian : ``jacobian(v) -> (J, r)``: the residual r (m,) at v and J = ∂r/∂v (m, n).
    residual : ``residual(v) -> r`` (m,), or None where v is not admissible (a trial step
        there is halved).
    scale : ``scale(v) -> s`` (n,): each parameter's natural size (> 0).
    project : onto the feasible set (e.g. a clip to a box); identity when None.
    max_steps : accepted steps at most.
    rel_decrease : stop after a step that lowers the cost by less than this share.
    min_linear_decrease : no step is taken when the linearised model predicts a decrease
        ``‖Jₛδz‖²`` below this share of the cost: v is at the stationary point as far as
        J can tell (0: always try).

    Returns
    -------
    v, J, r : the point reached, with the Jacobian and residual there.
    """
    v = np.asarray(v, dtype=float)
    J, r = jacobian(v)
    cost = sum_squares(r)
    for _ in range(max_steps):
        if not (np.all(np.isfinite(J)) and math.isfinite(cost)):
            break
        s = scale(v)
        A, g = normal_products(J * s, r)
        try:
            dz = solve(A, -g)
        except np.linalg.LinAlgError:
            break
        # ‖Jₛδz‖² = δzᵀ(JₛᵀJₛ)δz = −δzᵀJₛᵀr at the solution of the normal equations
        linear = -dot(dz, g)
        if not (np.all(np.isfinite(dz)) and linear > min_linear_decrease * cost):
            break
        step = dz * s
        for _half in range(_HALVINGS):
            cand = v + step if project is None else project(v + step)
            rc = residual(cand)
            c_new = sum_squares(rc) if rc is not None else math.inf
            if math.isfinite(c_new) and c_new < cost:
                break
            step = 0.5 * step
        else:
            break
        rel = (cost - c_new) / cost
        v = cand
        J, r = jacobian(v)
        cost = sum_squares(r)
        if rel < rel_decrease:
            break
    return v, J, r

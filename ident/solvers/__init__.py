"""Solvers of the identification regression (thesis eq. 3.11-3.12), one module each.

* :func:`~ident.solvers.ls.solve_ls` -- unconstrained least squares (eq. 3.12, Case 1);
* :func:`~ident.solvers.exact.solve_exact` -- the constrained optimum under eq. 3.8, found
  numerically (reduced objective + global search) and certified by the KKT conditions;
* :func:`~ident.solvers.ga.solve_ga` -- the genetic algorithm of section 4.2 on the
  reduced objective of eq. 4.12.

All take ``(Phi (N, 8), Y (N,), bounds, **options)`` and return a
:class:`~ident.solvers.common.SolverResult`.  :func:`solve` picks one by name.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from core.errors import InputError
from ident.model import Bounds
from ident.solvers.common import ReducedObjective, SolverResult
from ident.solvers.exact import solve_exact
from ident.solvers.ga import solve_ga
from ident.solvers.ls import solve_ls

__all__ = ["SOLVERS", "solve", "solve_ls", "solve_exact", "solve_ga", "SolverResult", "ReducedObjective"]

#: Solver name -> function, as accepted by ``agent identify --solver``.
SOLVERS: dict[str, Callable[..., SolverResult]] = {"exact": solve_exact, "ga": solve_ga, "ls": solve_ls}


def solve(name: str, Phi: np.ndarray, Y: np.ndarray, bounds: Bounds | None = None, **options: Any) -> SolverResult:
    """Run the solver called ``name`` ("exact", "ga" or "ls"); ``bounds`` default to :class:`Bounds()`."""
    try:
        fn = SOLVERS[name]
    except KeyError:
        raise InputError(f"unknown solver {name!r}; choose one of {', '.join(SOLVERS)}") from None
    return fn(Phi, Y, Bounds() if bounds is None else bounds, **options)

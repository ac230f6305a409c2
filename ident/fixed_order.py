"""Linear algebra of the Gauss–Newton steps in a fixed order of operations.

The output-error fits (:func:`ident.least_squares.bounded_lm`) follow costs that ripple on
a fine scale (friction sticking, a gap closing): a difference in the last bit of one step
can send a search into another valley.  BLAS and LAPACK do not fix their order of
operations — it depends on the CPU's kernel (with or without FMA, the width of its
vectors) and on the number of threads — so ``J.T @ J`` or ``np.linalg.solve`` made the
same recording give other parameters, even another verdict, on another machine (measured:
the concealed Stribeck fixture named with OpenBLAS's Haswell kernels and not with its
Sandybridge ones).  These compiled loops do the same few products in one written order
(IEEE arithmetic, no fast-math, no contraction), so the results are the same bit for bit
on any x86-64 machine, under any load and thread count.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["dot", "normal_products", "sum_squares", "solve", "weighted_rows"]

#: Independent partial sums per dot product (combined in a fixed order): four keep the
#: adder's pipeline busy without making the order depend on the machine.
_LANES = 4


@njit(cache=True, nogil=True)
def _dot(a: np.ndarray, b: np.ndarray) -> float:
    m = a.size
    s0 = s1 = s2 = s3 = 0.0
    k = 0
    while k + _LANES <= m:
        s0 += a[k] * b[k]
        s1 += a[k + 1] * b[k + 1]
        s2 += a[k + 2] * b[k + 2]
        s3 += a[k + 3] * b[k + 3]
        k += _LANES
    while k < m:
        s0 += a[k] * b[k]
        k += 1
    return (s0 + s1) + (s2 + s3)


@njit(cache=True, nogil=True)
def _normal(J: np.ndarray, r: np.ndarray):
    n = J.shape[1]
    A = np.empty((n, n))
    g = np.empty(n)
    for i in range(n):
        ci = J[:, i]
        for j in range(i, n):
            A[i, j] = A[j, i] = _dot(ci, J[:, j])
        g[i] = _dot(ci, r)
    return A, g


def normal_products(J: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``JᵀJ`` and ``Jᵀr`` of the Gauss–Newton normal equations, in a fixed order."""
    return _normal(np.asfortranarray(J, dtype=np.float64), np.ascontiguousarray(r, dtype=np.float64))


def dot(a: np.ndarray, b: np.ndarray) -> float:
    """``aᵀb`` of two vectors in a fixed order."""
    return float(_dot(np.ascontiguousarray(a, dtype=np.float64), np.ascontiguousarray(b, dtype=np.float64)))


def sum_squares(r: np.ndarray) -> float:
    """``rᵀr`` in a fixed order."""
    r = np.ascontiguousarray(r, dtype=np.float64)
    return float(_dot(r, r))


@njit(cache=True, nogil=True)
def _weighted_rows(Y, cols, x, w, out, diverged):
    for p in range(Y.shape[0]):
        for i in range(cols.size):
            out[p, i] = w[i] * (Y[p, cols[i]] - x[i])
        s = _dot(out[p], out[p])
        if not np.isfinite(s):
            out[p, :] = diverged


def weighted_rows(Y: np.ndarray, cols: np.ndarray | None, x: np.ndarray, w: np.ndarray,
                  diverged: float = 1e3) -> np.ndarray:
    """Weighted residuals of simulations: row p is ``w·(Y[p, cols] − x)`` (``cols`` None: every
    column, in place in ``Y``), and all ``diverged`` where its sum of squares is not finite
    (a NaN, an inf or an overflow: a simulation that diverged).  One pass over each row, the
    sum of squares in :func:`sum_squares`'s order."""
    Y = np.asarray(Y)
    if cols is None:
        cols = np.arange(Y.shape[1])
        out = Y
    else:
        out = np.empty((Y.shape[0], cols.size))
    _weighted_rows(Y, cols, np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(w, dtype=np.float64),
                   out, float(diverged))
    return out


@njit(cache=True, nogil=True)
def _lu_solve(A: np.ndarray, b: np.ndarray):
    """Gaussian elimination with partial pivoting (the first largest pivot); ok False if singular."""
    n = b.size
    M = A.copy()
    x = b.copy()
    for c in range(n):
        p = c
        for i in range(c + 1, n):
            if abs(M[i, c]) > abs(M[p, c]):
                p = i
        if M[p, c] == 0.0:
            return x, False
        if p != c:
            for j in range(n):
                M[c, j], M[p, j] = M[p, j], M[c, j]
            x[c], x[p] = x[p], x[c]
        for i in range(c + 1, n):
            f = M[i, c] / M[c, c]
            for j in range(c + 1, n):
                M[i, j] -= f * M[c, j]
            x[i] -= f * x[c]
    for i in range(n - 1, -1, -1):
        s = x[i]
        for j in range(i + 1, n):
            s -= M[i, j] * x[j]
        x[i] = s / M[i, i]
    return x, True


def solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The solution of the small square system ``A x = b`` in a fixed order.

    Raises
    ------
    numpy.linalg.LinAlgError
        A is singular (a zero pivot).
    """
    x, ok = _lu_solve(np.ascontiguousarray(A, dtype=np.float64), np.ascontiguousarray(b, dtype=np.float64))
    if not ok:
        raise np.linalg.LinAlgError("singular matrix")
    return x

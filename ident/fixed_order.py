"""Linear algebra of the fits in a fixed order of operations.

The output-error fits (:func:`ident.least_squares.bounded_lm`, :mod:`ident.refine`) follow
costs that ripple on a fine scale (friction sticking, a gap closing): a difference in the
last bit of one step can send a search into another valley.  BLAS and LAPACK do not fix
their order of operations — it depends on the CPU's kernel (with or without FMA, the width
of its vectors) and on the number of threads — so ``J.T @ J``, ``np.linalg.solve`` or
``np.linalg.lstsq`` made the same recording give other parameters, even another verdict,
on another machine (measured: drive-zoo-dev's case_018 named a resonance with OpenBLAS's
SkylakeX kernels and backlash with its Haswell ones, from an equation-error model that
differed in its 16th digit).  These compiled loops do the same products in one written
order (IEEE arithmetic, no fast-math, no contraction), so the results are the same bit for
bit on any x86-64 machine, under any load and thread count: dot products and sums of
squares, the Gauss–Newton normal equations, small square solves, Householder QR and the
least squares it gives (the regression of eq. 3.11 and the diagnosis's fits), and
matrix–vector products.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["dot", "lstsq", "matvec", "moving_mean", "norm", "normal_products", "qr_r", "solve", "solve_upper",
           "sum_squares", "unit_columns", "weighted_rows"]

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


@njit(cache=True, nogil=True)
def _householder(A: np.ndarray, n: int) -> None:
    """Householder triangularisation of the first ``n`` columns of ``A`` (Fortran order),
    applied to every column: afterwards ``A[:n, :n]`` is R and each further column is Qᵀ
    times the column it was.  Reflections with a positive diagonal, in a written order."""
    m, ncol = A.shape
    for k in range(min(n, m)):
        v = A[k:, k]
        nx = np.sqrt(_dot(v, v))
        if nx == 0.0:
            continue
        alpha = -nx if v[0] >= 0.0 else nx
        v[0] -= alpha
        vv = _dot(v, v)
        for j in range(k + 1, ncol):
            c = A[k:, j]
            s = 2.0 * _dot(v, c) / vv
            for i in range(c.size):
                c[i] -= s * v[i]
        A[k, k] = alpha
        for i in range(k + 1, m):
            A[i, k] = 0.0
        if alpha < 0.0:  # R with a positive diagonal: flip row k of R and of Qᵀ·(further columns)
            for j in range(k, ncol):
                A[k, j] = -A[k, j]


def qr_r(Z: np.ndarray) -> np.ndarray:
    """R of ``Z = QR`` (Householder, square n×n for Z m×n with m ≥ n, positive diagonal where
    the column is not zero), in a fixed order: the same bits on any machine."""
    A = np.array(Z, dtype=np.float64, order="F")
    n = A.shape[1]
    _householder(A, n)
    return np.triu(A[: min(n, A.shape[0]), :])


@njit(cache=True, nogil=True)
def _back_substitute(R: np.ndarray, b: np.ndarray, tol: float) -> np.ndarray:
    n = b.size
    x = np.zeros(n)
    for i in range(n - 1, -1, -1):
        if abs(R[i, i]) <= tol:  # a column the others already span: left out (its weight 0)
            continue
        s = b[i]
        for j in range(i + 1, n):
            s -= R[i, j] * x[j]
        x[i] = s / R[i, i]
    return x


def lstsq(A: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least-squares solution of ``A x ≈ y`` (A m×n, m ≥ n) by Householder QR, in a fixed order.

    Replaces ``np.linalg.lstsq(A, y, rcond=None)`` where its last bits must not depend on the
    machine.  On a full-rank A the two agree to rounding.  A column within ``max(m, n)·eps`` of
    the span of those before it (relative to R's largest diagonal) gets weight 0 — the
    *basic* solution, where LAPACK's SVD would return the minimum-norm one."""
    A = np.asarray(A, dtype=np.float64)
    m, n = A.shape
    if m < n:
        raise ValueError(f"lstsq needs at least as many rows as columns, got {A.shape}")
    Z = np.empty((m, n + 1), order="F")
    Z[:, :n] = A
    Z[:, n] = y
    _householder(Z, n)
    R = Z[:n, :n]
    d = np.abs(np.diag(R))
    tol = max(m, n) * np.finfo(float).eps * (float(d.max()) if d.size else 0.0)
    return _back_substitute(np.ascontiguousarray(R), np.ascontiguousarray(Z[:n, n]), tol)


def unit_columns(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(A / s, s)``: the columns of A scaled to unit norm (a zero column left as it is), so
    that least squares on A is conditioned by the columns' directions, not their units (eq.
    3.12's columns span mm, mm/s and mm/s²).  ``θ = lstsq(A / s, y) / s``.  Each norm is a
    sum down one column (numpy reduces along the first axis of a C array row by row: one
    order on every machine)."""
    s = np.linalg.norm(A, axis=0)
    s[s == 0] = 1.0
    return A / s, s


@njit(cache=True, nogil=True)
def _matvec(A: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    for i in range(A.shape[0]):
        s = 0.0
        for j in range(A.shape[1]):
            s += A[i, j] * x[j]
        out[i] = s


def matvec(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A x`` (A m×n, x n), each row summed left to right: the same bits on any machine."""
    A = np.asarray(A, dtype=np.float64)
    out = np.empty(A.shape[0])
    _matvec(A, np.ascontiguousarray(x, dtype=np.float64), out)
    return out


def solve_upper(R: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``R⁻¹ B`` for an upper-triangular, non-singular R (B a vector or a matrix of
    columns) by back-substitution in a fixed order (``scipy.linalg.solve_triangular``'s
    result without its machine-dependent BLAS)."""
    R = np.ascontiguousarray(R, dtype=np.float64)
    B = np.asarray(B, dtype=np.float64)
    if B.ndim == 1:
        return _back_substitute(R, np.ascontiguousarray(B), 0.0)
    return np.column_stack([_back_substitute(R, np.ascontiguousarray(B[:, j]), 0.0) for j in range(B.shape[1])])


def norm(v: np.ndarray) -> float:
    """‖v‖₂ of a vector in a fixed order (``np.linalg.norm`` of a vector is a BLAS dot)."""
    return float(np.sqrt(sum_squares(v)))


@njit(cache=True, nogil=True)
def _moving_mean(y: np.ndarray, k: int, out: np.ndarray) -> None:
    n = y.size
    lead = (k - 1) // 2
    for i in range(n):
        lo, hi = max(i + lead - k + 1, 0), min(i + lead, n - 1)
        s = 0.0
        for j in range(lo, hi + 1):
            s += y[j]
        out[i] = s / k


def moving_mean(y: np.ndarray, k: int) -> np.ndarray:
    """Mean over ``k`` samples centred as ``np.convolve(y, np.ones(k) / k, mode="same")``
    centres it (zeros beyond the ends), each window summed left to right — numpy's
    convolve is a BLAS dot, whose order is the machine's."""
    y = np.ascontiguousarray(y, dtype=np.float64)
    out = np.empty(y.size)
    _moving_mean(y, int(k), out)
    return out

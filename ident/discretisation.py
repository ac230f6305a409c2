"""Exact first-order-hold discretisation of eq. 3.3's linear part, for the simulator kernel.

Eq. 3.3 with the integral state ``z = ∫(x_r − x) dt`` and state ``s = [z, x, ẋ]``::

    ṡ = A s + B w,   A = [[0, −1, 0], [0, 0, 1], [a3, −a2, −a1]],   B = [[1, 0], [0, 0], [0, 1]]

with the inputs ``w = [x_r, g]``: the command position (it drives ż) and the acceleration
``g`` that is not proportional to the state (the command drive ``b0·ẍ_r + b1·ẋ_r + b2·x_r``
less friction, plus any effect's force).  For inputs linear over a step ``h``,
``w(t+τ) = w + τ·ẇ``, the state advances exactly as ``s(t+h) = Φ s + Γ0 w + Γ1 ẇ``: the
blocks of ``exp([[A, B, 0], [0, 0, I], [0, 0, 0]]·h)`` — exact for any pole location, so
there is no stiffness limit on the step.

Written with loops in numba and generic in the number type: in complex128 (parameters
``p + i·ε·d``) the blocks carry their exact derivatives for the complex-step sensitivities
(:func:`ident.diagnosis.augmented.sensitivities`); the only branch (the number of squarings)
is decided on the real part, so the float64 blocks are the same either way.  scipy's
``expm`` is not used: it goes through multi-threaded BLAS, which costs milliseconds on a
loaded machine for a 7×7 matrix.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["balanced", "foh_blocks"]


@njit(cache=True, nogil=True)
def _matmul(A, B):  # pragma: no cover - numba
    """Small dense product with plain loops, in the number type of ``A``."""
    n, k = A.shape
    m = B.shape[1]
    C = np.zeros((n, m)) + 0.0 * A[0, 0]
    for i in range(n):
        for j in range(m):
            acc = 0.0 * A[0, 0]
            for r in range(k):
                acc += A[i, r] * B[r, j]
            C[i, j] = acc
    return C


@njit(cache=True, nogil=True)
def _expm(M):  # pragma: no cover - numba
    """exp(M) by scaling and squaring with a degree-18 Taylor series (‖Re M/2^s‖₁ ≤ 0.5).

    Truncation error ≤ 0.5^19/19! ≈ 1.6e-23 relative before squaring: exact to rounding.
    """
    n = M.shape[0]
    norm = 0.0
    for j in range(n):
        c = 0.0
        for i in range(n):
            c += abs(M[i, j].real)
        norm = max(norm, c)
    s = 0
    while norm > 0.5:
        norm *= 0.5
        s += 1
    A = M / (2.0**s)
    E = np.eye(n) + 0.0 * M[0, 0]
    term = np.eye(n) + 0.0 * M[0, 0]
    for k in range(1, 19):
        term = _matmul(term, A) / k
        E += term
    for _ in range(s):
        E = _matmul(E, E)
    return E


@njit(cache=True, nogil=True)
def balanced(a1, a2, a3, h):  # pragma: no cover - numba
    """``(M, S)``: the augmented matrix of eq. 3.3's linear part times ``h``, balanced by the
    state and input scales ``S`` (z, x, ẋ, x_r, g, ẋ_r, ġ: powers of a rate ω, a power of two,
    that makes a1, √a2 and ∛a3 entries of one size), in the number type of ``a1`` and ``h``.
    Every entry of M is at most a few times ω·h."""
    lam = max(abs(a1.real), np.sqrt(abs(a2.real)), np.cbrt(abs(a3.real)), 1.0)
    w = 2.0 ** np.round(np.log2(lam))
    S = np.array([1.0 / w, 1.0, w, 1.0, w * w, w, w * w * w])
    M = np.zeros((7, 7)) + 0.0 * a1 + 0.0 * h
    M[0, 1] = -1.0
    M[1, 2] = 1.0
    M[2, 0] = a3
    M[2, 1] = -a2
    M[2, 2] = -a1
    M[0, 3] = 1.0
    M[2, 4] = 1.0
    M[3, 5] = 1.0
    M[4, 6] = 1.0
    for i in range(7):
        for j in range(7):
            M[i, j] = M[i, j] * (S[j] / S[i] * h)
    return M, S


@njit(cache=True, nogil=True)
def foh_blocks(a1, a2, a3, h):  # pragma: no cover - numba
    """``(Φ, Γ0, Γ1)`` of eq. 3.3's linear part over a step ``h`` (s): Φ (3×3), Γ0 and Γ1 (3×2)
    for the inputs ``[x_r, g]`` (mm, mm/s²), in the number type of ``a1``.

    The augmented matrix is balanced before the exponential: z, x and ẋ (and the inputs) are
    rescaled by powers of a rate ω (a power of two, so the rescaling rounds nothing) that
    makes a1, √a2 and ∛a3 entries of one size.  Unbalanced, a3·h (10⁶·10⁻⁴) forces several
    squarings whose rounding the free run then accumulates over every sub-step.
    """
    M, S = balanced(a1, a2, a3, h)
    E = _expm(M)
    for i in range(3):
        for j in range(7):
            E[i, j] = E[i, j] * (S[i] / S[j])
    return E[:3, :3].copy(), E[:3, 3:5].copy(), E[:3, 5:7].copy()

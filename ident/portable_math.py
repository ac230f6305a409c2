"""Elementary functions of arrays whose last bits do not depend on the CPU.

numpy picks its ``exp``, ``log``, ``power``, ``arctan`` … loops at import by the CPU's SIMD
extensions: on a CPU with AVX-512 the float64 ``exp`` and ``log`` are vectorised
approximations that differ in the last bits from the scalar C library's, which numpy uses
on an AVX2 CPU.  A grid of starts (``np.geomspace``) or a column of a regression that
differs in its last bits sends a rippled search elsewhere, so the same recording could
give another verdict on another machine.  These loops call the C library's ``exp`` and
``log`` element by element (numba compiles them to scalar calls: LLVM has no vector
library to substitute here), as every other scalar in the product does.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["exp", "log", "geomspace"]


@njit(cache=True, nogil=True)
def _exp(x: np.ndarray, out: np.ndarray) -> None:
    for i in range(x.size):
        out[i] = math.exp(x[i])


@njit(cache=True, nogil=True)
def _log(x: np.ndarray, out: np.ndarray) -> None:
    for i in range(x.size):
        v = x[i]
        out[i] = math.log(v) if v > 0.0 else (-math.inf if v == 0.0 else math.nan)


def _elementwise(kernel, x) -> np.ndarray | float:
    a = np.asarray(x, dtype=np.float64)
    flat = np.ascontiguousarray(a).ravel()
    out = np.empty_like(flat)
    kernel(flat, out)
    return float(out[0]) if a.ndim == 0 else out.reshape(a.shape)


def exp(x) -> np.ndarray | float:
    """``e**x`` elementwise, the C library's value for every element (a float for a scalar)."""
    return _elementwise(_exp, x)


def log(x) -> np.ndarray | float:
    """Natural logarithm elementwise (−inf at 0, NaN below), the C library's value."""
    return _elementwise(_log, x)


def geomspace(start: float, stop: float, num: int) -> np.ndarray:
    """``num`` points from ``start`` to ``stop`` (both > 0) evenly spaced in log scale, the ends
    exactly ``start`` and ``stop`` (``np.geomspace`` for positive ends, machine-independent)."""
    if not (start > 0 and stop > 0):
        raise ValueError(f"geomspace needs positive ends, got {start!r} and {stop!r}")
    out = exp(np.linspace(math.log(start), math.log(stop), int(num)))
    if out.size:
        out[0] = start
        out[-1] = stop
    return out

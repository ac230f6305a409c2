"""Arithmetic for kernels written once for float64 and for the complex step.

A numba kernel generic in its number type runs in complex128 to give exact derivatives by
the complex step (Squire & Trapp 1998; Martins, Sturdza & Alonso 2003): parameters
``p + i·h·d`` with h = 1e-30, every imaginary part is then h times a derivative, and terms
of order h² lie far below the real part's rounding.  Complex division and the complex
exp/sin/cos spend most of their work on those h² terms (Smith's division with its branches,
cosh and sinh of the imaginary part); these functions drop them:

* ``div(a, b)`` = a/b, for complex ``Re = Re a / Re b`` and ``Im = (Im a − q·Im b) / Re b``;
* ``exp``, ``sin``, ``cos`` of ``a + ib`` = f(a) + i·b·f′(a).

On float64 each is the plain operation (``a / b``, ``np.exp`` …), so a float run is bit for
bit what it is without them; on complex128 the real part is the float64 result (the same
branches are taken) and the imaginary part the derivative to the real part's precision.
"""

from __future__ import annotations

import numpy as np
from numba import types
from numba.extending import overload

__all__ = ["div", "exp", "sin", "cos"]


def div(a, b):
    """``a / b`` (the complex step's form inside numba kernels)."""
    return a / b


def exp(x):
    """``exp(x)`` (the complex step's form inside numba kernels)."""
    return np.exp(x)


def sin(x):
    """``sin(x)`` (the complex step's form inside numba kernels)."""
    return np.sin(x)


def cos(x):
    """``cos(x)`` (the complex step's form inside numba kernels)."""
    return np.cos(x)


def _complex(*ts) -> bool:
    return any(isinstance(t, types.Complex) for t in ts)


@overload(div, inline="always")
def _div(a, b):
    if _complex(a, b):
        def impl(a, b):
            q = a.real / b.real
            return complex(q, (a.imag - q * b.imag) / b.real)
        return impl
    return lambda a, b: a / b


@overload(exp, inline="always")
def _exp(x):
    if _complex(x):
        def impl(x):
            e = np.exp(x.real)
            return complex(e, e * x.imag)
        return impl
    return lambda x: np.exp(x)


@overload(sin, inline="always")
def _sin(x):
    if _complex(x):
        return lambda x: complex(np.sin(x.real), np.cos(x.real) * x.imag)
    return lambda x: np.sin(x)


@overload(cos, inline="always")
def _cos(x):
    if _complex(x):
        return lambda x: complex(np.cos(x.real), -np.sin(x.real) * x.imag)
    return lambda x: np.cos(x)

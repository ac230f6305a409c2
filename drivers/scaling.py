"""Integer position counts -> mm (deg): the one conversion every transport uses.

Controllers send positions as integer counts with a fixed step: Modbus maps give the
step (``scale_mm``, mm per count), DBC signals a factor (mm per bit), serial info frames
and the CAN ``scale=`` option give counts per mm.  Every driver turns counts into mm as
``counts / counts_per_unit`` with :func:`counts_per_unit` exact when the step is the
inverse of an integer: 12345 counts at 1e-4 mm is then 12345 / 10000 = 1.2345, the double
nearest the exact decimal, whereas 12345 x 1e-4 = 1.2345000000000002 (two roundings).
"""

from __future__ import annotations

__all__ = ["counts_per_unit"]


def counts_per_unit(step: float) -> float:
    """Counts per mm (deg) of a step in mm (deg) per count; an exact integer when it is one (1e-6 -> 1e6)."""
    inv = round(1.0 / step)
    return float(inv) if inv > 0 and abs(inv * step - 1.0) < 1e-12 else 1.0 / step

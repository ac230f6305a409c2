"""The path control mode of each block of a program, in the planner's terms: exact stop
(G61, G61.1, canned cycles) or blending with a tolerance (G64 P…).

The interpreter keeps the mode modal from block to block and records it on each block
(:attr:`gcode_gen.program.Block.blend_tolerance`: None for exact stop, ``inf`` for G64
without P, else P in mm); this module states it by program line for the planner.
"""

from __future__ import annotations

import math
from typing import Iterable

from gcode_gen.program import Block

__all__ = ["path_tolerances"]


def path_tolerances(blocks: Iterable[Block]) -> dict[int, float | None]:
    """Program line (1-based) -> the blending tolerance in force for its block, mm: 0.0 for
    exact stop, the P value of G64 P…, None for G64 without P (blend at any deviation)."""
    out: dict[int, float | None] = {}
    for b in blocks:
        tol = b.blend_tolerance
        out[b.line] = 0.0 if tol is None else (None if math.isinf(tol) else float(tol))
    return out

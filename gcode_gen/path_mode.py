"""The path control mode of each block of a program: exact stop (G61, G61.1) or blending
with a tolerance (G64 P…), as the controller keeps it modal from line to line.

The interpreter (gcode_gen.interpreter) accepts these words without recording them; the
planner needs them, so they are read here from the program's text.
"""

from __future__ import annotations

import re

__all__ = ["path_tolerances"]

_COMMENT = re.compile(r"\([^)]*\)|;.*")
_WORD = re.compile(r"G0*(64|61\.1|61)(?![.\d])(?:P([-+]?[\d.]+))?")


def path_tolerances(text: str) -> dict[int, float | None]:
    """Line number (1-based) -> the blending tolerance in force there, mm: 0.0 for exact stop
    (the default), the P value of G64 P…, None for G64 without P (blend at any deviation)."""
    out: dict[int, float | None] = {}
    mode: float | None = 0.0
    for number, raw in enumerate(text.splitlines(), start=1):
        line = _COMMENT.sub("", raw).upper().replace(" ", "")
        for m in _WORD.finditer(line):
            if m.group(1) == "64":
                mode = float(m.group(2)) if m.group(2) else None
            else:
                mode = 0.0
        out[number] = mode
    return out

"""ISO 6983 / Fanuc-style writer, as thesis Table 3.2 (``N0010 G01 X-0.790``).

Layout: ``%`` wrappers, comments ``( )``, then N-numbered blocks in steps of 10:
``G21 G90 G17 G94`` (mm, absolute, XY plane, feed per minute), ``G61`` exact-stop mode
(Fanuc: decelerate to rest at every block end; ``G64 P0.01`` when blending), a ``G00``
to the start point, ``G01``/``G02``/``G03`` blocks with ``F`` in mm/min (written when it
changes), ``M30``.

Arcs use I/J centre offsets relative to the arc start — which is the previous target; the
writer computes them from the toolpath's absolute centre.
"""

from __future__ import annotations

from gcode_gen.dialects._rs274 import write_rs274
from gcode_gen.program import Toolpath

__all__ = ["write"]


def write(toolpath: Toolpath) -> str:
    """ISO text of ``toolpath``."""
    return write_rs274(toolpath, dialect="iso", numbered=True, two_digit=True,
                       preamble=["G21 G90 G17 G94"], exact_stop="G61", end="M30")

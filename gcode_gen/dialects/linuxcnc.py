"""LinuxCNC RS274NGC writer: a program LinuxCNC runs as is.

Layout: ``%`` on the first and last line (LinuxCNC ignores anything after the closing
``%``), ``( )`` comments (none starting with ``debug,``/``print,``/``msg,``, which LinuxCNC
treats as commands), ``G21 G90 G17 G94`` (mm, absolute, XY plane, units per minute),
path mode written explicitly — ``G61.1`` exact stop (in LinuxCNC plain ``G61`` is "exact
path", which does not stop between collinear moves; ``G61.1`` stops at the end of every
segment, as the interpolator's default does), or ``G64 P0.01`` blending with a 0.01 mm
tolerance when asked — then ``G0``/``G1``/``G2``/``G3`` with ``F`` in mm/min and
``M2`` program end.  Arcs use I/J offsets (incremental arc distance mode, G91.1, the
LinuxCNC default).  No spindle, coolant or tool change words are written.
"""

from __future__ import annotations

from gcode_gen.dialects._rs274 import write_rs274
from gcode_gen.program import Toolpath

__all__ = ["write"]


def write(toolpath: Toolpath) -> str:
    """LinuxCNC text of ``toolpath``."""
    return write_rs274(toolpath, dialect="linuxcnc", numbered=False, two_digit=False,
                       preamble=["G21 G90 G17 G94 G40 G49"], exact_stop="G61.1", end="M2")

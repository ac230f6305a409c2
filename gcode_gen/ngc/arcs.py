"""Arc geometry shared by the interpreters: centres, radius checks, sweeps.

Conventions (LinuxCNC's, see gcode_gen/program.py): an arc lies in a plane with a first and a
second axis (XY: X, Y; XZ: Z, X; YZ: Y, Z); G3 turns counter-clockwise from the first axis
towards the second, G2 clockwise.
"""

from __future__ import annotations

import math

from gcode_gen.program import ARC_ORDER

__all__ = ["ArcError", "PLANES", "center_from_radius", "check_radii", "sweep"]

_OFFSET_LETTER = {"X": "i", "Y": "j", "Z": "k"}
#: plane -> (first axis, second axis, normal axis, first offset letter, second offset letter),
#: the axes in :data:`gcode_gen.program.ARC_ORDER`'s order
PLANES = {plane: (a1, a2, ({"X", "Y", "Z"} - {a1, a2}).pop(), _OFFSET_LETTER[a1], _OFFSET_LETTER[a2])
          for plane, (a1, a2) in ARC_ORDER.items()}


class ArcError(ValueError):
    """The arc cannot be made (radius too short, radii differ, zero radius)."""


def center_from_radius(x0: float, y0: float, x1: float, y1: float, r: float, clockwise: bool) -> tuple[float, float]:
    """Arc centre from the chord and radius; r < 0 selects the arc longer than 180°."""
    dx, dy = x1 - x0, y1 - y0
    chord = math.hypot(dx, dy)
    if chord < 1e-9:
        raise ArcError("radius-format arc cannot be a full circle (use I/J/K)")
    if abs(r) < chord / 2 - 1e-6:
        raise ArcError(f"arc radius {abs(r):.4f} mm is shorter than half the chord {chord / 2:.4f} mm")
    h = math.sqrt(max(r * r - chord * chord / 4, 0.0))
    nx, ny = -dy / chord, dx / chord  # left normal of the chord
    side = -1.0 if clockwise else 1.0
    if r < 0:
        side = -side
    return (x0 + dx / 2 + side * h * nx, y0 + dy / 2 + side * h * ny)


def check_radii(r0: float, r1: float, inch: bool) -> None:
    """LinuxCNC's spiral tolerance: the start and end radius (mm) may differ by at most
    100·tol, and by at most tol when they also differ by more than 0.1 %, where tol is
    2·0.01·√2 mm (2·0.001·√2 in in G20)."""
    if min(r0, r1) < 1e-9:
        raise ArcError("arc radius is zero")
    tol = 2 * (0.001 * 25.4 if inch else 0.01) * math.sqrt(2.0)
    err = abs(r0 - r1)
    if err > 100 * tol or (err / max(r0, r1) > 0.001 and err > tol):
        raise ArcError(f"arc end radius {r1:.4f} mm differs from start radius {r0:.4f} mm")


def sweep(start: tuple[float, float], end: tuple[float, float], centre: tuple[float, float], ccw: bool,
          turns: int = 1) -> float:
    """Angle swept (rad, > 0) from ``start`` to ``end`` about ``centre``; end = start is a full
    circle; ``turns`` adds full circles."""
    th0 = math.atan2(start[1] - centre[1], start[0] - centre[0])
    th1 = math.atan2(end[1] - centre[1], end[0] - centre[0])
    d = (th1 - th0) % (2 * math.pi) if ccw else (th0 - th1) % (2 * math.pi)
    return (d or 2 * math.pi) + 2 * math.pi * (turns - 1)

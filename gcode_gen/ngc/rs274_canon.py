"""LinuxCNC's ``rs274`` interpreter as a reference: run it, read its canonical commands.

``rs274 -g program.ngc`` prints one canonical machining command per line::

    12 N..... STRAIGHT_TRAVERSE(1.7246, -1.0127, 1.0000, 0.0000, 0.0000, 0.0000)
    18 N..... ARC_FEED(1.6133, -1.1787, 0.0119, 0.0161, -1, -0.1000, 0.0000, 0.0000, 0.0000)

with coordinates in the program's current length unit (``USE_LENGTH_UNITS``) and in the
program coordinate system: the G5x and G92 offsets (``SET_G5X_OFFSET``,
``SET_G92_OFFSET``) and the tool length offset (``USE_TOOL_LENGTH_OFFSET``) are printed
separately and applied by LinuxCNC's motion layer.  :func:`parse_canon` replays them into
machine positions in mm — the same coordinates :mod:`gcode_gen.ngc` gives its blocks — so
the two interpreters can be compared move by move.  ``ARC_FEED`` arguments are (first end,
second end, first centre, second centre, rotation, axis end, a, b, c[, u, v, w]) with the
plane's axes in LinuxCNC's order (XY: X Y | Z, XZ: Z X | Y, YZ: Y Z | X); the rotation is
+turns counter-clockwise, −turns clockwise.  Values are printed with 4 decimals.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

from gcode_gen.ngc.arcs import PLANES

__all__ = ["Agreement", "CanonMove", "Rs274Run", "compare", "parse_canon", "run_rs274", "RS274"]

RS274 = shutil.which("rs274")
_CALL = re.compile(r"^\s*\d+\s+N[.\d ]*?\s*([A-Z_0-9]+)\((.*)\)\s*$")
_AXES = ("X", "Y", "Z", "A", "B", "C", "U", "V", "W")
_PLANE_AXES = {plane: axes[:3] for plane, axes in PLANES.items()}  # first, second, normal


@dataclass(frozen=True)
class CanonMove:
    """One motion of the canonical output, machine coordinates in mm (degrees for A B C).

    kind : "G0" (STRAIGHT_TRAVERSE), "G1" (STRAIGHT_FEED), "G2"/"G3" (ARC_FEED), "G4" (DWELL).
    end : position of every axis after the move.
    center : arc centre on the plane's two axes; plane "XY", "XZ" or "YZ"; turns ≥ 1.
    feed : mm/s of a feed move (SET_FEED_RATE in effect), None for G0 and G4.
    """

    kind: str
    end: dict[str, float] = field(default_factory=dict)
    center: dict[str, float] | None = None
    plane: str = "XY"
    turns: int = 1
    feed: float | None = None
    dwell_s: float | None = None


@dataclass(frozen=True)
class Rs274Run:
    """What rs274 did with a program: exit code, moves, its message (last stderr/stdout lines)."""

    returncode: int
    moves: list[CanonMove]
    message: str
    unsupported: str | None = None  # canonical command parse_canon cannot replay (rotation, NURBS…)


def _numbers(args: str) -> list[float]:
    return [float(v) for v in re.split(r"[,\s]+", args.strip()) if v]


def parse_canon(text: str) -> tuple[list[CanonMove], str | None]:
    """Moves of rs274's canonical output ``text`` and the first command it cannot replay."""
    unit = 1.0
    g5x = {a: 0.0 for a in _AXES}
    g92 = {a: 0.0 for a in _AXES}
    tlo = {a: 0.0 for a in _AXES}
    plane = "XY"
    feed_rate = 0.0
    pos = {a: 0.0 for a in _AXES}
    moves: list[CanonMove] = []
    unsupported = None

    def scale(a: str) -> float:
        return 1.0 if a in "ABC" else unit

    def machine(values: list[float]) -> dict[str, float]:
        return {a: v * scale(a) + g5x[a] + g92[a] + tlo[a] for a, v in zip(_AXES, values)}

    for raw in text.splitlines():
        m = _CALL.match(raw)
        if not m:
            continue
        name, args = m.group(1), m.group(2)
        if name == "USE_LENGTH_UNITS":
            unit = 25.4 if "INCHES" in args else 1.0
        elif name == "SET_G5X_OFFSET":
            vals = _numbers(args)[1:]
            g5x = {a: (vals[k] * scale(a) if k < len(vals) else 0.0) for k, a in enumerate(_AXES)}
        elif name == "SET_G92_OFFSET":
            vals = _numbers(args)
            g92 = {a: (vals[k] * scale(a) if k < len(vals) else 0.0) for k, a in enumerate(_AXES)}
        elif name == "USE_TOOL_LENGTH_OFFSET":
            vals = _numbers(args)
            tlo = {a: (vals[k] * scale(a) if k < len(vals) else 0.0) for k, a in enumerate(_AXES)}
        elif name == "SET_XY_ROTATION":
            if abs(_numbers(args)[0]) > 0 and unsupported is None:
                unsupported = f"SET_XY_ROTATION({args})"
        elif name == "SELECT_PLANE":
            plane = {"CANON_PLANE_XY": "XY", "CANON_PLANE_XZ": "XZ", "CANON_PLANE_YZ": "YZ"}.get(args.strip(), plane)
        elif name == "SET_FEED_RATE":
            feed_rate = _numbers(args)[0]
        elif name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED"):
            end = {**pos, **machine(_numbers(args))}
            kind = "G0" if name == "STRAIGHT_TRAVERSE" else "G1"
            moves.append(CanonMove(kind, end, feed=None if kind == "G0" else feed_rate * unit / 60.0))
            pos = end
        elif name == "ARC_FEED":
            v = _numbers(args)
            first, second, normal = _PLANE_AXES[plane]
            prog = {first: v[0], second: v[1], normal: v[5]}
            for a, value in zip(("A", "B", "C", "U", "V", "W"), v[6:]):
                prog[a] = value
            end = {**pos, **machine([prog.get(a, 0.0) for a in _AXES])}
            centre = {first: v[2] * unit + g5x[first] + g92[first] + tlo[first],
                      second: v[3] * unit + g5x[second] + g92[second] + tlo[second]}
            rotation = int(v[4])
            moves.append(CanonMove("G3" if rotation > 0 else "G2", end, centre, plane, abs(rotation),
                                   feed=feed_rate * unit / 60.0))
            pos = end
        elif name == "DWELL":
            moves.append(CanonMove("G4", dict(pos), dwell_s=_numbers(args)[0]))
        elif name in ("NURBS_FEED", "STRAIGHT_PROBE", "RIGID_TAP", "SPLINE_FEED") and unsupported is None:
            unsupported = name
    return moves, unsupported


def run_rs274(path: str | Path, *, tool_table: str | Path | None = None, timeout: float = 60.0) -> Rs274Run:
    """Run LinuxCNC's ``rs274`` in batch mode on ``path`` (with a tool table if given)."""
    if RS274 is None:
        raise FileNotFoundError("rs274 (LinuxCNC's interpreter, package linuxcnc-uspace) is not installed")
    cmd = [RS274, "-g"]
    if tool_table is not None:
        cmd[1:1] = ["-t", str(tool_table)]
    res = subprocess.run([*cmd, str(path)], capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL)
    moves, unsupported = parse_canon(res.stdout)
    tail = [ln for ln in (res.stderr + "\n" + res.stdout).splitlines() if ln.strip() and not _CALL.match(ln)
            and ln.strip() != "executing"]
    return Rs274Run(res.returncode, moves, " | ".join(tail[-2:]), unsupported)


@dataclass(frozen=True)
class Agreement:
    """Result of :func:`compare`: moves compared, the worst end-point and centre error (mm),
    and the first disagreement (None when they agree)."""

    n_moves: int
    max_end_error_mm: float
    max_center_error_mm: float
    problem: str | None


def _significant(moves: list[tuple[str, dict[str, float], object]], min_mm: float) -> list[int]:
    """Indices of moves that are not zero-length straight moves (both interpreters may emit
    those for a bare G0/G1; they move nothing)."""
    keep, prev = [], {a: 0.0 for a in _AXES}
    for k, (kind, end, _) in enumerate(moves):
        length = max((abs(end.get(a, prev[a]) - prev[a]) for a in _AXES), default=0.0)
        if kind in ("G2", "G3", "G4") or length > min_mm:
            keep.append(k)
        prev = {a: end.get(a, prev[a]) for a in _AXES}
    return keep


def compare(blocks, moves: list[CanonMove], *, tol_mm: float = 0.005, feed_rel: float = 1e-4) -> Agreement:  # noqa: ANN001
    """Compare our :class:`~gcode_gen.program.Block` list with rs274's moves.

    Same sequence of moves (zero-length straight moves dropped on both sides), same kind,
    end points within ``tol_mm`` on every axis, arc centres within ``tol_mm``, same plane
    and turns, same dwell, feeds within ``feed_rel`` (relative) + 0.001 mm/s.
    """
    ours_full, pos = [], {a: 0.0 for a in _AXES}
    for b in blocks:
        pos = {**pos, **b.target}
        ours_full.append((b.motion, dict(pos), b))
    theirs_full = [(m.kind, m.end, m) for m in moves]
    # 3 µm: a zero-length move rs274 prints after a change of units can round to 2.5 µm
    ours = [ours_full[k] for k in _significant(ours_full, 3e-3)]
    theirs = [theirs_full[k] for k in _significant(theirs_full, 3e-3)]
    worst_end = worst_centre = 0.0
    for k, ((kind, end, b), (tkind, tend, t)) in enumerate(zip(ours, theirs)):
        where = f"move {k + 1} (our line {b.line})"
        if kind != tkind:
            return Agreement(k, worst_end, worst_centre, f"{where}: ours {kind}, rs274 {tkind}")
        if kind == "G4":
            if abs((b.dwell_s or 0.0) - (t.dwell_s or 0.0)) > 1e-4:
                return Agreement(k, worst_end, worst_centre, f"{where}: dwell {b.dwell_s} s, rs274 {t.dwell_s} s")
            continue
        err = max(abs(end[a] - tend[a]) for a in _AXES)
        worst_end = max(worst_end, err)
        if err > tol_mm:
            axis = max(_AXES, key=lambda a: abs(end[a] - tend[a]))
            return Agreement(k, worst_end, worst_centre, f"{where}: end {axis} {end[axis]:.4f} mm, rs274 {tend[axis]:.4f} mm")
        if kind in ("G2", "G3"):
            if b.plane != t.plane or b.turns != t.turns:
                return Agreement(k, worst_end, worst_centre, f"{where}: arc plane/turns {b.plane}/{b.turns}, rs274 {t.plane}/{t.turns}")
            cerr = max(abs(b.center[a] - t.center[a]) for a in t.center)
            worst_centre = max(worst_centre, cerr)
            if cerr > tol_mm:
                return Agreement(k, worst_end, worst_centre, f"{where}: arc centre {b.center}, rs274 {t.center}")
        if kind != "G0":
            if b.feed is None or abs(b.feed - t.feed) > feed_rel * t.feed + 1e-3:
                return Agreement(k, worst_end, worst_centre, f"{where}: feed {b.feed} mm/s, rs274 {t.feed:.4f} mm/s")
    if len(ours) != len(theirs):
        return Agreement(min(len(ours), len(theirs)), worst_end, worst_centre,
                         f"{len(ours)} moves, rs274 {len(theirs)}")
    return Agreement(len(ours), worst_end, worst_centre, None)

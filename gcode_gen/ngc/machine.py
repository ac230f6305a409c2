"""The modal state of an RS274/NGC controller and the moves one block makes.

:class:`Machine` executes one lexed block (its words already evaluated) in LinuxCNC's order
of execution (feed mode, F, S, T, M6, spindle/coolant, dwell, plane, units, cutter
compensation, tool length offset, coordinate system, path mode, distance modes, retract
mode, G10/G28/G30/G92, motion, stops) and appends :class:`~gcode_gen.program.Block` moves.

Coordinates: the machine starts at the origin of machine coordinates, G54 active, no
offsets, mm, XY plane, G90, G91.1, G94, G64, G99 (rs274's start state without an INI file).  A
programmed value v of a linear axis in the active system is the machine position
``v·unit + G5x offset + G92 offset + tool length offset`` (mm); the blocks carry machine
positions.  Rotary axes are in degrees and never scaled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

from gcode_gen.ngc.arcs import PLANES, center_from_radius, check_radii, sweep
from gcode_gen.ngc.canned_cycles import SUPPORTED_CYCLES, CycleState, expand_cycle
from gcode_gen.ngc.codes import COORD_SYSTEMS, CodeError, split_block
from gcode_gen.ngc.cutter_comp import LEFT, RIGHT, CompError, CutterComp, QueuedMove
from gcode_gen.ngc.parameters import COORD_SYSTEM, G5X_BASE, G28_BASE, G30_BASE, G92_BASE, Parameters
from gcode_gen.ngc.tool_table import Tool
from gcode_gen.program import Block

__all__ = ["Machine", "AXES", "InterpError"]

AXES = ("X", "Y", "Z", "A", "B", "C", "U", "V", "W")
ROTARY = ("A", "B", "C")
INCH = 25.4
class InterpError(Exception):
    """A block cannot be executed; the flow adds file and line."""


@dataclass
class Modal:
    """The modal state saved by M70 and restored by M71/M72/M73."""

    unit: float = 1.0
    plane: str = "XY"
    absolute: bool = True
    arc_absolute: bool = False
    inverse_time: bool = False
    feed: float | None = None
    retract_initial: bool = False  # G98 (True) / G99 (False, rs274's start state)
    coord: int = 1
    blend: float | None = math.inf  # None: exact stop (G61/G61.1); inf: G64 without P; else G64 P (mm)
    motion: str | None = None


@dataclass
class Machine:
    """Controller state and the moves produced so far (see module docstring)."""

    params: Parameters
    tools: dict[int, Tool] | None = None
    dialect: str = "linuxcnc"
    blocks: list[Block] = field(default_factory=list)
    pos: dict[str, float] = field(default_factory=lambda: {a: 0.0 for a in AXES})
    modal: Modal = field(default_factory=Modal)
    g5x: dict[int, dict[str, float]] = field(default_factory=lambda: {i: {a: 0.0 for a in AXES} for i in range(1, 10)})
    g92: dict[str, float] = field(default_factory=lambda: {a: 0.0 for a in AXES})
    tlo: dict[str, float] = field(default_factory=lambda: {a: 0.0 for a in AXES})
    tool: int = 0
    selected: int = 0
    comp_radius: float = 0.0
    cycle: CycleState = field(default_factory=CycleState)
    saved_modal: Modal | None = None
    comp: CutterComp | None = None
    force_axes: set[str] = field(default_factory=set)  # axes the next move must name (after G40)
    actual: dict[str, float] = field(default_factory=lambda: {a: 0.0 for a in AXES})  # where the last move ended
    arc_not_allowed: bool = False
    line: int = 0
    n: int | None = None

    def __post_init__(self) -> None:
        self.comp = CutterComp(self._output_queued)

    def _output_queued(self, q: QueuedMove) -> None:
        """A compensated move leaves the queue: it becomes a block."""
        if q.kind == "G4":
            self.blocks.append(Block(line=q.line, n=q.n, motion="G4", target={}, dwell_s=q.dwell_s))
            return
        a1, a2 = q.axes
        target = {a1: q.x, a2: q.y, **q.rest}
        self.actual.update(target)
        centre = {a1: q.cx, a2: q.cy} if q.kind in ("G2", "G3") else None
        self.blocks.append(Block(line=q.line, n=q.n, motion=q.kind, target=target, feed=q.feed, center=centre,
                                 plane=q.plane, turns=max(1, abs(q.turn)) if centre else 1,
                                 blend_tolerance=self.modal.blend))

    def finish(self) -> None:
        """Program end: compensated moves still queued are made."""
        self.comp.dequeue()

    # ---- coordinates --------------------------------------------------------------------
    def offset(self, axis: str) -> float:
        """Machine position of program 0 on ``axis`` (mm): G5x + G92 + tool length offset."""
        return self.g5x[self.modal.coord][axis] + self.g92[axis] + self.tlo[axis]

    def scale(self, axis: str) -> float:
        return 1.0 if axis in ROTARY else self.modal.unit

    def program(self, axis: str) -> float:
        """Current position of ``axis`` in program units of the active system."""
        return (self.pos[axis] - self.offset(axis)) / self.scale(axis)

    def machine(self, axis: str, value: float) -> float:
        """Machine position (mm) of program-unit ``value`` on ``axis`` (absolute)."""
        return value * self.scale(axis) + self.offset(axis)

    def _mirror_offsets(self) -> None:
        """Write the offsets to their LinuxCNC parameter numbers (mm)."""
        for k, a in enumerate(AXES):
            self.params.set(G92_BASE + k, self.g92[a])
            for i in range(1, 10):
                self.params.set(G5X_BASE + 20 * (i - 1) + k, self.g5x[i][a])
        self.params.set(COORD_SYSTEM, float(self.modal.coord))

    # ---- output -------------------------------------------------------------------------
    def feed_mm_s(self, motion: str, length_mm: float) -> float | None:
        if motion == "G0":
            return None
        f = self.modal.feed
        if f is None:
            if self.modal.inverse_time:
                raise InterpError(f"{motion} move in inverse time feed (G93) needs F in its block")
            raise InterpError(f"{motion} move without a programmed feed (F)")
        if f <= 0:
            raise InterpError(f"{motion} move with feed F{f:g} (the feed must be positive)")
        if self.modal.inverse_time:
            return max(length_mm * f / 60.0, 1e-9)
        return f * self.modal.unit / 60.0

    def emit(self, motion: str, target: dict[str, float], *, center: dict[str, float] | None = None,
             plane: str = "XY", turns: int = 1, length_mm: float | None = None) -> None:
        moved = dict(target)
        for a, v in moved.items():
            if not math.isfinite(v):
                raise InterpError(f"{motion} to a non-finite {a} position ({v})")
        for a in self.force_axes:
            moved.setdefault(a, self.pos[a])
        self.force_axes = set()
        if length_mm is None:
            length_mm = math.sqrt(sum((moved[a] - self.pos[a]) ** 2 for a in moved if a not in ROTARY))
        self.blocks.append(Block(line=self.line, n=self.n, motion=motion, target=moved,
                                 feed=self.feed_mm_s(motion, length_mm), center=center, plane=plane, turns=turns,
                                 blend_tolerance=self.modal.blend))
        self.pos.update(moved)
        self.actual.update(moved)

    def dwell(self, seconds: float) -> None:
        if seconds < 0:
            raise InterpError(f"negative dwell {seconds:g} s")
        if self.comp.queue:
            self.comp.enqueue(QueuedMove("G4", dwell_s=seconds, line=self.line, n=self.n))
            return
        self.blocks.append(Block(line=self.line, n=self.n, motion="G4", target={}, dwell_s=seconds))

    # ---- one block ----------------------------------------------------------------------
    def execute(self, words: list[tuple[str, float]], on_end: Callable[[], None]) -> None:
        """Execute one block of evaluated words (letters lower case)."""
        try:
            codes = split_block(words)
        except CodeError as exc:
            raise InterpError(str(exc)) from None
        gs, ms, vals = codes.gs, codes.ms, codes.vals
        used: set[str] = {"n"}
        if self.modal.inverse_time and "f" not in vals:
            self.modal.feed = None  # G93: every feed block carries its own F

        # 2-3 feed mode and rate
        if 93.0 in gs:
            self.modal.inverse_time = True
            self.modal.feed = None
        if 94.0 in gs:  # LinuxCNC sets the feed to 0 with G94: a feed move needs a new F
            self.modal.inverse_time = False
            self.modal.feed = None
        if "f" in vals:
            if vals["f"] < 0:
                raise InterpError(f"feed F{vals['f']:g} must not be negative")
            self.modal.feed = vals["f"]
            used.add("f")
        used.add("s")
        # 5-6 tool select and change (no motion); M61 sets the tool number
        if "t" in vals:
            self.selected = int(vals["t"])
            self._check_tool(self.selected, "T")
            used.add("t")
        if 6 in ms:
            self._refuse_with_comp("tool change M6")
            self.tool = self.selected
            # LinuxCNC re-reads the position after a tool change: where the machine is, which
            # after G40 is the compensated point, not the programmed one the interpreter assumed.
            self.pos = dict(self.actual)
            self.force_axes = set()
        if 61 in ms:
            if "q" not in vals:
                raise InterpError("M61 without a tool number Q")
            self.tool = int(vals["q"])
            self._check_tool(self.tool, "M61 Q")
            used.add("q")
        if 70 in ms:
            self.saved_modal = self.snapshot()
        if 71 in ms or 72 in ms:
            if self.saved_modal is None:
                raise InterpError(f"M{71 if 71 in ms else 72}: no modal state saved by M70")
            self.restore(self.saved_modal)
            if 71 in ms:
                self.saved_modal = None
        if 73 in ms:
            self.on_m73()
        if 66 in ms or 67 in ms or 68 in ms:
            used |= {"p", "e", "l", "q"}
        if 19 in ms:
            used |= {"r", "q", "p"}
        # 10 dwell
        if 4.0 in gs:
            if self.dialect == "iso" and "x" in vals:
                seconds = vals.pop("x")  # ISO dwell time, not an axis
            elif "p" in vals:
                seconds = vals["p"] / (1000.0 if self.dialect == "iso" else 1.0)
                used.add("p")
            else:
                raise InterpError("G4 dwell without a time (P)")
            self.dwell(seconds)
        # 11-12 plane and units
        for g, plane in ((17.0, "XY"), (18.0, "XZ"), (19.0, "YZ")):
            if g in gs:
                if self.comp.side and plane != self.modal.plane:
                    raise InterpError("cannot change the plane with cutter radius compensation on")
                self.modal.plane = plane
        new_unit = INCH if 20.0 in gs else 1.0 if 21.0 in gs else self.modal.unit
        if new_unit != self.modal.unit and any(self.tlo.values()):
            # LinuxCNC keeps the active offset's number through a change of units, so G53,
            # G28/G30 and the next G43/G49 would be off by the unconverted offset: refuse.
            raise InterpError(f"G{20 if new_unit == INCH else 21} changes the units with a tool length offset "
                              "active (LinuxCNC does not convert it); cancel it with G49 first")
        self.modal.unit = new_unit
        # 13 cutter radius compensation
        if 40.0 in gs:
            self._comp_off()
        if 41.0 in gs or 42.0 in gs:
            if self.modal.plane not in ("XY", "XZ"):
                raise InterpError("cutter radius compensation in the YZ plane (G19): LinuxCNC allows only G17 and G18")
            d = vals.get("d")
            used.add("d")
            if d is not None and (d != int(d) or d < 0):
                raise InterpError(f"D{d:g}: the tool number for G41/G42 must be a whole number >= 0")
            tool = self.tool if d is None else int(d)
            radius = self._tool(tool).diameter / 2 if tool else 0.0
            if tool and self._tool(tool).orientation not in (0, 9) and radius:
                raise InterpError(f"cutter compensation with lathe tool {tool} (orientation "
                                  f"{self._tool(tool).orientation}) is not supported")
            a1, a2, n = PLANES[self.modal.plane][:3]
            try:
                self.comp.start(LEFT if 41.0 in gs else RIGHT, radius, (self.pos[a1], self.pos[a2], self.pos[n]))
            except CompError as exc:
                raise InterpError(str(exc)) from None
        # 14 tool length offset
        if 43.0 in gs:
            h = int(vals["h"]) if "h" in vals else self.tool
            used.add("h")
            entry = self._tool(h).offsets if h else {}
            self.tlo = {a: entry.get(a, 0.0) for a in AXES}
        if 43.1 in gs:
            self.tlo = {a: 0.0 for a in AXES}
            for a in AXES:
                if a.lower() in vals:
                    self.tlo[a] = vals[a.lower()] * self.scale(a)
                    used.add(a.lower())
        if 49.0 in gs:
            self.tlo = {a: 0.0 for a in AXES}
        # 15 coordinate system
        for g, index in COORD_SYSTEMS.items():
            if g in gs:
                self.modal.coord = index
                self._mirror_offsets()
        # 16 path control
        if 61.0 in gs or 61.1 in gs:
            self.modal.blend = None
        if 64.0 in gs:
            self.modal.blend = vals["p"] * self.modal.unit if "p" in vals else math.inf
            used |= {"p", "q"}
        # 17 distance modes, 18 retract mode
        for g, attr, value in ((90.0, "absolute", True), (91.0, "absolute", False), (90.1, "arc_absolute", True),
                               (91.1, "arc_absolute", False), (98.0, "retract_initial", True),
                               (99.0, "retract_initial", False)):
            if g in gs:
                setattr(self.modal, attr, value)

        # 19 non-modal: G10, G28/G30 (+ .1), G92 family
        axis_words = {a: vals[a.lower()] for a in AXES if a.lower() in vals}
        polar = {k: vals[k] for k in "@^" if k in vals}
        motion_done = False
        if any(g in gs for g in (10.0, 28.0, 30.0, 92.0, 92.1, 92.2, 92.3, 43.0, 43.1, 49.0)):
            self._refuse_with_comp("G10/G28/G30/G43/G49/G92")
        if 10.0 in gs:
            self._g10(vals, axis_words)
            used |= {"l", "p", "r"} | {a.lower() for a in axis_words}
            axis_words = {}
        elif 28.0 in gs or 30.0 in gs:
            self._home(28 if 28.0 in gs else 30, axis_words, 53.0 in gs)
            axis_words, motion_done = {}, True
        elif 28.1 in gs or 30.1 in gs:
            base = G28_BASE if 28.1 in gs else G30_BASE
            for k, a in enumerate(AXES):
                self.params.set(base + k, self.pos[a])
        elif 92.0 in gs:
            if not axis_words:
                raise InterpError("G92 without axis words")
            for a, v in axis_words.items():
                # program value v at the current position: G92 offset takes up the difference
                self.g92[a] = self.pos[a] - self.g5x[self.modal.coord][a] - self.tlo[a] - v * self.scale(a)
            self.params.set(G92_BASE - 1, 1.0)
            self._mirror_offsets()
            axis_words = {}
        elif 92.1 in gs or 92.2 in gs:
            self.g92 = {a: 0.0 for a in AXES}
            if 92.1 in gs:
                self.params.set(G92_BASE - 1, 0.0)
                self._mirror_offsets()
        elif 92.3 in gs:
            self.g92 = {a: self.params.get(G92_BASE + k) for k, a in enumerate(AXES)}

        # 20 motion
        if codes.motion:
            self.modal.motion = codes.motion
        has_motion_words = bool(axis_words or polar)
        if not motion_done and (codes.motion or has_motion_words):
            motion = self.modal.motion
            if motion is None or motion == "G80":
                if has_motion_words:
                    raise InterpError("axis words without a motion mode (G0/G1/G2/G3 or a canned cycle)")
            else:
                used |= self._motion(motion, vals, axis_words, polar, 53.0 in gs)
        if codes.motion and codes.motion not in SUPPORTED_CYCLES:
            self.cycle.series = None  # any other motion mode (or G80) ends a series of cycles
        used |= {k for k in vals if k.upper() in AXES} | set(polar)
        for letter in vals:
            if letter not in used:
                raise InterpError(f"word {letter.upper()}{vals[letter]:g} is not used by any code in the block")
        # 21 stops
        if 2 in ms or 30 in ms:
            self._comp_off()
            on_end()

    def _comp_off(self) -> None:
        """G40: flush the queue; the programmed point becomes the current one (LinuxCNC)."""
        a1, a2, n = PLANES[self.modal.plane][:3]
        try:
            jumped = self.comp.stop((self.pos[a1], self.pos[a2]))
        except CompError as exc:
            raise InterpError(str(exc)) from None
        if jumped:
            px, py, pz = self.comp.program
            for a, v in ((a1, px), (a2, py), (n, pz)):
                if v != self.pos[a]:
                    self.force_axes.add(a)
                self.pos[a] = v
            self.arc_not_allowed = True

    def _refuse_with_comp(self, what: str) -> None:
        if self.comp.side:
            raise InterpError(f"{what} with cutter radius compensation on (G40 first)")

    def on_m73(self) -> None:  # replaced by the flow, which knows the call frames
        raise InterpError("M73 outside a subroutine")

    def snapshot(self) -> Modal:
        return replace(self.modal)

    def restore(self, modal: Modal) -> None:
        self.modal = replace(modal)

    def _check_tool(self, number: int, word: str) -> None:
        if number and self.tools is not None and number not in self.tools:
            raise InterpError(f"{word}{number}: tool {number} is not in the tool table")

    def _tool(self, number: int) -> Tool:
        if self.tools is None:
            raise InterpError(f"tool {number} is used for an offset (G43, G41/G42) but no tool table was given "
                              "(--tool-table FILE, a LinuxCNC tool table)")
        if number not in self.tools:
            raise InterpError(f"tool {number} is not in the tool table")
        return self.tools[number]

    def _g10(self, vals: dict[str, float], axis_words: dict[str, float]) -> None:
        l = vals.get("l")
        if l not in (2.0, 20.0):
            raise InterpError(f"G10 L{l:g} (tool table edits) is not supported; G10 L2 and L20 are" if l is not None
                              else "G10 without L")
        if vals.get("r", 0.0) != 0.0:
            raise InterpError("G10 L2 R (coordinate system rotation) is not supported")
        p = int(vals.get("p", 0))
        index = self.modal.coord if p == 0 else p
        if not 1 <= index <= 9:
            raise InterpError(f"G10 P{p}: coordinate system must be 0..9")
        for a, v in axis_words.items():
            if l == 2.0:
                self.g5x[index][a] = v * self.scale(a)
            else:  # L20: the current position gets program value v in that system
                self.g5x[index][a] = self.pos[a] - self.g92[a] - self.tlo[a] - v * self.scale(a)
        self._mirror_offsets()

    def _home(self, which: int, axis_words: dict[str, float], g53: bool) -> None:
        """G28/G30: rapid to the programmed intermediate point, then to the stored position."""
        if axis_words:
            inter = {a: (self.pos[a] + v * self.scale(a)) if not self.modal.absolute else self.machine(a, v)
                     for a, v in axis_words.items()}
            self.emit("G0", inter)
        base = G28_BASE if which == 28 else G30_BASE
        axes = list(axis_words) if axis_words else list(AXES)
        # The home move ends at the stored machine position (rs274 prints it minus the
        # offsets).  Without axis words every axis goes home; only those that move are named,
        # so a program for an X/Y machine does not appear to move A…W.
        target = {a: self.params.get(base + AXES.index(a)) for a in axes}
        if not axis_words:
            target = {a: v for a, v in target.items() if v != self.pos[a]}
        self.emit("G0", target)

    def _motion(self, motion: str, vals: dict[str, float], axis_words: dict[str, float], polar: dict[str, float],
                g53: bool) -> set[str]:
        if motion in SUPPORTED_CYCLES:
            self._refuse_with_comp(f"{motion} canned cycle")
            return self._cycle(motion, vals, axis_words, polar)
        if motion in ("G2", "G3") and self.arc_not_allowed:
            raise InterpError("the move just after G40 must be straight, not an arc")
        self.arc_not_allowed = False
        if self.comp.active:
            if g53:
                raise InterpError("G53 with cutter radius compensation on")
            return self._comp_motion(motion, vals, axis_words, polar)
        target = self._target(axis_words, polar, g53)
        if motion in ("G0", "G1"):
            self.emit(motion, target)
            return set()
        if g53:
            raise InterpError("G53 with an arc")
        return self._arc(motion, vals, target)

    def _comp_motion(self, motion: str, vals: dict[str, float], axis_words: dict[str, float],
                     polar: dict[str, float]) -> set[str]:
        """A G0/G1/G2/G3 under cutter radius compensation (see :mod:`cutter_comp`); the
        geometry runs in the plane's (first, second, normal) axes."""
        plane = self.modal.plane
        a1, a2, n, l1, l2 = PLANES[plane]
        base = dict(self.pos)
        if not self.comp.firstmove:  # LinuxCNC: relative to the programmed, not the tool, point
            base[a1], base[a2], base[n] = self.comp.program
        target = self._target(axis_words, polar, False, base)
        p = (target.get(a1, base[a1]), target.get(a2, base[a2]), target.get(n, base[n]))
        rest = {a: v for a, v in target.items() if a not in (a1, a2, n)}
        feed = self.feed_mm_s(motion, math.dist(p, (base[a1], base[a2], base[n])))
        cur = (self.pos[a1], self.pos[a2], self.pos[n])

        def make(kind: str, x: float, y: float, z: float, dx: float, dy: float, centre=None, turn: int = 0,  # noqa: ANN001
                 original: float = 0.0) -> QueuedMove:
            extra = dict(rest)
            if z != cur[2] or n in target:
                extra[n] = z
            return QueuedMove(kind, x, y, extra, dx, dy, *(centre or (0.0, 0.0)), turn, original,
                              None if kind == "G0" else feed, line=self.line, n=self.n, axes=(a1, a2), plane=plane)

        try:
            if motion in ("G0", "G1"):
                new = self.comp.straight(motion, cur, p, make)
                used: set[str] = set()
            else:
                turns = int(vals.get("p", 1))
                centre_of = lambda sx, sy: self._arc_centre(motion, vals, l1, l2, a1, a2, (sx, sy), p[:2])  # noqa: E731
                new = self.comp.arc(motion, cur, p, centre_of, turns, make)
                used = {l1, l2, "r", "p"}
        except CompError as exc:
            raise InterpError(str(exc)) from None
        self.pos[a1], self.pos[a2], self.pos[n] = new
        self.pos.update(rest)
        return used

    def _target(self, axis_words: dict[str, float], polar: dict[str, float], g53: bool,
                base: dict[str, float] | None = None) -> dict[str, float]:
        base = self.pos if base is None else base
        target: dict[str, float] = {}
        for a, v in axis_words.items():
            if g53:
                if not self.modal.absolute:
                    raise InterpError("G53 in incremental mode (G91)")
                target[a] = v * self.scale(a)  # machine coordinates
            elif self.modal.absolute:
                target[a] = self.machine(a, v)
            else:
                target[a] = base[a] + v * self.scale(a)
        if polar:
            if "X" in axis_words or "Y" in axis_words:
                raise InterpError("polar coordinates (@ ^) together with X or Y")
            x, y = self.program("X"), self.program("Y")
            r, theta = math.hypot(x, y), math.atan2(y, x)
            if self.modal.absolute:
                r = polar.get("@", r)
                theta = math.radians(polar["^"]) if "^" in polar else theta
            else:
                if x == 0 and y == 0:
                    raise InterpError("incremental polar motion is undefined at the origin")
                r += polar.get("@", 0.0)
                theta += math.radians(polar.get("^", 0.0))
            target["X"] = self.machine("X", r * math.cos(theta))
            target["Y"] = self.machine("Y", r * math.sin(theta))
        return target

    def _arc(self, motion: str, vals: dict[str, float], target: dict[str, float]) -> set[str]:
        plane = self.modal.plane
        a1, a2, normal, l1, l2 = PLANES[plane]
        other = {"i", "j", "k"} - {l1, l2}
        for letter in other:
            if letter in vals:
                raise InterpError(f"{letter.upper()} offset with an arc in the {plane} plane (G{ {'XY': 17, 'XZ': 18, 'YZ': 19}[plane] })")
        x0, y0 = self.pos[a1], self.pos[a2]
        x1, y1 = target.get(a1, x0), target.get(a2, y0)
        turns = 1
        if "p" in vals:
            if vals["p"] != int(vals["p"]) or vals["p"] < 1:
                raise InterpError(f"arc P{vals['p']:g}: the number of turns must be a whole number >= 1")
            turns = int(vals["p"])
        cx, cy = self._arc_centre(motion, vals, l1, l2, a1, a2, (x0, y0), (x1, y1))
        r0, r1 = math.hypot(x0 - cx, y0 - cy), math.hypot(x1 - cx, y1 - cy)
        full = {a1: x1, a2: y1}
        full.update({a: v for a, v in target.items() if a not in full})
        planar = 0.5 * (r0 + r1) * sweep((x0, y0), (x1, y1), (cx, cy), motion == "G3", turns)
        axial = math.sqrt(sum((full[a] - self.pos[a]) ** 2 for a in full if a not in (a1, a2) and a not in ROTARY))
        self.emit(motion, full, center={a1: cx, a2: cy}, plane=plane, turns=turns, length_mm=math.hypot(planar, axial))
        return {l1, l2, "r", "p"}

    def _arc_centre(self, motion: str, vals: dict[str, float], l1: str, l2: str, a1: str, a2: str,
                    start: tuple[float, float], end: tuple[float, float]) -> tuple[float, float]:
        """Centre (machine mm) of an arc from ``start`` to ``end`` in the plane's axes a1, a2."""
        (x0, y0), (x1, y1) = start, end
        u = self.modal.unit
        if "r" in vals:
            if l1 in vals or l2 in vals:
                raise InterpError("arc with both R and centre offsets")
            return center_from_radius(x0, y0, x1, y1, vals["r"] * u, motion == "G2")
        if l1 not in vals and l2 not in vals:
            raise InterpError(f"{motion} arc without centre offsets ({l1.upper()}{l2.upper()}) or R")
        if self.modal.arc_absolute:
            cx, cy = self.machine(a1, vals.get(l1, 0.0)), self.machine(a2, vals.get(l2, 0.0))
        else:
            cx, cy = x0 + vals.get(l1, 0.0) * u, y0 + vals.get(l2, 0.0) * u
        check_radii(math.hypot(x0 - cx, y0 - cy), math.hypot(x1 - cx, y1 - cy), u == INCH)
        return cx, cy

    def _cycle(self, motion: str, vals: dict[str, float], axis_words: dict[str, float], polar: dict[str, float]) -> set[str]:
        if self.modal.plane != "XY":
            raise InterpError(f"{motion} canned cycle outside the XY plane (G17) is not supported")
        if set(axis_words) - {"X", "Y", "Z"}:
            raise InterpError(f"{motion} canned cycle with axis {sorted(set(axis_words) - {'X', 'Y', 'Z'})[0]}")
        first = self.cycle.series != motion
        words = {a.lower(): v for a, v in axis_words.items()}
        words.update({k: vals[k] for k in "rlpq" if k in vals})
        if self.dialect == "iso" and "p" in words:
            words["p"] /= 1000.0  # Fanuc: cycle dwell P in ms, like G4 P
        if polar:
            if self.modal.absolute:
                target = self._target({}, polar, False)
                words["x"], words["y"] = (target["X"] - self.offset("X")) / self.modal.unit, (target["Y"] - self.offset("Y")) / self.modal.unit
            else:
                words.update(polar)
        current = (self.program("X"), self.program("Y"), self.program("Z"))
        moves, _ = expand_cycle(motion, first, words, self.cycle, current, not self.modal.absolute,
                                self.modal.retract_initial, self.modal.unit == INCH, InterpError)
        blend, self.modal.blend = self.modal.blend, None  # cycles run in exact path (LinuxCNC)
        for mv in moves:
            if mv.kind == "G4":
                self.dwell(mv.dwell_s)
                continue
            target = {"X": self.machine("X", mv.x), "Y": self.machine("Y", mv.y), "Z": self.machine("Z", mv.z)}
            self.emit(mv.kind, {a: v for a, v in target.items() if abs(v - self.pos[a]) > 0 or a == "Z"})
        self.modal.blend = blend
        self.cycle.series = motion
        return {"r", "l", "p", "q"}

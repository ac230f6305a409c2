"""The dialect-independent form of a part program: blocks and programs.

A :class:`Program` is what the interpreter (:mod:`gcode_gen.interpreter`) reads from
G-code text and what the interpolator (:mod:`gcode_gen.interpolator`) turns into a
sampled commanded trajectory.  A :class:`Toolpath` is what the generators
(:mod:`gcode_gen.excitation`, :mod:`gcode_gen.toolpaths`) produce before a dialect
writer (:mod:`gcode_gen.dialects`) turns it into text.

Conventions (the same everywhere in gcode_gen):

* positions in mm (degrees for rotary axes A/B/C), absolute, machine coordinates;
* feeds in mm/s (the text carries mm/min, the usual ``F`` unit; converted on read);
* arcs lie in the block's ``plane`` ("XY" for G17, "XZ" for G18, "YZ" for G19); the
  centre is absolute, keyed by the plane's two axes; G2 turns clockwise seen from the
  plane's normal (+Z, +Y, +X respectively), as LinuxCNC;
* axis letters upper case, one of :data:`AXIS_LETTERS`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["AXIS_LETTERS", "ROTARY_AXES", "MOTIONS", "ARC_ORDER", "ARC_PLANES", "PLANE_CODES", "Block", "Program", "Toolpath"]

#: Axis letters the generator, writers and interpreter accept.
AXIS_LETTERS: tuple[str, ...] = ("X", "Y", "Z", "A", "B", "C", "U", "V", "W")
#: The rotary ones, in degrees.
ROTARY_AXES: frozenset[str] = frozenset("ABC")

#: Each arc plane's (first, second) axes: G3 turns from the first towards the second (ccw
#: seen from the third axis's +), as RS274/NGC counts it.
ARC_ORDER: dict[str, tuple[str, str]] = {"XY": ("X", "Y"), "XZ": ("Z", "X"), "YZ": ("Y", "Z")}
#: The plane of an arc between two axes, in either order.
ARC_PLANES: dict[frozenset, str] = {frozenset(axes): plane for plane, axes in ARC_ORDER.items()}
#: The G-code that selects each plane.
PLANE_CODES: dict[str, str] = {"XY": "G17", "XZ": "G18", "YZ": "G19"}

#: Motion kinds a block can carry: rapid, linear, clockwise arc, counter-clockwise arc, dwell.
MOTIONS: tuple[str, ...] = ("G0", "G1", "G2", "G3", "G4")


@dataclass(frozen=True)
class Block:
    """One motion (or dwell) block of a program.

    Attributes
    ----------
    line : int
        1-based line number in the program text (0 for a block not read from text).
    n : int or None
        Block number as written (``N0010`` in ISO, the leading number in Heidenhain).
    motion : str
        ``"G0"`` rapid, ``"G1"`` linear, ``"G2"`` clockwise arc, ``"G3"`` counter-clockwise
        arc (both seen from +Z, XY plane), ``"G4"`` dwell.
    target : dict[str, float]
        Absolute end position in mm of the axes the block programs (both X and Y for an
        arc; empty for a dwell).
    feed : float or None
        Path feed in mm/s in effect for the block; None for rapid moves and dwells.
    center : dict[str, float] or None
        Absolute arc centre in mm (keys: the two axes of ``plane``, ``"X"``, ``"Y"`` for G17) for
        G2/G3; None otherwise.
    dwell_s : float or None
        Dwell time in s for G4; None otherwise.
    plane : str
        Plane of an arc: "XY" (G17, default), "XZ" (G18: first axis Z, second X) or
        "YZ" (G19: first Y, second Z); the third axis moves linearly (helix).
    turns : int
        Full turns of an arc (G2/G3 ``P``, default 1): the arc runs ``turns - 1`` full
        circles more than the sweep from start to end.
    blend_tolerance : float or None
        Path mode in effect: None for exact stop (G61/G61.1, canned cycles), ``inf`` for G64
        without P (blend at best speed), else the G64 P tolerance in mm.
    """

    line: int
    n: int | None
    motion: str
    target: dict[str, float] = field(default_factory=dict)
    feed: float | None = None
    center: dict[str, float] | None = None
    dwell_s: float | None = None
    plane: str = "XY"
    turns: int = 1
    blend_tolerance: float | None = None


@dataclass(frozen=True)
class Program:
    """A program read from text.

    Attributes
    ----------
    name : str
        Program name (file stem, or the Heidenhain ``BEGIN PGM`` name).
    dialect : str
        ``"iso"``, ``"heidenhain"`` or ``"linuxcnc"``.
    blocks : tuple[Block, ...]
        Motion and dwell blocks in execution order (modal state already resolved).
    header : dict[str, str]
        ``key=value`` pairs found in the comments before the first motion block; the
        generator records every parameter and the seed there.
    text : str
        The program text it was read from.
    """

    name: str
    dialect: str
    blocks: tuple[Block, ...]
    header: dict[str, str]
    text: str

    @property
    def axes(self) -> tuple[str, ...]:
        """Axis letters the program moves, in order of first appearance."""
        seen: dict[str, None] = {}
        for b in self.blocks:
            for ax in b.target:
                seen.setdefault(ax, None)
        return tuple(seen)


@dataclass(frozen=True)
class Toolpath:
    """A generated program before it is written in a dialect.

    The blocks' ``line`` is their index and ``n`` is None; a writer numbers them.

    Attributes
    ----------
    name : str
        Program name (becomes the file stem and the Heidenhain PGM name).
    blocks : tuple[Block, ...]
        Moves in order; the first is normally a rapid (G0) to the start point.
    header : dict[str, str]
        Every generation parameter and the seed, written as ``key=value`` comments.
    decimals : int
        Decimal places for coordinates (4 resolves 0.1 µm, needed for 0.03 mm steps).
    blending : bool
        False (default): exact stop written explicitly (G61 in LinuxCNC);
        True: path blending (G64 P<tolerance>).
    """

    name: str
    blocks: tuple[Block, ...]
    header: dict[str, str]
    decimals: int = 4
    blending: bool = False

"""Read ISO, LinuxCNC and Heidenhain programs into a :class:`~gcode_gen.program.Program`.

What is understood (everything the writers produce, plus the common motion subset):

RS274 (``iso``, ``linuxcnc``)
    the RS274/NGC language as LinuxCNC's interpreter runs it — parameters, expressions,
    O-word subroutines and loops, offsets, tool length offsets, G28/G30, G53, arcs in all
    three planes, canned cycles, polar coordinates … — by :mod:`gcode_gen.ngc`; the full
    list of what is supported and refused is docs/gcode-support.md.  ISO differs only in
    its dwell: ``G4 X`` seconds or ``P`` milliseconds (Fanuc), LinuxCNC ``G4 P`` seconds.
Heidenhain conversational (``heidenhain``)
    leading block numbers, ``BEGIN PGM name MM|INCH``, ``END PGM``, ``L`` with absolute
    (``X+1.5``) or incremental (``IX+1.5``) coordinates, ``R0``, ``F`` (mm/min, modal),
    ``FMAX``/``F MAX`` (rapid, this block only), ``CC`` (arc centre; without coordinates
    the current position), ``C … DR+|DR-`` arcs about CC, ``CR … R± DR±`` radius arcs,
    ``CYCL DEF 9`` dwell, ``BLK FORM``/``TOOL CALL``/``TOOL DEF``/``STOP`` (no motion,
    accepted), ``M`` words as above, ``;`` comments.

Anything else raises :class:`~core.errors.ProgramError` naming the word and the line.
Comments of the form ``key=value`` before the first motion block become
``Program.header``.  Feeds are converted to mm/s, positions to absolute mm.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from core.errors import InputError, ProgramError
from gcode_gen.ngc import Tool, interpret, read_tool_table
from gcode_gen.ngc.arcs import ArcError, center_from_radius
from gcode_gen.program import AXIS_LETTERS, Block, Program

__all__ = ["parse_program", "read_program", "detect_dialect", "DIALECT_NAMES"]

DIALECT_NAMES = ("iso", "heidenhain", "linuxcnc")
INCH = 25.4
LINEAR_AXES = ("X", "Y", "Z", "U", "V", "W")
_HEADER_RE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_.\-]*)\s*=\s*(.*?)\s*$")
_NUM = r"[+-]?\s*(?:\d+\.?\d*|\.\d+)"
_RS_WORD = re.compile(rf"\s*([A-Za-z])\s*({_NUM})")
_HEADER_DIALECT = re.compile(r"[(;]\s*dialect\s*=\s*(iso|linuxcnc|heidenhain)\b", re.I)


_LINUXCNC_ONLY = re.compile(r"#<|o<|^\s*(?:/?\s*n\d+\s*)?o\s*\d+\s*(?:sub|call|if|while|do|repeat)\b|\[", re.M | re.I)


def detect_dialect(text: str, name: str | None = None) -> str:
    """Guess the dialect: Heidenhain if it has ``BEGIN PGM`` or ``L X…`` lines, else the
    ``dialect=`` header comment, else LinuxCNC for a ``.ngc`` file or one using LinuxCNC's
    language (``#<name>``, ``[ ]`` expressions, O-word subroutines), else ISO when blocks are
    N-numbered, else LinuxCNC."""
    if re.search(r"^\s*\d*\s*BEGIN\s+PGM\b", text, re.M | re.I):
        return "heidenhain"
    m = _HEADER_DIALECT.search(text)
    if m:
        return m.group(1).lower()
    if re.search(r"^\s*\d+\s+(L|CC|C|CR)\s+I?[XYZ]", text, re.M | re.I):
        return "heidenhain"
    if (name or "").lower().endswith(".ngc") or _LINUXCNC_ONLY.search(text):
        return "linuxcnc"
    if re.search(r"^\s*/?\s*N\s*\d+", text, re.M | re.I):
        return "iso"
    return "linuxcnc"


def read_program(path: str | Path, *, dialect: str | None = None, tool_table: str | Path | dict[int, Tool] | None = None) -> Program:
    """Read a program file; the name is the file stem.

    Raises
    ------
    InputError
        The file cannot be read.
    ProgramError
        The program text is invalid (message has file and line number).
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8", errors="strict")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read program {p}: {exc.__class__.__name__}: {exc}") from exc
    if dialect is None:
        dialect = detect_dialect(text, name=p.name)
    return parse_program(text, dialect=dialect, name=p.stem, tool_table=tool_table)


def parse_program(text: str, *, dialect: str | None = None, name: str = "program",
                  tool_table: str | Path | dict[int, Tool] | None = None) -> Program:
    """Parse program ``text`` in ``dialect`` (auto-detected when None).

    Parameters
    ----------
    text : str
        Program text.
    dialect : str or None
        "iso", "heidenhain", "linuxcnc" or None to detect (see :func:`detect_dialect`; a
        ``name`` ending in ``.ngc`` counts as LinuxCNC).
    name : str
        Program name used in error messages (a Heidenhain ``BEGIN PGM`` name replaces it).
    tool_table : path, dict or None
        LinuxCNC tool table (file in mm, or tools from :func:`gcode_gen.ngc.read_tool_table`)
        for G43 tool length offsets and cutter radii; without one, a tool offset is an error.

    Returns
    -------
    Program
        Blocks with absolute targets in mm and feeds in mm/s.

    Raises
    ------
    ProgramError
        Unknown or unsupported word, missing feed, inconsistent arc …, with the line number.
    """
    if dialect is None:
        dialect = detect_dialect(text, name=name)
    if dialect not in DIALECT_NAMES:
        raise InputError(f"unknown dialect {dialect!r} (use one of {', '.join(DIALECT_NAMES)})")
    if dialect != "heidenhain":
        tools = read_tool_table(tool_table) if isinstance(tool_table, (str, Path)) else tool_table
        blocks, header = interpret(text, name=name, dialect=dialect, tools=tools)
        return Program(name=name, dialect=dialect, blocks=tuple(blocks), header=header, text=text)
    reader = _HeidenhainReader(name)
    reader.run(text)
    return Program(name=reader.name, dialect=dialect, blocks=tuple(reader.blocks), header=reader.header, text=text)


class _Reader:
    """State shared by both readers: position, feed, units, header, blocks."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.blocks: list[Block] = []
        self.header: dict[str, str] = {}
        self.pos: dict[str, float] = {}
        self.feed_mm_min: float | None = None
        self.scale = 1.0  # mm per program unit (25.4 after G20 / INCH)
        self.line = 0
        self.ended = False

    def error(self, message: str) -> ProgramError:
        return ProgramError(message, line=self.line, source=self.name)

    def comment(self, body: str) -> None:
        if self.blocks:
            return
        m = _HEADER_RE.match(body)
        if m:
            self.header[m.group(1)] = m.group(2)

    def number(self, text: str) -> float:
        try:
            value = float(text.replace(" ", ""))
        except ValueError:
            raise self.error(f"bad number {text!r}") from None
        if not math.isfinite(value):
            raise self.error(f"number {text!r} is not finite")
        return value

    def axis_value(self, axis: str, value: float, incremental: bool) -> float:
        if axis in LINEAR_AXES:
            value *= self.scale
        if incremental:
            if axis not in self.pos:
                raise self.error(f"incremental {axis} move from an unknown position")
            value += self.pos[axis]
        return value

    def feed_mm_s(self, motion: str) -> float | None:
        if motion == "G0":
            return None
        if self.feed_mm_min is None:
            raise self.error(f"{motion} move without a programmed feed (F)")
        return self.feed_mm_min / 60.0

    def set_feed(self, value: float) -> None:
        if value <= 0:
            raise self.error(f"feed F{value:g} must be positive")
        self.feed_mm_min = value * self.scale

    def add_move(self, n: int | None, motion: str, target: dict[str, float], center: dict[str, float] | None = None) -> None:
        self.blocks.append(Block(line=self.line, n=n, motion=motion, target=target,
                                 feed=self.feed_mm_s(motion), center=center))
        self.pos.update(target)

    def add_dwell(self, n: int | None, seconds: float) -> None:
        if seconds < 0:
            raise self.error(f"negative dwell {seconds:g} s")
        self.blocks.append(Block(line=self.line, n=n, motion="G4", target={}, dwell_s=seconds))

    def arc(self, n: int | None, motion: str, end: dict[str, float], center: tuple[float, float] | None,
            radius: float | None) -> None:
        """Add a G2/G3 arc in XY from the current position to ``end`` (absolute, mm)."""
        if "X" not in self.pos or "Y" not in self.pos:
            raise self.error("arc from an unknown X/Y position (program a linear move first)")
        x0, y0 = self.pos["X"], self.pos["Y"]
        x1, y1 = end.get("X", x0), end.get("Y", y0)
        if radius is not None:
            try:
                center = center_from_radius(x0, y0, x1, y1, radius, motion == "G2")
            except ArcError as exc:
                raise self.error(str(exc)) from None
        assert center is not None
        cx, cy = center
        r0, r1 = math.hypot(x0 - cx, y0 - cy), math.hypot(x1 - cx, y1 - cy)
        if r0 < 1e-9:
            raise self.error("arc radius is zero")
        if abs(r0 - r1) > max(0.002, 1e-3 * r0):
            raise self.error(f"arc end radius {r1:.4f} mm differs from start radius {r0:.4f} mm")
        target = {"X": x1, "Y": y1}
        target.update({k: v for k, v in end.items() if k not in target})
        self.add_move(n, motion, target, {"X": cx, "Y": cy})


class _HeidenhainReader(_Reader):
    """TNC conversational (Klartext) reader."""

    _ACCEPTED_M = {0, 1, 3, 4, 5, 8, 9}
    _COORD = re.compile(rf"(I?)([A-Z])\s*({_NUM})")

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.cc: tuple[float, float] | None = None

    def run(self, text: str) -> None:
        for self.line, raw in enumerate(text.splitlines(), start=1):
            if self.ended:
                break
            self.do_line(raw)

    def do_line(self, raw: str) -> None:
        code = raw
        if ";" in code:
            code, comment = code.split(";", 1)
            self.comment(comment)
        code = code.strip().rstrip("*").strip()
        m = re.match(r"^(\d+)(?:\s+|$)", code)
        n = None
        if m:
            n = int(m.group(1))
            code = code[m.end():].strip()
        if not code:
            return
        upper = code.upper()
        keyword = upper.split()[0]
        if upper.startswith("BEGIN PGM"):
            parts = code.split()
            if len(parts) < 3:
                raise self.error("BEGIN PGM without a program name")
            self.name = parts[2]
            unit = parts[3].upper() if len(parts) > 3 else "MM"
            if unit not in ("MM", "INCH"):
                raise self.error(f"unknown unit {parts[3]!r} in BEGIN PGM (MM or INCH)")
            self.scale = INCH if unit == "INCH" else 1.0
            return
        if upper.startswith("END PGM"):
            self.ended = True
            return
        if upper.startswith(("BLK FORM", "TOOL CALL", "TOOL DEF")) or upper == "STOP":
            return
        if upper.startswith("CYCL DEF"):
            self.cycle(n, upper)
            return
        rest = upper[len(keyword):]
        if keyword == "L":
            self.linear(n, rest)
        elif keyword == "CC":
            self.pole(rest)
        elif keyword in ("C", "CR"):
            self.circular(n, keyword, rest)
        elif re.fullmatch(r"M\d+", keyword):
            if not re.fullmatch(r"(\s*M\d+)*\s*", rest):
                raise self.error(f"unknown word in {code!r}")
            self.m_words(upper)
        else:
            raise self.error(f"unknown or unsupported block {keyword!r}")

    def cycle(self, n: int | None, upper: str) -> None:
        m = re.match(r"CYCL DEF\s+9\.0\b", upper)
        if m:
            return
        m = re.match(rf"CYCL DEF\s+9\.1\s+DWELL\s*({_NUM})\s*$", upper)
        if m:
            self.add_dwell(n, self.number(m.group(1)))
            return
        raise self.error(f"unsupported cycle {upper!r} (only CYCL DEF 9 dwell)")

    def m_words(self, text: str) -> None:
        for m in re.findall(r"M(\d+)", text):
            m = int(m)
            if m in (2, 30):
                self.ended = True
            elif m not in self._ACCEPTED_M:
                raise self.error(f"unknown or unsupported M-code M{m}")

    def words(self, rest: str, allowed_extra: tuple[str, ...]) -> tuple[dict[str, tuple[bool, float]], dict[str, str]]:
        """Split ``rest`` into coordinates {axis: (incremental, value)} and other words."""
        rest = re.sub(r"F\s+MAX\b", "FMAX", rest)
        coords: dict[str, tuple[bool, float]] = {}
        other: dict[str, str] = {}
        pos = 0
        patterns = [
            ("FMAX", re.compile(r"FMAX\b")),
            ("DR", re.compile(r"DR\s*([+-])")),
            ("F", re.compile(rf"F\s*({_NUM})")),
            ("M", re.compile(r"M\s*(\d+)")),
            ("R", re.compile(rf"R\s*({_NUM}|L\b|R\b)")),
        ]
        while pos < len(rest):
            ws = re.match(r"\s+", rest[pos:])
            if ws:
                pos += ws.end()
                continue
            m = self._COORD.match(rest, pos)
            if m and m.group(2) in AXIS_LETTERS:
                axis = m.group(2)
                if axis in coords:
                    raise self.error(f"coordinate {axis} appears twice in one block")
                coords[axis] = (m.group(1) == "I", self.number(m.group(3)))
                pos = m.end()
                continue
            for key, pat in patterns:
                m = pat.match(rest, pos)
                if m:
                    if key not in allowed_extra:
                        raise self.error(f"word {m.group(0).strip()!r} not allowed here")
                    if key == "M":
                        other["M"] = other.get("M", "") + " M" + m.group(1)
                    else:
                        other[key] = m.group(1) if m.groups() else m.group(0)
                    pos = m.end()
                    break
            else:
                raise self.error(f"unknown word {rest[pos:].split()[0]!r}")
        return coords, other

    def absolute(self, coords: dict[str, tuple[bool, float]]) -> dict[str, float]:
        return {ax: self.axis_value(ax, v, inc) for ax, (inc, v) in coords.items()}

    def apply_feed(self, other: dict[str, str]) -> None:
        if "F" in other:
            self.set_feed(self.number(other["F"]))

    def linear(self, n: int | None, rest: str) -> None:
        coords, other = self.words(rest, ("FMAX", "F", "M", "R"))
        if "R" in other and other["R"] not in ("0", "+0", "-0"):
            raise self.error(f"radius compensation R{other['R']} is not supported (use R0)")
        self.apply_feed(other)
        motion = "G0" if "FMAX" in other else "G1"
        if coords:
            self.add_move(n, motion, self.absolute(coords))
        self.m_words(other.get("M", ""))

    def pole(self, rest: str) -> None:
        coords, _ = self.words(rest, ())
        bad = [ax for ax in coords if ax not in ("X", "Y")]
        if bad:
            raise self.error(f"CC with axis {bad[0]}: only the XY plane is supported")
        xy = self.absolute(coords)
        x, y = xy.get("X", self.pos.get("X")), xy.get("Y", self.pos.get("Y"))
        if x is None or y is None:
            raise self.error("CC needs both X and Y when the position is unknown")
        self.cc = (x, y)

    def circular(self, n: int | None, keyword: str, rest: str) -> None:
        coords, other = self.words(rest, ("DR", "F", "M", "R"))
        if "DR" not in other:
            raise self.error(f"{keyword} block without a direction DR+ or DR-")
        motion = "G3" if other["DR"] == "+" else "G2"
        self.apply_feed(other)
        end = self.absolute(coords)
        if keyword == "C":
            if "R" in other and other["R"] not in ("0", "+0", "-0"):
                raise self.error(f"radius compensation R{other['R']} is not supported")
            if self.cc is None:
                raise self.error("C arc without a centre CC")
            self.arc(n, motion, end, self.cc, None)
        else:
            if "R" not in other or other["R"] in ("L", "R"):
                raise self.error("CR arc without a radius R+/R-")
            self.arc(n, motion, end, None, self.number(other["R"]) * self.scale)
        self.m_words(other.get("M", ""))

"""LinuxCNC tool table files: ``T1 P1 Z12.5 D6 ;comment`` per tool.

The offsets (``X Y Z A B C U V W``) and the diameter ``D`` are read in the file's unit,
given as mm per unit (1 for a table in mm, 25.4 for one in inches — rs274 run without an
INI file reads its table in inches).  ``Q`` is the lathe tool orientation; ``I J``
(lathe angles) and ``P`` (pocket) are read and ignored.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from core.errors import InputError

__all__ = ["Tool", "read_tool_table", "parse_tool_table"]

_WORD = re.compile(r"([A-Za-z])\s*([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)")


@dataclass(frozen=True)
class Tool:
    """One tool: its number, offsets per axis (mm), diameter (mm) and lathe orientation Q."""

    number: int
    offsets: dict[str, float] = field(default_factory=dict)
    diameter: float = 0.0
    orientation: int = 0


def parse_tool_table(text: str, *, unit_mm: float = 1.0, source: str = "tool table") -> dict[int, Tool]:
    """Tools by number from tool table ``text`` (values times ``unit_mm`` give mm)."""
    tools: dict[int, Tool] = {}
    for number, raw in enumerate(text.splitlines(), start=1):
        code = raw.split(";", 1)[0].strip()
        if not code:
            continue
        words: dict[str, float] = {}
        pos = 0
        while pos < len(code):
            if code[pos].isspace():
                pos += 1
                continue
            m = _WORD.match(code, pos)
            if not m:
                raise InputError(f"{source}:{number}: cannot read {code[pos:].split()[0]!r} (expected words like T1 P1 Z12.5 D6)")
            words[m.group(1).upper()] = float(m.group(2))
            pos = m.end()
        if "T" not in words:
            raise InputError(f"{source}:{number}: tool entry without a T number")
        t = int(words["T"])
        offsets = {a: words[a] * unit_mm for a in "XYZABCUVW" if a in words}
        for a in "ABC":  # rotary offsets are degrees, not scaled
            if a in words:
                offsets[a] = words[a]
        tools[t] = Tool(t, offsets, words.get("D", 0.0) * unit_mm, int(words.get("Q", 0)))
    return tools


def read_tool_table(path: str | Path, *, unit_mm: float = 1.0) -> dict[int, Tool]:
    """Read a LinuxCNC tool table file (see :func:`parse_tool_table`)."""
    p = Path(path)
    try:
        text = p.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read tool table {p}: {exc}") from None
    return parse_tool_table(text, unit_mm=unit_mm, source=str(p))

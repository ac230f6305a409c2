"""A LinuxCNC INI file read as LinuxCNC reads it.

LinuxCNC's INI is not Python's: a key's leading whitespace is ignored (sample configs indent
keys to align their ``=``), the *first* of two equal keys in a section is the one that
counts, ``#`` and ``;`` start a comment line, and the ``linuxcnc`` start script expands
``#INCLUDE file`` lines (relative to the INI's folder) before anything reads the file.
Values are in the machine's units, ``[TRAJ] LINEAR_UNITS`` (mm or inch).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from core.errors import InputError

__all__ = ["sections", "read_sections", "linear_units_mm", "joint_unit", "KEY_LINE"]

_SECTION = re.compile(r"^\s*\[([^\]]+)\]\s*$")
#: a key line: (indent, key, " = ", value), the parts kept so that a line can be rewritten
KEY_LINE = re.compile(r"^(\s*)([A-Za-z0-9_]+)(\s*=\s*)(.*?)\s*$")
_INCLUDE = re.compile(r"^#INCLUDE\s+(\S.*?)\s*$")
#: LINEAR_UNITS words LinuxCNC knows, in mm per machine unit
_LINEAR_UNITS = {"mm": 1.0, "metric": 1.0, "in": 25.4, "inch": 25.4, "imperial": 25.4}
_MAX_INCLUDE_DEPTH = 8


def sections(lines: list[str]) -> dict[str, dict[str, tuple[int, str]]]:
    """{section: {key: (line index, value)}} of an INI's lines; the first of equal keys counts."""
    out: dict[str, dict[str, tuple[int, str]]] = {}
    cur = None
    for i, line in enumerate(lines):
        m = _SECTION.match(line)
        if m:
            cur = out.setdefault(m.group(1).strip(), {})
            continue
        if cur is None or line.lstrip().startswith(("#", ";")):
            continue
        k = KEY_LINE.match(line)
        if k:
            cur.setdefault(k.group(2), (i, k.group(4)))
    return out


def _expanded(path: Path, depth: int = 0) -> list[str]:
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError as exc:
        raise InputError.about("ini", f"{path}: cannot read ({exc.strerror or exc})") from None
    out: list[str] = []
    for line in lines:
        m = _INCLUDE.match(line)
        if m is None:
            out.append(line)
            continue
        if depth >= _MAX_INCLUDE_DEPTH:
            raise InputError.about("ini", f"{path}: #INCLUDE nested more than {_MAX_INCLUDE_DEPTH} deep")
        inc = path.parent / Path(m.group(1)).expanduser()
        if inc.is_file():  # LinuxCNC's start script says a missing one is missing and goes on
            out.extend(_expanded(inc, depth + 1))
    return out


def read_sections(path: str | Path) -> dict[str, dict[str, tuple[int, str]]]:
    """:func:`sections` of the INI at ``path`` with its ``#INCLUDE`` lines expanded (line
    indices are then those of the expanded text)."""
    path = Path(path)
    if not path.is_file():
        raise InputError.about("ini", f"{path}: no such INI file")
    return sections(_expanded(path))


def linear_units_mm(secs: dict[str, dict[str, tuple[int, str]]], path: str | Path) -> float:
    """mm per machine unit from ``[TRAJ] LINEAR_UNITS``: a word LinuxCNC knows or a number of
    units per mm; taken as mm when absent."""
    word = secs.get("TRAJ", {}).get("LINEAR_UNITS", (0, "mm"))[1].split("#")[0].strip()
    if word.lower() in _LINEAR_UNITS:
        return _LINEAR_UNITS[word.lower()]
    try:
        per_mm = float(word)  # a number: machine units per mm (1.0 is mm, 0.03937 inch)
    except ValueError:
        per_mm = 0.0
    if not (math.isfinite(per_mm) and per_mm > 0):
        raise InputError.about("ini", f"{path}: [TRAJ] LINEAR_UNITS = {word!r}: LinuxCNC knows "
                                      f"{', '.join(_LINEAR_UNITS)} or a number of units per mm")
    return 1.0 / per_mm


def joint_unit(secs: dict[str, dict[str, tuple[int, str]]], joint: int, path: str | Path) -> tuple[float, str]:
    """(factor to the recorded unit, that unit) of joint ``joint``'s positions and gains: a
    linear joint in mm (:func:`linear_units_mm`), one of ``[JOINT_n] TYPE = ANGULAR`` in degrees (1)."""
    kind = secs.get(f"JOINT_{joint}", {}).get("TYPE", (0, "LINEAR"))[1].split("#")[0].strip().upper()
    return (1.0, "deg") if kind == "ANGULAR" else (linear_units_mm(secs, path), "mm")

"""Dialect writers: turn a :class:`~gcode_gen.program.Toolpath` into program text.

Three dialects (SPEC §3):

* ``iso`` — N-numbered G00/G01/G02/G03 blocks, Fanuc / ISO 6983 style as thesis Table 3.2
  (:mod:`gcode_gen.dialects.iso`);
* ``heidenhain`` — TNC conversational ``L X+… F…`` as Tables 4.3/4.4
  (:mod:`gcode_gen.dialects.heidenhain`);
* ``linuxcnc`` — RS274NGC that LinuxCNC runs unchanged (:mod:`gcode_gen.dialects.linuxcnc`).

Every program starts with its header as ``key=value`` comments (``(key=value)`` or
``; key=value``), which :func:`gcode_gen.interpreter.parse_program` reads back into
``Program.header``.
"""

from __future__ import annotations

from pathlib import Path

from core.errors import InputError
from gcode_gen.dialects import heidenhain, iso, linuxcnc
from gcode_gen.program import Toolpath

__all__ = ["DIALECTS", "EXTENSIONS", "write", "file_name", "save"]

#: dialect name -> writer function (Toolpath -> text)
DIALECTS = {"iso": iso.write, "heidenhain": heidenhain.write, "linuxcnc": linuxcnc.write}

#: dialect name -> file extension (with the dot)
EXTENSIONS = {"iso": ".nc", "heidenhain": ".h", "linuxcnc": ".ngc"}


def _check(dialect: str) -> None:
    if dialect not in DIALECTS:
        raise InputError(f"unknown dialect {dialect!r} (use one of {', '.join(DIALECTS)})")


def write(toolpath: Toolpath, dialect: str) -> str:
    """The program text of ``toolpath`` in ``dialect`` ("iso", "heidenhain" or "linuxcnc")."""
    _check(dialect)
    return DIALECTS[dialect](toolpath)


def file_name(toolpath: Toolpath, dialect: str) -> str:
    """File name for ``toolpath`` in ``dialect``, e.g. ``ident_low.ngc``."""
    _check(dialect)
    return toolpath.name + EXTENSIONS[dialect]


def save(toolpath: Toolpath, dialect: str, directory: Path | str) -> Path:
    """Write ``toolpath`` in ``dialect`` to ``directory/<file_name>`` and return the path."""
    path = Path(directory) / file_name(toolpath, dialect)
    path.write_text(write(toolpath, dialect), encoding="utf-8")
    return path

"""RS274/NGC (LinuxCNC) and ISO word-address programs → motion blocks.

The interpreter is split by job:

* :mod:`~gcode_gen.ngc.lexer` — a line into words, parameter assignments, O-word statements;
* :mod:`~gcode_gen.ngc.expressions` — values, ``[ ]`` expressions and functions;
* :mod:`~gcode_gen.ngc.parameters` — numbered and named parameters and their scopes;
* :mod:`~gcode_gen.ngc.subroutines` — O-word subroutines, conditionals and loops;
* :mod:`~gcode_gen.ngc.codes` — a block's G/M codes: known, refused, modal groups;
* :mod:`~gcode_gen.ngc.machine` — the modal state, offsets, and the moves of a block;
* :mod:`~gcode_gen.ngc.arcs` — arc centres, radius tolerance, sweeps;
* :mod:`~gcode_gen.ngc.canned_cycles` — G73/G81–G89 expanded into moves;
* :mod:`~gcode_gen.ngc.cutter_comp` — cutter radius compensation G41/G42;
* :mod:`~gcode_gen.ngc.tool_table` — LinuxCNC tool table files.

:func:`interpret` runs a program the way LinuxCNC's interpreter does (checked against its
``rs274`` by scripts/compare_rs274.py) and returns the blocks in machine coordinates (mm,
mm/s).  docs/gcode-support.md lists what is supported and what is refused.
"""

from __future__ import annotations

import re

from core.errors import ProgramError
from gcode_gen.ngc.arcs import ArcError
from gcode_gen.ngc.expressions import Expr, ExprError, evaluate
from gcode_gen.ngc.lexer import Line, lex_line
from gcode_gen.ngc.machine import InterpError, Machine
from gcode_gen.ngc.parameters import Parameters
from gcode_gen.ngc.subroutines import Flow
from gcode_gen.ngc.tool_table import Tool, parse_tool_table, read_tool_table
from gcode_gen.program import Block

__all__ = ["interpret", "Tool", "read_tool_table", "parse_tool_table"]

_HEADER_RE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_.\-]*)\s*=\s*(.*?)\s*$")
_ACTIVE_COMMENT = re.compile(r"^\s*(msg|debug|print|log|logopen|logappend|logclose|py)\s*,", re.I)


def interpret(text: str, *, name: str = "program", dialect: str = "linuxcnc",
              tools: dict[int, Tool] | None = None) -> tuple[list[Block], dict[str, str]]:
    """Blocks (machine coordinates, mm, mm/s) and ``key=value`` header of program ``text``.

    Raises
    ------
    ProgramError
        ``name:line: message`` for anything the program does that is not supported or
        is wrong (unknown word, undefined parameter, unsupported G-code …).
    """
    params = Parameters()
    machine = Machine(params=params, tools=tools, dialect=dialect)
    header: dict[str, str] = {}
    lines: list[Line | Exception] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        try:
            lines.append(lex_line(raw, number))
        except ExprError as exc:
            lines.append(ProgramError(str(exc), line=number, source=name))

    def value(expr: Expr) -> float:
        return evaluate(expr, params.get, params.get_named, params.exists)

    state = {"ended": False, "percent": 0}

    def end() -> None:
        state["ended"] = True

    def block(line: Line) -> bool:
        machine.line, machine.n = line.number, line.n
        if not machine.blocks:
            for body in line.comments:
                if _ACTIVE_COMMENT.match(body):
                    continue
                m = _HEADER_RE.match(body)
                if m:
                    header[m.group(1)] = m.group(2)
        words = [(letter, value(expr)) for letter, expr in line.words]
        sets = []
        for target, expr in line.assignments:
            v = value(expr)
            if target[0] == "named":
                sets.append((target[1], v))
            else:
                sets.append((int(round(value(target[1]))), v))
        for key, v in sets:  # after the whole line is read, as LinuxCNC
            if isinstance(key, str):
                params.set_named(key, v)
            else:
                params.set(key, v)
        if words:
            machine.execute(words, end)
        return state["ended"]

    def percent(index: int) -> bool:
        state["percent"] += 1
        return state["percent"] > 1 or bool(machine.blocks)

    flow = None
    try:
        flow = Flow(lines, value, params, machine, iso=dialect == "iso")
        flow.run(block, percent)
        machine.finish()
    except ProgramError:
        raise
    except (InterpError, ExprError, ArcError) as exc:
        line = getattr(exc, "line", None) or (flow.current + 1 if flow else machine.line)
        raise ProgramError(str(exc), line=line, source=name) from None
    except RecursionError:
        raise ProgramError("expression nested too deeply", line=machine.line, source=name) from None
    except (OverflowError, ValueError) as exc:  # math range errors in expressions, int(inf) …
        line = flow.current + 1 if flow else machine.line
        raise ProgramError(f"value out of range: {exc}", line=line, source=name) from None
    return machine.blocks, header

"""O-word control flow: subroutines, conditionals and loops, run line by line.

Statements (LinuxCNC 2.9): ``oN sub`` … ``oN endsub [value]`` (a definition, skipped where
it stands), ``oN call [a1] [a2] …`` (arguments become ``#1``…``#30``), ``oN return [value]``
(sets ``#<_value>``), ``oN if [c]`` / ``elseif [c]`` / ``else`` / ``endif``, ``oN while [c]``
… ``endwhile``, ``oN do`` … ``oN while [c]``, ``oN repeat [n]`` … ``endrepeat``,
``oN break`` / ``continue``.  Labels are numbers or ``<names>``; the statements of one
structure share its label, as LinuxCNC requires.  Subroutines must be defined in the
program file (LinuxCNC would also search its SUBROUTINE_PATH for ``name.ngc``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

from gcode_gen.ngc.lexer import Line
from gcode_gen.ngc.machine import InterpError, Modal

__all__ = ["Flow"]

MAX_CALL_DEPTH = 100
#: Statements executed, beyond two per line of the file, before a run is taken for an
#: endless loop (a straight-through CAM program of any length never reaches it).
MAX_EXTRA_STATEMENTS = 1_000_000


@dataclass
class _Frame:
    return_pc: int
    saved_params: dict[int, float]
    label: str
    auto_restore: Modal | None = None
    repeats: dict[int, int] = field(default_factory=dict)


class Flow:
    """Runs lexed ``lines`` (a list; a lexing failure is stored as the exception) through
    ``block`` (execute one block line) with O-word control flow."""

    def __init__(self, lines: list[Line | Exception], evaluate: Callable, params, machine, iso: bool = False) -> None:  # noqa: ANN001
        self.lines = lines
        self.evaluate = evaluate
        self.params = params
        self.machine = machine
        self.iso = iso
        self.subs: dict[str, tuple[int, int]] = {}
        self.frames: list[_Frame] = []
        self.repeats: dict[int, int] = {}
        self.current = 0
        machine.on_m73 = self._m73
        self._index_subs()

    def _m73(self) -> None:
        """M73: restore the modal state when the current subroutine returns."""
        if not self.frames:
            raise InterpError("M73 outside a subroutine")
        self.frames[-1].auto_restore = self.machine.snapshot()

    def _oword(self, i: int) -> Line | None:
        ln = self.lines[i]
        return ln if isinstance(ln, Line) and ln.kind == "oword" else None

    def _index_subs(self) -> None:
        open_sub: tuple[str, int] | None = None
        for i in range(len(self.lines)):
            ln = self._oword(i)
            if ln is None:
                continue
            if ln.keyword == "sub":
                if open_sub is not None:
                    raise self._error(i, f"o{ln.label} sub inside the definition of o{open_sub[0]}")
                open_sub = (ln.label, i)
            elif ln.keyword == "endsub":
                if open_sub is None or open_sub[0] != ln.label:
                    raise self._error(i, f"o{ln.label} endsub without a matching o{ln.label} sub")
                self.subs[ln.label] = (open_sub[1], i)
                open_sub = None
        if open_sub is not None:
            raise self._error(open_sub[1], f"o{open_sub[0]} sub without endsub")

    def _error(self, i: int, message: str) -> InterpError:
        err = InterpError(message)
        err.line = i + 1  # type: ignore[attr-defined]
        return err

    def _find(self, i: int, label: str, keywords: tuple[str, ...], step: int = 1) -> int:
        """Index of the next (step=1) or previous (step=-1) statement of ``label`` with one of
        ``keywords``; stops at a sub boundary."""
        j = i + step
        while 0 <= j < len(self.lines):
            ln = self._oword(j)
            if ln is not None:
                if ln.label == label and ln.keyword in keywords:
                    return j
                if ln.keyword in ("sub", "endsub") and ln.label != label:
                    break
            j += step
        raise self._error(i, f"o{label} {self._oword(i).keyword} without a matching {' or '.join(keywords)}")

    def _cond(self, i: int, ln: Line) -> bool:
        if len(ln.args) != 1:
            raise self._error(i, f"o{ln.label} {ln.keyword} needs one condition [ ]")
        return self.evaluate(ln.args[0]) != 0.0

    def _is_do_while(self, i: int, label: str) -> bool:
        """A ``while`` closes a do-loop when the nearest earlier loop statement of its label is ``do``."""
        j = i - 1
        while j >= 0:
            ln = self._oword(j)
            if ln is not None and ln.label == label and ln.keyword in ("do", "while", "endwhile"):
                return ln.keyword == "do"
            if ln is not None and ln.keyword in ("sub", "endsub") and ln.label != label:
                return False
            j -= 1
        return False

    def run(self, block: Callable[[Line], bool], percent: Callable[[int], bool]) -> None:
        """Execute from the first line; ``block`` returns True when the program ended."""
        pc = 0
        steps, limit = 0, MAX_EXTRA_STATEMENTS + 2 * len(self.lines)
        while pc < len(self.lines):
            steps += 1
            if steps > limit:
                raise self._error(pc, f"more than {limit:,} statements executed: an endless loop?")
            self.current = pc
            ln = self.lines[pc]
            if isinstance(ln, Exception):
                raise ln
            if ln.kind == "program_number":  # Fanuc "O1234": a program number, no statement
                if not self.iso:
                    raise self._error(pc, f"O-word o{ln.label} without a keyword (sub, call, if, while, repeat, …)")
                pc += 1
            elif ln.kind == "percent":
                if percent(pc):
                    return
                pc += 1
            elif ln.kind == "oword":
                pc = self._statement(pc, ln)
            else:
                if block(ln):
                    return
                pc += 1
        if self.frames:
            raise self._error(len(self.lines) - 1, f"program ended inside subroutine o{self.frames[-1].label}")

    def _statement(self, i: int, ln: Line) -> int:  # noqa: C901 - one branch per keyword
        kw, label = ln.keyword, ln.label
        if kw == "sub":
            return self.subs[label][1] + 1
        if kw in ("endsub", "return"):
            if not self.frames:
                raise self._error(i, f"o{label} {kw} outside a subroutine call")
            if ln.args:
                self.params.set_named("_value", self.evaluate(ln.args[0]))
                self.params.set_named("_value_returned", 1.0)
            else:
                self.params.set_named("_value_returned", 0.0)
            frame = self.frames.pop()
            self.params.leave(frame.saved_params)
            if frame.auto_restore is not None:
                self.machine.restore(frame.auto_restore)
            return frame.return_pc
        if kw == "call":
            if label not in self.subs:
                raise self._error(i, f"subroutine o{label} is not defined in this program "
                                     "(subroutines in separate files are not supported)")
            if len(self.frames) >= MAX_CALL_DEPTH:
                raise self._error(i, f"subroutine calls nested deeper than {MAX_CALL_DEPTH}")
            if len(ln.args) > 30:
                raise self._error(i, f"o{label} call with {len(ln.args)} arguments (at most 30)")
            args = [self.evaluate(a) for a in ln.args]
            self.frames.append(_Frame(i + 1, self.params.enter(args), label))
            return self.subs[label][0] + 1
        if kw == "if":
            j = i
            cond = self._cond(i, ln)
            while not cond:
                j = self._find(j, label, ("elseif", "else", "endif"))
                nxt = self._oword(j)
                if nxt.keyword == "elseif":
                    cond = self._cond(j, nxt)
                else:
                    break
            return j + 1
        if kw in ("elseif", "else"):  # end of an executed branch
            return self._find(i, label, ("endif",)) + 1
        if kw in ("endif", "do"):
            return i + 1
        if kw == "while":
            if self._is_do_while(i, label):
                return self._find(i, label, ("do",), -1) + 1 if self._cond(i, ln) else i + 1
            return i + 1 if self._cond(i, ln) else self._find(i, label, ("endwhile",)) + 1
        if kw == "endwhile":
            return self._find(i, label, ("while",), -1)
        if kw == "repeat":
            if len(ln.args) != 1:
                raise self._error(i, f"o{label} repeat needs a count [ ]")
            count = int(round(self.evaluate(ln.args[0])))
            if count <= 0:
                return self._find(i, label, ("endrepeat",)) + 1
            self.repeats[i] = count
            return i + 1
        if kw == "endrepeat":
            start = self._find(i, label, ("repeat",), -1)
            self.repeats[start] = self.repeats.get(start, 1) - 1
            if self.repeats[start] > 0:
                return start + 1
            del self.repeats[start]
            return i + 1
        if kw in ("break", "continue"):
            j = self._find(i, label, ("endwhile", "endrepeat", "while"))
            end = self._oword(j)
            if kw == "break":
                if end.keyword == "endrepeat":
                    self.repeats.pop(self._find(j, label, ("repeat",), -1), None)
                return j + 1
            if end.keyword == "endwhile":
                return self._find(i, label, ("while",), -1)
            return j  # endrepeat counts down; a do-while's closing while tests its condition
        raise self._error(i, f"o{label} {kw} is not supported")

"""Programs → the commanded axis positions a CNC's interpolator sends its servo loops.

One implementation for every machine that runs programs: the built-in virtual CNC
(:func:`virtual_cnc.simulate`) and the identified virtual machine
(:mod:`ident.virtual_machine`) both call :func:`command_programs`, so the same program
on the same interpolator limits gives the same command, sample for sample.

Programs run one after another as separate segments of one run (the low- and
high-speed identification sets), each starting where the previous one stopped, on one
continuous clock; after each program the command is held for ``settle_s`` so the drive
settles before the next one.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence, Union

import numpy as np

from core.errors import InputError, MachineError
from gcode_gen.dialects import write
from gcode_gen.interpolator import interpolate
from gcode_gen.interpreter import parse_program
from gcode_gen.program import Block, Program, Toolpath

__all__ = ["CommandedRun", "ProgramLike", "command_programs", "load_program", "SETTLE_S"]

#: Commanded position held after each program so the drive settles before the next one (s).
SETTLE_S = 0.2

#: What may be passed as a program: a file, a parsed Program or a generated Toolpath.
ProgramLike = Union[str, Path, Program, Toolpath]


@dataclass(frozen=True)
class CommandedRun:
    """The interpolated command of one or more programs, sampled at ``Ts``.

    Attributes
    ----------
    t : (N,) time, s, k·Ts.
    commanded : axis -> (N,) commanded position, mm, for every axis the programs move.
    segment : (N,) index of the program each sample belongs to.
    line : (N,) line number (in its program) of the block being executed, 0 before the first
        block and while settling.
    Ts : sample period, s.
    programs : per program ``{"name", "sha256"}``.
    blocks : per program, its parsed blocks (line number -> Block), for the geometry of
        the path (arc centres) and for naming places by line.
    sequence : per program, its blocks in the order they run (a subroutine defined at the
        top runs where it is called; a loop's blocks once per pass).
    """

    t: np.ndarray
    commanded: dict[str, np.ndarray]
    segment: np.ndarray
    line: np.ndarray
    Ts: float
    programs: tuple[dict[str, str], ...]
    blocks: tuple[dict[int, Block], ...]
    texts: tuple[str, ...] = ()
    sequence: tuple[tuple[Block, ...], ...] = ()

    def executed(self, p: int) -> tuple[Block, ...]:
        """Program ``p``'s blocks in the order they run (:attr:`sequence`; by line where it is not kept)."""
        if p < len(self.sequence):
            return self.sequence[p]
        return tuple(b for _, b in sorted(self.blocks[p].items()))

    def repeated_lines(self, p: int) -> frozenset[int]:
        """Program ``p``'s lines executed more than once as different blocks (a loop, a subroutine
        called with other arguments): :attr:`blocks` holds their last execution, so their geometry
        is not the one of every sample labelled with them."""
        first: dict[int, Block] = {}
        return frozenset(b.line for b in self.executed(p) if first.setdefault(b.line, b) != b)

    @property
    def axes(self) -> list[str]:
        return list(self.commanded)

    @property
    def block_key(self) -> np.ndarray:
        """(N,) one integer per (program, line) executed at each sample: for grouping samples by block."""
        return self.segment.astype(np.int64) * (int(self.line.max(initial=0)) + 1) + self.line

    def per_sample(self, value: Callable[[int, Block], Any], default: Any, dtype: Any = object) -> np.ndarray:
        """(N,) ``value(program index, block)`` of the block executed at each sample, ``default``
        where none is (before the first block, while settling).

        Evaluated once per distinct block, not once per sample.
        """
        distinct, inverse = np.unique(self.block_key, return_inverse=True)
        width = int(self.line.max(initial=0)) + 1
        values = []
        for key in distinct:
            p, line = divmod(int(key), width)
            block = self.blocks[p].get(line)
            values.append(default if block is None else value(p, block))
        return np.asarray(values, dtype=dtype)[inverse]

    def block_at(self, k: int) -> Block | None:
        """The block whose line sample ``k`` is labelled with (None while settling)."""
        return self.blocks[int(self.segment[k])].get(int(self.line[k]))

    def feed_at(self, k: int) -> float | None:
        """Programmed feed (mm/s) of the block executed at sample ``k``, None for rapids/settling."""
        blk = self.block_at(k)
        return None if blk is None or blk.motion == "G0" else blk.feed


def load_program(item: ProgramLike, tool_table: "str | Path | None" = None) -> tuple[str, str, Program]:
    """(name, text, parsed program) of a program file, a parsed Program or a generated Toolpath;
    ``tool_table``: a LinuxCNC tool table file for the tool offsets (G43 H, G41/G42 D) of a file."""
    if isinstance(item, Toolpath):
        text = write(item, "linuxcnc")
        return item.name, text, parse_program(text, name=item.name)
    if isinstance(item, Program):
        return item.name, item.text, item
    path = Path(item)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise InputError(f"{path}: no such program file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read program ({exc})") from None
    return path.name, text, parse_program(text, name=path.name, tool_table=tool_table)


def parse_program_files(paths: Sequence[ProgramLike], tool_table: "str | Path | None") -> list[ProgramLike]:
    """Program files parsed with ``tool_table`` (as :class:`Program`, which every command runs
    as it would the file); the items unchanged without a table."""
    if tool_table is None:
        return list(paths)
    if not Path(tool_table).is_file():
        raise InputError(f"--tool-table {tool_table}: no such file")
    return [load_program(p, tool_table)[2] for p in paths]


def command_programs(
    programs: Sequence[ProgramLike],
    axes: Sequence[str],
    *,
    Ts: float,
    a_max: float,
    j_max: float | None = None,
    rapid_feed: float = 200.0,
    settle_s: float = SETTLE_S,
    machine_name: str = "the machine",
    axis_limits: "dict[str, tuple[float, float]] | None" = None,
    start: "dict[str, float] | None" = None,
) -> CommandedRun:
    """Interpolate ``programs`` in order on a machine with ``axes`` and these limits.

    ``axis_limits`` (axis -> max velocity, max acceleration) plans with per-axis limits
    (:func:`gcode_gen.interpolator.interpolate`).  Every axis starts at ``start`` (default 0 mm).  Raises :class:`MachineError` (naming program and line)
    when a block moves an axis the machine does not have, and :class:`InputError` when
    the programs move no axis.
    """
    if not programs:
        raise InputError("no program given")
    start = {a: float((start or {}).get(a, 0.0)) for a in axes}
    parts: list[dict[str, np.ndarray]] = []
    segments, lines, info, texts, blocks, sequence = [], [], [], [], [], []
    moved: set[str] = set()
    n_settle = int(round(settle_s / Ts))
    for index, item in enumerate(programs):
        name, text, program = load_program(item)
        info.append({"name": name, "sha256": hashlib.sha256(text.encode()).hexdigest()})
        texts.append(text)
        blocks.append({b.line: b for b in program.blocks})
        sequence.append(tuple(program.blocks))
        for block in program.blocks:
            unknown = set(block.target) - set(axes)
            if unknown:
                raise MachineError(f"{name}:{block.line}: moves axis {sorted(unknown)[0]}, "
                                   f"{machine_name} has axes {', '.join(axes)}")
            moved |= set(block.target)
        try:
            traj = interpolate(program, Ts=Ts, a_max=a_max, j_max=j_max, rapid_feed=rapid_feed, start=dict(start),
                               axis_limits=axis_limits)
        except InputError as exc:  # the interpolator names the line; the program's name added
            raise InputError(f"{name}: {exc}") from None
        part = {}
        for a in axes:
            x = np.asarray(traj.axes.get(a, np.full(traj.t.shape, start[a])), dtype=float)
            part[a] = np.concatenate([x, np.full(n_settle, x[-1] if x.size else start[a])])
            start[a] = float(part[a][-1])
        n = traj.t.shape[0] + n_settle
        segments.append(np.full(n, index, dtype=np.int32))
        lines.append(np.concatenate([traj.block, np.zeros(n_settle, dtype=np.int64)]))
        parts.append(part)
    if not moved:
        raise InputError("the programs move no axis")
    moving = [a for a in axes if a in moved]
    segment = np.concatenate(segments)
    return CommandedRun(
        t=np.arange(segment.size) * Ts,
        commanded={a: np.concatenate([p[a] for p in parts]) for a in moving},
        segment=segment,
        line=np.concatenate(lines).astype(np.int64),
        Ts=float(Ts),
        programs=tuple(info),
        blocks=tuple(blocks),
        sequence=tuple(sequence),
        texts=tuple(texts),
    )

"""The virtual CNC: G-code programs → interpolator → servo loops and drive physics → Recording.

This is the one place the three parts meet; ``agent simulate`` writes its result to a
log and ``agent serve`` streams it over a transport in real time.  Programs run one
after another as separate segments of one recording (the low- and high-speed sets),
each continuing from where the previous one stopped, on one continuous controller clock.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Sequence

import numpy as np

from core.errors import InputError, MachineError
from virtual_cnc.effects import parse_effect
from virtual_cnc.presets import DEFAULT_MACHINE, Machine, load_machine
from gcode_gen.dialects import write
from gcode_gen.interpolator import interpolate
from gcode_gen.interpreter import parse_program
from gcode_gen.program import Program, Toolpath
from core.recording import AxisTrace, Recording

__all__ = ["simulate", "SETTLE_S"]

#: Commanded position held after each program so the drive settles before the next one (s).
SETTLE_S = 0.2


def _program(item: "str | Path | Program | Toolpath") -> tuple[str, str, Program]:
    """(name, text, parsed program) of a program file, a parsed Program or a generated Toolpath."""
    if isinstance(item, Toolpath):
        text = write(item, "linuxcnc")
        return item.name, text, parse_program(text, name=item.name)
    if isinstance(item, Program):
        return item.name, item.text, item
    path = Path(item)
    text, program = _read_program(path)
    return path.name, text, program


def _read_program(path: Path):
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise InputError(f"{path}: no such program file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read program ({exc})") from None
    return text, parse_program(text, name=path.name)


def simulate(
    programs: Sequence[str | Path],
    machine: str | Path | Machine | None = None,
    effects: Sequence[str] = (),
    seed: int = 0,
) -> Recording:
    """Run programs on the virtual CNC and return what a capture of the machine would record.

    Parameters
    ----------
    programs : G-code files (iso, heidenhain or linuxcnc dialect), parsed
        :class:`gcode_gen.Program` s or generated :class:`gcode_gen.Toolpath` s, run in order.
    machine : preset name, TOML machine file, or a Machine; default :data:`DEFAULT_MACHINE`.
    effects : ``NAME=VALUE`` strings of SPEC §7 physics added to every axis.
    seed : seed of the encoder noise.
    """
    if not programs:
        raise InputError("no program given")
    mach = machine if isinstance(machine, Machine) else load_machine(machine or DEFAULT_MACHINE)
    fx = [parse_effect(e) for e in effects]
    Ts = mach.Ts
    start = {a: 0.0 for a in mach.axes}
    parts: list[dict[str, np.ndarray]] = []  # per program: axis -> commanded (mm)
    segments: list[np.ndarray] = []
    info = []
    moved: set[str] = set()
    for index, p in enumerate(programs):
        name, text, program = _program(p)
        info.append({"name": name, "sha256": hashlib.sha256(text.encode()).hexdigest()})
        for block in program.blocks:
            unknown = set(block.target) - set(mach.axes)
            if unknown:
                raise MachineError(
                    f"{name}:{block.line}: moves axis {sorted(unknown)[0]}, "
                    f"machine {mach.name} has axes {', '.join(mach.axes)}"
                )
            moved |= set(block.target)
        traj = interpolate(program, Ts=Ts, a_max=mach.a_max, j_max=mach.j_max,
                           rapid_feed=mach.rapid_feed, start=dict(start))
        n_settle = int(round(SETTLE_S / Ts))
        part = {}
        for a in mach.axes:
            x = np.asarray(traj.axes.get(a, np.full(traj.t.shape, start[a])), dtype=float)
            part[a] = np.concatenate([x, np.full(n_settle, x[-1] if x.size else start[a])])
            start[a] = float(part[a][-1])
        segments.append(np.full(traj.t.shape[0] + n_settle, index, dtype=np.int32))
        parts.append(part)
    if not moved:
        raise InputError("the programs move no axis")
    axes = [a for a in mach.axes if a in moved]
    commanded = {a: np.concatenate([part[a] for part in parts]) for a in axes}
    segment = np.concatenate(segments)
    from virtual_cnc.servo import simulate_machine  # numba: imported when a simulation runs

    actual = simulate_machine(commanded, mach, fx, seed=seed)
    n = segment.size
    return Recording(
        t=np.arange(n) * Ts,
        axes={a: AxisTrace(commanded[a], np.asarray(actual[a], dtype=float)) for a in axes},
        sample_period=Ts,
        segment=segment,
        metadata={
            "transport": "simulation",
            "controller": f"rapid-ident virtual CNC, machine {mach.name}: {mach.description}",
            "machine": mach.name,
            "effects": [str(e) for e in effects],
            "seed": seed,
            "programs": info,
        },
    )

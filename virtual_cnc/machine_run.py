"""The virtual CNC: G-code programs → interpolator → servo loops and drive physics → Recording.

This is the one place the three parts meet; ``agent simulate`` writes its result to a
log and ``agent serve`` streams it over a transport in real time.  Programs run one
after another as separate segments of one recording (the low- and high-speed sets),
each continuing from where the previous one stopped, on one continuous controller clock.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from core.recording import AxisTrace, Recording
from gcode_gen.commands import SETTLE_S, ProgramLike, command_programs
from virtual_cnc.effects import parse_effect
from virtual_cnc.presets import DEFAULT_MACHINE, Machine, load_machine

__all__ = ["simulate", "SETTLE_S"]


def simulate(
    programs: Sequence[ProgramLike],
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
    mach = machine if isinstance(machine, Machine) else load_machine(machine or DEFAULT_MACHINE)
    fx = [parse_effect(e) for e in effects]
    run = command_programs(programs, list(mach.axes), Ts=mach.Ts, a_max=mach.a_max, j_max=mach.j_max,
                           rapid_feed=mach.rapid_feed, machine_name=f"machine {mach.name}")
    from virtual_cnc.servo import simulate_machine  # numba: imported when a simulation runs

    actual = simulate_machine(run.commanded, mach, fx, seed=seed)
    return Recording(
        t=run.t,
        axes={a: AxisTrace(x, np.asarray(actual[a], dtype=float)) for a, x in run.commanded.items()},
        sample_period=run.Ts,
        segment=run.segment,
        metadata={
            "transport": "simulation",
            "controller": f"rapid-ident virtual CNC, machine {mach.name}: {mach.description}",
            "machine": mach.name,
            "effects": [str(e) for e in effects],
            "seed": seed,
            "programs": [dict(p) for p in run.programs],
        },
    )

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


def not_following(rec: Recording) -> list[str]:
    """One line per axis whose simulated position strays further from the command than the
    command's whole travel: no drive that follows its command does that, so the loop (with
    the effects added) is unstable or held at its output limit — a dead time of tens of
    milliseconds in a loop of ~50 Hz bandwidth, for one (``agent simulate`` and ``agent serve``
    warn; the run is theirs all the same)."""
    out = []
    for name, tr in rec.axes.items():
        travel = float(np.ptp(tr.commanded))
        e = np.abs(tr.tracking_error)
        worst = float(np.max(e)) if e.size else 0.0
        if travel > 0.0 and not worst <= travel:  # NaN counts as not following
            out.append(f"{name}: the simulated axis does not follow the command (tracking error up to "
                       f"{worst:.3g} mm over {travel:.3g} mm of travel): the loop with the effects added is "
                       f"unstable or held at its output limit")
    return out

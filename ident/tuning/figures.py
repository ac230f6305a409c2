"""The figures a tuning is judged by, predicted on the recovered plants with the sampled loop.

* ``ballbar``: the ISO 230-4 circle pair (ccw, cw, started at 45°, :mod:`ident.ballbar`),
  figure = the larger circularity G of the two data arcs, µm.  With ``lead_deg`` the test as a
  machine runs it (:func:`ident.synthetic_ballbar.ballbar_program`, what ``agent ballbar
  --program-out`` writes: one program, feed-in and feed-out arcs, ccw then cw after a dwell,
  from rest on the feed-in arc's start with the loop's state at zero); without, the two
  circles each from rest at their start point (the start transient is then on the data arc);
* ``program``: a part program, figure = max |contour error| over its feed moves, µm
  (:func:`ident.prediction.contour_of_run`; the tracking error for a one-axis program).

The command is the virtual machine's interpolation (:meth:`VirtualMachine.command`), each
axis follows it through :func:`ident.tuning.loop.simulate_loop` with its plant and gains,
so before and after are predicted the same way.  Also returned: the largest |u| over the
run divided by the output limit (0 when there is none).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Mapping, Sequence

import numpy as np

from gcode_gen.commands import CommandedRun, ProgramLike
from ident.tuning.controllers import Gains
from ident.tuning.loop import simulate_loop
from ident.tuning.plant import Plant
from ident.virtual_machine import VirtualMachine

__all__ = ["Criterion", "predicted_figure", "follow"]


@dataclass(frozen=True)
class Criterion:
    """What a tuning is scored on: the ballbar pair (radius, feed) or a list of programs."""

    kind: str  # "ballbar" | "program"
    runs: tuple[CommandedRun, ...]
    axes: tuple[str, ...]
    radius: float = 0.0
    feed: float = 0.0
    centre: tuple[float, float] = (0.0, 0.0)
    data_lines: tuple[int, ...] = ()  # per run, the program line of its data arc (ballbar)

    @classmethod
    def ballbar(cls, vm: VirtualMachine, axes: tuple[str, str], radius: float, feed: float,
                centre: tuple[float, float] = (0.0, 0.0), lead_deg: float | None = None) -> "Criterion":
        """The ballbar pair; ``lead_deg``: as one program with feed-in/out arcs (module docstring)."""
        from gcode_gen.toolpaths import circle
        from ident.synthetic_ballbar import START_DEG, ballbar_program, data_arc_lines, start_point

        if lead_deg is None:
            runs = tuple(vm.command([circle(size=2 * radius, feed=feed, center=centre, axes=axes, direction=d,
                                            start_deg=START_DEG, name=f"ballbar_{d}")]) for d in ("ccw", "cw"))
            return cls("ballbar", runs, tuple(axes), radius, feed, tuple(centre),
                       tuple(max(r.blocks[0]) for r in runs))
        run = vm.command([ballbar_program(radius, feed, centre, axes, lead_deg)],
                         start=dict(zip(axes, start_point(radius, centre, lead_deg))))
        return cls("ballbar", (run, run), tuple(axes), radius, feed, tuple(centre), data_arc_lines(run, lead_deg))

    @classmethod
    def program(cls, vm: VirtualMachine, programs: Sequence[ProgramLike]) -> "Criterion":
        run = vm.command(list(programs))
        return cls("program", (run,), tuple(a for a in run.commanded if a in vm.axes))

    @property
    def unit(self) -> str:
        """The figure's name in the JSON: circularity, max contour error, or max tracking error (one axis)."""
        if self.kind == "ballbar":
            return "circularity_um"
        return "contour_error_max_um" if len(self.axes) >= 2 else "tracking_error_max_um"


def follow(run: CommandedRun, gains: Mapping[str, Gains], plants: Mapping[str, Plant],
           axes: Sequence[str]) -> tuple[dict[str, np.ndarray], float]:
    """Actual positions per axis of ``run`` on the sampled loops, and max |u|/limit over them."""
    actual, ratio = {}, 0.0
    for a in axes:
        g, p = gains[a], plants[a]
        kind, Kp, Ki, Kd, Kv, Ka = g.law()
        timing = g.timing
        if p.delay_s:
            timing = replace(timing, delay=timing.delay + int(round(p.delay_s / run.Ts)))
        xr = run.commanded[a]
        seg = run.segment
        starts = np.r_[np.flatnonzero(np.r_[True, seg[1:] != seg[:-1]]), seg.size]
        xs, us = [], []
        for s0, s1 in zip(starts[:-1], starts[1:]):
            x, u = simulate_loop(xr[s0:s1], run.Ts, kind=kind, Kp=Kp, Ki=Ki, Kd=Kd, Kv=Kv, Ka=Ka, Kf0=g.ff0, kj=p.kj,
                                 bj=p.bj, d_plus=p.d_plus, d_minus=p.d_minus, u_max=g.u_max, timing=timing,
                                 integration=p.integration)
            xs.append(x)
            us.append(u)
        actual[a] = np.concatenate(xs)
        if math.isfinite(g.u_max):
            ratio = max(ratio, float(np.max(np.abs(np.concatenate(us)))) / g.u_max)
    return actual, ratio


def predicted_figure(test: Criterion, gains: Mapping[str, Gains], plants: Mapping[str, Plant]) -> tuple[float, float]:
    """(figure in µm, max |u|/limit) of ``test`` (module docstring)."""
    if test.kind == "ballbar":
        from ident.ballbar import analyse_ballbar, ballbar_run

        runs, ratio, followed = [], 0.0, {}
        for run, direction, line in zip(test.runs, ("ccw", "cw"), test.data_lines):
            if id(run) not in followed:  # the one-program test is followed once
                followed[id(run)] = follow(run, gains, plants, test.axes)
            act, r = followed[id(run)]
            ratio = max(ratio, r)
            arc = np.flatnonzero(run.line == line)
            x, y = test.axes
            if not (np.all(np.isfinite(act[x])) and np.all(np.isfinite(act[y]))):
                return math.inf, ratio
            runs.append(ballbar_run(act[x][arc], act[y][arc], centre=test.centre, radius=test.radius,
                                    feed=test.feed, direction=direction, xc=run.commanded[x][arc],
                                    yc=run.commanded[y][arc], dt=run.Ts))
        res = analyse_ballbar(runs, tuple(test.axes))
        return max(f.circularity_um for f in res.runs), ratio
    from ident.prediction import _feed_moves, contour_of_run

    run = test.runs[0]
    act, ratio = follow(run, gains, plants, test.axes)
    if any(not np.all(np.isfinite(v)) for v in act.values()):
        return math.inf, ratio
    if len(test.axes) >= 2:
        err = contour_of_run(run, {a: run.commanded[a] for a in test.axes}, act)
    else:
        a = test.axes[0]
        err = run.commanded[a] - act[a]
    feed = _feed_moves(run)
    sel = feed if feed.any() else np.ones(err.size, bool)
    return 1e3 * float(np.max(np.abs(err[sel]))), ratio

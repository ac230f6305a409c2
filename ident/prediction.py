"""What a machinist asks of a predicted part program: tracking and contour errors, and where.

:func:`analyse` takes a :class:`ident.virtual_machine.Prediction` (a program run on the
identified drives) and returns a :class:`PredictionSummary`: per axis the tracking error
(commanded − predicted actual), the contour error along the toolpath (the thesis's
normal distance to the programmed path, lines and arcs, all moving axes together; see
:func:`ident.contour.path_contour_error`), its max and rms over the feed moves, and the
worst places by program line, time, position and feed.

:func:`compare` scores a prediction against a recording of the same motion (the
thesis's circle/diamond comparisons, §4.3.3): both contour errors on the recorded
command, and the difference between them.

One definition of the contour error everywhere: the normal distance to the programmed
path, over the samples of the feed moves (G1/G2/G3) where the command moves.  A recording's
samples are assigned to the program's blocks by where its command goes (:func:`block_of_samples`:
each block ends when the command reaches the block's end point), so a recording from another
controller's planner, a G0 lead-in and the dwells are told apart the same way as in the
prediction.  The cycle time is the program's run time: first to last moving command sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from core.recording import Recording
from gcode_gen.commands import CommandedRun, ProgramLike
from gcode_gen.path_mode import path_tolerances
from gcode_gen.program import ROTARY_AXES
from ident.contour import path_contour_error
from ident.virtual_machine import Prediction, VirtualMachine

__all__ = ["AxisErrors", "Place", "PredictionSummary", "Comparison", "predict", "analyse", "compare",
           "contour_of_run", "block_of_samples", "cycle_time_s", "WORST_PLACES", "END_TOLERANCE_MM"]

#: How many worst places are listed.
WORST_PLACES = 5

#: mm: a recorded command whose nearest approach to a block's end point is this close has
#: reached it.  LinuxCNC splits the servo period in which a block ends between it and the
#: next one, so even in exact stop the samples pass a corner within about a·Ts² (3 µm at
#: 2828 mm/s², 1 ms), not on it.
END_TOLERANCE_MM = 5e-3


def line_number_words(line: int, n: int | None = None) -> str:
    """A program line's number and, if it has one, its block number: ``24 (N90)``."""
    return f"{line}" + ("" if n is None else f" (N{n})")


def line_words(program: str, line: int, n: int | None = None) -> str:
    """Where a program line is, as a machinist looks it up: ``part.ngc line 24 (N90)``."""
    return f"{program} line {line_number_words(line, n)}"


@dataclass(frozen=True)
class AxisErrors:
    """Tracking error of one axis over the feed moves, mm."""

    axis: str
    max_abs_mm: float
    rms_mm: float
    at_s: float
    line: int
    program: str
    n: int | None = None  # the line's block number (N word), if it has one

    @property
    def where(self) -> str:
        return line_words(self.program, self.line, self.n)

    def to_dict(self) -> dict[str, Any]:
        return {"max_abs_mm": self.max_abs_mm, "rms_mm": self.rms_mm, "at_s": self.at_s,
                "program": self.program, "line": self.line, "block_number": self.n}


@dataclass(frozen=True)
class Place:
    """The largest contour error on one program line."""

    program: str
    line: int
    t_s: float
    position_mm: dict[str, float]
    feed_mm_s: float | None  # as programmed (F); None for a rapid
    contour_error_mm: float
    speed_mm_s: float = math.nan  # the command's path speed there (a planner lowers F to its limits)
    n: int | None = None  # the line's block number (N word), if it has one

    @property
    def where(self) -> str:
        return line_words(self.program, self.line, self.n)

    def to_dict(self) -> dict[str, Any]:
        return {"program": self.program, "line": self.line, "block_number": self.n, "t_s": self.t_s,
                "position_mm": self.position_mm, "feed_mm_s": self.feed_mm_s, "speed_mm_s": self.speed_mm_s,
                "contour_error_mm": self.contour_error_mm}


@dataclass(frozen=True)
class PredictionSummary:
    """Figures of one program run on one virtual machine."""

    machine: str
    axes: tuple[str, ...]
    tracking: dict[str, AxisErrors]
    contour: np.ndarray | None  # (N,) mm, None for a single moving axis
    feed_move: np.ndarray  # (N,) bool: a G1/G2/G3 block is executing
    contour_max_mm: float | None
    contour_rms_mm: float | None
    worst: tuple[Place, ...] = ()
    warnings: tuple[str, ...] = ()
    prediction: Prediction | None = field(default=None, repr=False)
    cycle_time_s: float | None = None
    planner: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "machine": self.machine,
            "axes": list(self.axes),
            "planner": self.planner,
            "cycle_time_s": self.cycle_time_s,
            "tracking_error": {a: e.to_dict() for a, e in self.tracking.items()},
            "contour_error": None if self.contour is None else {
                "max_abs_mm": self.contour_max_mm, "rms_mm": self.contour_rms_mm,
                "worst_places": [p.to_dict() for p in self.worst]},
            "warnings": list(self.warnings),
        }


@dataclass(frozen=True)
class Comparison:
    """Predicted vs recorded contour error of the same motion, mm (on the recorded command)."""

    source: str
    t: np.ndarray
    measured: np.ndarray
    predicted: np.ndarray
    mask: np.ndarray  # the samples compared: feed moves where the command moves
    measured_cycle_s: float | None = None
    predicted_cycle_s: float | None = None
    standalone: dict[str, float] | None = None  # the prediction on its own planned command vs measured

    @property
    def max_ratio(self) -> float:
        """max |predicted| / max |measured| over the compared samples."""
        return float(np.max(np.abs(self.predicted[self.mask])) / np.max(np.abs(self.measured[self.mask])))

    @property
    def rms_difference_ratio(self) -> float:
        """rms(predicted − measured) / rms(measured)."""
        m, p = self.measured[self.mask], self.predicted[self.mask]
        return float(np.sqrt(np.mean((p - m) ** 2)) / np.sqrt(np.mean(m ** 2)))

    def to_dict(self) -> dict[str, Any]:
        m, p = self.measured[self.mask], self.predicted[self.mask]
        return {"source": self.source, "measured_max_abs_mm": float(np.max(np.abs(m))),
                "predicted_max_abs_mm": float(np.max(np.abs(p))),
                "measured_rms_mm": float(np.sqrt(np.mean(m ** 2))), "predicted_rms_mm": float(np.sqrt(np.mean(p ** 2))),
                "max_ratio": self.max_ratio, "rms_difference_ratio": self.rms_difference_ratio,
                "measured_cycle_time_s": self.measured_cycle_s, "predicted_cycle_time_s": self.predicted_cycle_s,
                "standalone": self.standalone}


def _labels_of(run: CommandedRun) -> tuple[np.ndarray, np.ndarray]:
    return run.segment.astype(np.int64), run.line.astype(np.int64)


def _per_label(run: CommandedRun, labels: tuple[np.ndarray, np.ndarray], value, default, dtype) -> np.ndarray:  # noqa: ANN001
    """(N,) ``value(program index, block)`` per sample of ``labels`` (program, line), ``default`` where no block."""
    return replace(run, segment=labels[0], line=labels[1]).per_sample(value, default, dtype=dtype)


def _arcs(run: CommandedRun, axes: list[str], labels: tuple[np.ndarray, np.ndarray] | None = None
          ) -> tuple[list, np.ndarray | None, tuple[int, int]]:
    """Arc geometry per sample (of ``labels``, default the run's own) for :func:`path_contour_error`: arcs of
    the XY plane (G17) only; an arc of another plane, or of a line that ran as different arcs
    (a loop, a subroutine: :meth:`CommandedRun.repeated_lines`), counts as the path its samples draw."""
    if "X" not in axes or "Y" not in axes:
        return [], None, (0, 1)
    plane = (axes.index("X"), axes.index("Y"))
    arcs: list[tuple[np.ndarray, float, float]] = []
    index: dict[tuple[int, int], int] = {}
    for p, blocks in enumerate(run.blocks):
        again = run.repeated_lines(p)
        for line, b in blocks.items():
            if (b.motion in ("G2", "G3") and b.plane == "XY" and b.center and "X" in b.target and "Y" in b.target
                    and line not in again):
                c = np.array([b.center["X"], b.center["Y"]])
                r = float(np.hypot(b.target["X"] - c[0], b.target["Y"] - c[1]))
                index[(p, line)] = len(arcs)
                arcs.append((c, r, 1.0 if b.motion == "G3" else -1.0))
    if not arcs:
        return [], None, plane
    of = _per_label(run, labels or _labels_of(run), lambda p, b: index.get((p, b.line), -1), -1, np.int64)
    return arcs, of, plane


def _moving(commanded: dict[str, np.ndarray]) -> np.ndarray:
    """(N,) True where the command differs from the sample before (sample 0: False)."""
    P = np.column_stack(list(commanded.values()))
    return np.concatenate([[False], np.any(np.diff(P, axis=0) != 0, axis=1)])


def _feed_moves(run: CommandedRun, commanded: dict[str, np.ndarray] | None = None,
                labels: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(N,) True where a feed move (G1/G2/G3) is executing and the command moves: the samples
    every contour-error figure is taken over."""
    feed = _per_label(run, labels or _labels_of(run), lambda p, b: b.motion in ("G1", "G2", "G3"), False, bool)
    return feed & _moving(commanded if commanded is not None else run.commanded)


def block_of_samples(run: CommandedRun, commanded: dict[str, np.ndarray],
                     tol: float = END_TOLERANCE_MM) -> tuple[np.ndarray, np.ndarray]:
    """(program index, line) of the block executing at each sample of a recorded ``commanded``.

    The program's blocks are walked in the order they run (:meth:`CommandedRun.executed`:
    a loop's blocks once per pass) from the run's start: a block with motion ends
    at the sample where the command comes nearest its end point, within ``tol``, after
    having been farther (a full circle starts on its end point); a block
    without motion (a dwell, a move to where the axes are) ends at once.  Samples after
    the last block get line 0 (settling), as in the prediction.
    """
    axes = list(commanded)
    X = np.column_stack([commanded[a] for a in axes])
    ends, lines, moves, tols = [], [], [], []
    pos = np.array([run.commanded[a][0] if a in run.commanded else 0.0 for a in axes])
    for p in range(len(run.blocks)):
        executed = run.executed(p)
        blend = path_tolerances(executed)
        for b in executed:
            line = b.line
            tols.append(tol + float(blend.get(line) or 0.0))  # a blended corner is passed within G64 P
            q = pos.copy()
            for a, v in b.target.items():
                if a in axes:
                    q[axes.index(a)] = v
            moves.append(b.motion in ("G2", "G3") or bool(np.any(np.abs(q - pos) > tol)))
            ends.append(q)
            lines.append((p, line))
            pos = q
    seg = np.full(len(X), len(run.blocks) - 1, dtype=np.int64)
    line = np.zeros(len(X), dtype=np.int64)
    k_block, away = 0, False
    for k in range(len(X)):
        while k_block < len(ends) and not moves[k_block]:
            k_block += 1
        if k_block >= len(ends):
            break
        seg[k], line[k] = lines[k_block]
        dist = float(np.linalg.norm(X[k] - ends[k_block]))
        near = dist <= tols[k_block]
        closest = k + 1 == len(X) or float(np.linalg.norm(X[k + 1] - ends[k_block])) >= dist
        if near and away and closest:
            k_block, away = k_block + 1, False
        elif not near:
            away = True
    # A block's motion is the one continuous movement that ends on its end point: a step of
    # the command before it (a machine switched on takes its command from the feedback) is
    # not the block's.
    moving = _moving(commanded)
    key = seg * (int(line.max(initial=0)) + 1) + line
    change = np.flatnonzero(np.diff(key)) + 1
    for a, b in zip(np.concatenate([[0], change]), np.concatenate([change, [len(X)]])):
        if line[a] == 0:
            continue
        rest = np.flatnonzero(~moving[a:b - 1]) if b - a > 1 else np.zeros(0, dtype=np.int64)
        if rest.size and moving[a:b].any():
            line[a:a + rest[-1]] = 0  # up to the last sample at rest before the final movement
    return seg, line


def cycle_time_s(run: CommandedRun, commanded: dict[str, np.ndarray] | None = None,
                 labels: tuple[np.ndarray, np.ndarray] | None = None, Ts: float | None = None) -> float | None:
    """The program's run time, s: from the start of its first block's motion to the end of its
    last motion, plus the dwells programmed before its first motion (of ``commanded`` with
    its ``labels``, :func:`block_of_samples`; default the run's own command)."""
    cmd = run.commanded if commanded is None else commanded
    seg, line = labels or _labels_of(run)
    k = np.flatnonzero(_moving(cmd) & (line > 0))
    if k.size == 0:
        return None
    first_p, first_line = int(seg[k[0]]), int(line[k[0]])
    before = 0.0  # the dwells that run before the first moving block, in the order blocks run
    for p in range(first_p + 1):
        for b in run.executed(p):
            if p == first_p and b.line == first_line:
                break
            if b.motion == "G4":
                before += float(b.dwell_s or 0.0)
    return float((k[-1] - k[0] + 1) * (Ts or run.Ts)) + before


def contour_of_run(run: CommandedRun, commanded: dict[str, np.ndarray], actual: dict[str, np.ndarray],
                   labels: tuple[np.ndarray, np.ndarray] | None = None, t: np.ndarray | None = None) -> np.ndarray:
    """Contour error (N,) of ``actual`` against the programmed path of ``run``, all moving axes.

    ``labels`` (program, line) per sample when ``commanded`` is not the run's own command
    (:func:`block_of_samples`), with its times ``t``.
    """
    axes = list(commanded)
    arcs, of, plane = _arcs(run, axes, labels)
    return path_contour_error(np.column_stack([commanded[a] for a in axes]),
                              np.column_stack([actual[a] for a in axes]), arcs=arcs, arc_of_vertex=of, plane=plane,
                              t=run.t if t is None else t)


def analyse(pred: Prediction) -> PredictionSummary:
    """Tracking and contour errors of a prediction, with the worst places by program line."""
    run, rec = pred.run, pred.recording
    axes = list(rec.axes)
    feed = _feed_moves(run)
    sel = feed if feed.any() else np.ones(rec.n_samples, dtype=bool)
    names = [p["name"] for p in run.programs]

    tracking = {}
    for a, tr in rec.axes.items():
        e = np.where(sel, tr.tracking_error, 0.0)
        k = int(np.argmax(np.abs(e)))
        tracking[a] = AxisErrors(a, float(abs(e[k])), float(np.sqrt(np.mean(tr.tracking_error[sel] ** 2))),
                                 float(rec.t[k]), int(run.line[k]), names[int(run.segment[k])], _block_number(run, k))
    contour = worst = None
    cmax = crms = None
    if len(axes) >= 2:
        contour = contour_of_run(run, {a: rec.axes[a].commanded for a in axes}, {a: rec.axes[a].actual for a in axes})
        c = np.abs(np.where(sel, contour, 0.0))
        cmax, crms = float(c.max()), float(np.sqrt(np.mean(contour[sel] ** 2)))
        worst = _worst_places(run, rec, c, sel, names)
    return PredictionSummary(pred.machine.name, tuple(axes), tracking, contour, feed, cmax, crms,
                             tuple(worst or ()), tuple(pred.warnings) + tuple(_path_mode_warnings(run, pred.machine.planner_limits is not None)), pred,
                             cycle_time_s(run), pred.machine.planner)


def _path_mode_warnings(run: CommandedRun, per_axis: bool) -> list[str]:
    """Blending (G64) the planner does not model: say so."""
    out = []
    for info, blocks in zip(run.programs, run.blocks):
        tol = path_tolerances(blocks.values())
        modes = set(tol.values())
        arcs = any(b.motion in ("G2", "G3") and tol.get(line) != 0.0 for line, b in blocks.items())
        if None in modes or (not per_axis and any(m for m in modes)) or (per_axis and arcs):
            what = ("G64 path blending (modelled with --ini's per-axis planner)" if not per_axis
                    else "G64 without P" if None in modes else "blending into or out of an arc under G64")
            out.append(f"{info['name']}: {what} is not modelled, those blocks are planned to end at rest "
                       f"(G61.1): corners come out sharper and the cycle time longer than the controller's")
    return out


def _block_number(run: CommandedRun, k: int) -> int | None:
    """The N word of the line sample ``k`` runs, if the line has one."""
    block = run.block_at(k)
    return None if block is None else block.n


def _worst_places(run: CommandedRun, rec: Recording, c: np.ndarray, sel: np.ndarray, names: list[str]) -> list[Place]:
    """The largest contour error of each program line, the ``WORST_PLACES`` largest first."""
    key = run.block_key
    # the path speed of the linear axes (a rotary axis's deg/s is not a feed along the path)
    linear = [tr.commanded for a, tr in rec.axes.items() if a not in ROTARY_AXES] or [
        tr.commanded for tr in rec.axes.values()]
    P = np.column_stack(linear)
    speed = np.linalg.norm(np.gradient(P, rec.sample_period, axis=0), axis=1) if len(P) > 1 else np.zeros(len(P))
    order = np.flatnonzero(sel)[np.argsort(-c[sel], kind="stable")]
    places, seen = [], set()
    for k in order:
        if key[k] in seen:
            continue
        seen.add(key[k])
        p = int(run.segment[k])
        places.append(Place(names[p], int(run.line[k]), float(rec.t[k]),
                            {a: float(tr.commanded[k]) for a, tr in rec.axes.items()}, run.feed_at(int(k)), float(c[k]),
                            float(speed[k]), _block_number(run, k)))
        if len(places) == WORST_PLACES:
            break
    return places


def compare(machine: VirtualMachine, recording: Recording, run: CommandedRun | None = None,
            source: str = "recording") -> Comparison:
    """Predicted vs recorded contour error of the same motion.

    The model is driven by the recording's own command, which keeps the two in step
    whatever the controller's planner did; the samples are assigned to ``run``'s blocks by
    :func:`block_of_samples`, so both errors are taken over the same feed moves as a
    prediction's.  With ``run`` (the program as this machine's planner interpolates it)
    the figures of the stand-alone prediction are added: its contour error on its own
    planned command against the measured one, paired at the same point of the path
    (:func:`_standalone`), and both cycle times.  Without ``run`` every moving sample counts.
    """
    axes = [a for a in recording.axes if a in machine.axes]
    if len(axes) < 2:
        raise ValueError("a contour comparison needs two axes the machine and the recording share")
    cmd = {a: recording.axes[a].commanded for a in axes}
    pred = {a: machine.axes[a].simulate(cmd[a], segment=recording.segment) for a in axes}
    act = {a: recording.axes[a].actual for a in axes}
    if run is None:
        P = np.column_stack([cmd[a] for a in axes])
        measured = path_contour_error(P, np.column_stack([act[a] for a in axes]), t=recording.t)
        predicted = path_contour_error(P, np.column_stack([pred[a] for a in axes]), t=recording.t)
        return Comparison(source, recording.t, measured, predicted, _moving(cmd))
    start = {a: float(cmd[a][0]) for a in axes}
    if any(abs(run.commanded[a][0] - start[a]) > END_TOLERANCE_MM for a in axes if a in run.commanded):
        from gcode_gen.interpreter import parse_program

        # the program as planned from where the recording starts
        run = machine.command([parse_program(text, name=p["name"]) for text, p in zip(run.texts, run.programs)],
                              start={**{a: float(x[0]) for a, x in run.commanded.items()}, **start})
    labels = block_of_samples(run, cmd)
    measured = contour_of_run(run, cmd, act, labels, recording.t)
    predicted = contour_of_run(run, cmd, pred, labels, recording.t)
    mask = _feed_moves(run, cmd, labels)
    if not mask.any():
        raise ValueError("its command does not run the program's feed moves (another program, or another start?)")
    standalone = _standalone(machine, run, cmd, measured, mask, labels)
    return Comparison(source, recording.t, measured, predicted, mask,
                      cycle_time_s(run, cmd, labels, recording.sample_period), cycle_time_s(run), standalone)


def _travel(commanded: dict[str, np.ndarray], axes: list[str]) -> np.ndarray:
    """(N,) the command's travel along its path from the first sample, mm (every axis in ``axes``)."""
    X = np.column_stack([commanded[a] for a in axes])
    return np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(X, axis=0), axis=1))))


def _standalone(machine: VirtualMachine, run: CommandedRun, recorded: dict[str, np.ndarray], measured: np.ndarray,
                mask: np.ndarray, labels: tuple[np.ndarray, np.ndarray]) -> dict[str, float] | None:
    """The prediction on the planned command vs ``measured``: max and rms ratios.

    Each measured feed sample is paired with the prediction at the same point of the path:
    block by block, the predicted contour error interpolated at the recorded command's travel
    along the path (:func:`_travel`, from the run's start).  Paired by sample number from
    each block's start instead, the two carry up to a sample of the phase between the
    controller's clock and the plan, which on a blended corner, where the contour error
    changes fastest, moves the rms difference between runs of the same machine.
    """
    axes = list(recorded)
    if any(a not in run.commanded for a in axes):
        return None
    cmd = {a: run.commanded[a] for a in axes}
    sim = {a: machine.axes[a].simulate(cmd[a], segment=run.segment) for a in axes}
    own = contour_of_run(run, cmd, sim)
    # the planned samples assigned to blocks as the recorded ones are (a blended corner's
    # arc splits where it comes nearest the corner)
    own_labels = block_of_samples(run, cmd)
    own_mask = _feed_moves(run, cmd, own_labels)
    s_m, s_p = _travel(recorded, axes), _travel(cmd, axes)
    key_m = labels[0] * 1_000_000 + labels[1]
    key_p = own_labels[0] * 1_000_000 + own_labels[1]
    m_parts, p_parts = [], []
    for key in dict.fromkeys(key_p[own_mask]):
        km = np.flatnonzero(mask & (key_m == key))
        kp = np.flatnonzero(own_mask & (key_p == key))
        if km.size == 0 or kp.size < 2:
            continue
        # travel grows strictly while the command moves (the feed mask): the measured samples
        # inside the predicted block's span of travel are paired, none extrapolated
        inside = km[(s_m[km] >= s_p[kp[0]]) & (s_m[km] <= s_p[kp[-1]])]
        m_parts.append(measured[inside])
        p_parts.append(np.interp(s_m[inside], s_p[kp], own[kp]))
    if not m_parts:
        return None
    m, p = np.concatenate(m_parts), np.concatenate(p_parts)
    if m.size == 0:
        return None
    return {"predicted_max_abs_mm": float(np.max(np.abs(own[own_mask]))),
            "max_ratio": float(np.max(np.abs(own[own_mask])) / np.max(np.abs(measured[mask]))),
            "rms_difference_ratio": float(np.sqrt(np.mean((p - m) ** 2)) / np.sqrt(np.mean(m ** 2))),
            "paired_samples": int(m.size)}


def predict(programs: "list[ProgramLike] | tuple[ProgramLike, ...]", machine: "VirtualMachine | str | Path",
            overrides: "tuple[str, ...] | list[str]" = ()) -> PredictionSummary:
    """Run ``programs`` on ``machine`` (a VirtualMachine or a result JSON path) and analyse them.

    ``overrides`` are ``AXIS.PARAM=VALUE`` assignments (:meth:`VirtualMachine.with_overrides`).
    """
    from ident.virtual_machine import load_virtual_machine

    vm = machine if isinstance(machine, VirtualMachine) else load_virtual_machine(machine)
    if overrides:
        vm = vm.with_overrides(overrides)
    return analyse(vm.run(list(programs)))

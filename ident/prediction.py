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
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from core.recording import Recording
from gcode_gen.commands import CommandedRun, ProgramLike
from ident.contour import path_contour_error
from ident.virtual_machine import Prediction, VirtualMachine

__all__ = ["AxisErrors", "Place", "PredictionSummary", "Comparison", "predict", "analyse", "compare",
           "contour_of_run", "WORST_PLACES"]

#: How many worst places are listed.
WORST_PLACES = 5


@dataclass(frozen=True)
class AxisErrors:
    """Tracking error of one axis over the feed moves, mm."""

    axis: str
    max_abs_mm: float
    rms_mm: float
    at_s: float
    line: int
    program: str

    def to_dict(self) -> dict[str, Any]:
        return {"max_abs_mm": self.max_abs_mm, "rms_mm": self.rms_mm, "at_s": self.at_s,
                "program": self.program, "line": self.line}


@dataclass(frozen=True)
class Place:
    """The largest contour error on one program line."""

    program: str
    line: int
    t_s: float
    position_mm: dict[str, float]
    feed_mm_s: float | None
    contour_error_mm: float

    def to_dict(self) -> dict[str, Any]:
        return {"program": self.program, "line": self.line, "t_s": self.t_s, "position_mm": self.position_mm,
                "feed_mm_s": self.feed_mm_s, "contour_error_mm": self.contour_error_mm}


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

    def to_dict(self) -> dict[str, Any]:
        return {
            "machine": self.machine,
            "axes": list(self.axes),
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
    mask: np.ndarray  # the samples compared (feed moves where known, else moving)

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
                "max_ratio": self.max_ratio, "rms_difference_ratio": self.rms_difference_ratio}


def _arcs(run: CommandedRun, axes: list[str]) -> tuple[list, np.ndarray | None, tuple[int, int]]:
    """Arc geometry per sample of ``run`` for :func:`path_contour_error` (XY arcs only)."""
    if "X" not in axes or "Y" not in axes:
        return [], None, (0, 1)
    plane = (axes.index("X"), axes.index("Y"))
    arcs: list[tuple[np.ndarray, float, float]] = []
    index: dict[tuple[int, int], int] = {}
    for p, blocks in enumerate(run.blocks):
        for line, b in blocks.items():
            if b.motion in ("G2", "G3") and b.center and "X" in b.target and "Y" in b.target:
                c = np.array([b.center["X"], b.center["Y"]])
                r = float(np.hypot(b.target["X"] - c[0], b.target["Y"] - c[1]))
                index[(p, line)] = len(arcs)
                arcs.append((c, r, 1.0 if b.motion == "G3" else -1.0))
    if not arcs:
        return [], None, plane
    of = run.per_sample(lambda p, b: index.get((p, b.line), -1), -1, dtype=np.int64)
    return arcs, of, plane


def _feed_moves(run: CommandedRun) -> np.ndarray:
    """(N,) True where a feed move (G1/G2/G3) is executing."""
    return run.per_sample(lambda p, b: b.motion in ("G1", "G2", "G3"), False, dtype=bool)


def contour_of_run(run: CommandedRun, commanded: dict[str, np.ndarray], actual: dict[str, np.ndarray]) -> np.ndarray:
    """Contour error (N,) of ``actual`` against the programmed path of ``run``, all moving axes."""
    axes = list(commanded)
    arcs, of, plane = _arcs(run, axes)
    return path_contour_error(np.column_stack([commanded[a] for a in axes]),
                              np.column_stack([actual[a] for a in axes]), arcs=arcs, arc_of_vertex=of, plane=plane,
                              t=run.t)


def analyse(pred: Prediction) -> PredictionSummary:
    """Tracking and contour errors of a prediction, with the worst places by program line."""
    run, rec = pred.run, pred.recording
    axes = list(rec.axes)
    feed = _feed_moves(run)
    sel = feed if feed.any() else np.ones(rec.n_samples, dtype=bool)
    names = [p["name"] for p in run.programs]

    def where(k: int) -> tuple[float, int, str]:
        return float(rec.t[k]), int(run.line[k]), names[int(run.segment[k])]

    tracking = {}
    for a, tr in rec.axes.items():
        e = np.where(sel, tr.tracking_error, 0.0)
        k = int(np.argmax(np.abs(e)))
        t, line, prog = where(k)
        tracking[a] = AxisErrors(a, float(abs(e[k])), float(np.sqrt(np.mean(tr.tracking_error[sel] ** 2))), t, line, prog)
    contour = worst = None
    cmax = crms = None
    if len(axes) >= 2:
        contour = contour_of_run(run, {a: rec.axes[a].commanded for a in axes}, {a: rec.axes[a].actual for a in axes})
        c = np.abs(np.where(sel, contour, 0.0))
        cmax, crms = float(c.max()), float(np.sqrt(np.mean(contour[sel] ** 2)))
        worst = _worst_places(run, rec, c, sel, names)
    return PredictionSummary(pred.machine.name, tuple(axes), tracking, contour, feed, cmax, crms,
                             tuple(worst or ()), pred.warnings, pred)


def _worst_places(run: CommandedRun, rec: Recording, c: np.ndarray, sel: np.ndarray, names: list[str]) -> list[Place]:
    """The largest contour error of each program line, the ``WORST_PLACES`` largest first."""
    key = run.block_key
    order = np.flatnonzero(sel)[np.argsort(-c[sel], kind="stable")]
    places, seen = [], set()
    for k in order:
        if key[k] in seen:
            continue
        seen.add(key[k])
        p = int(run.segment[k])
        places.append(Place(names[p], int(run.line[k]), float(rec.t[k]),
                            {a: float(tr.commanded[k]) for a, tr in rec.axes.items()}, run.feed_at(int(k)), float(c[k])))
        if len(places) == WORST_PLACES:
            break
    return places


def compare(machine: VirtualMachine, recording: Recording, run: CommandedRun | None = None,
            source: str = "recording") -> Comparison:
    """Predicted vs recorded contour error, the model driven by the recording's own command.

    Driving the model with the recorded command keeps the two in step whatever the
    controller's interpolator did.  When ``run`` (the program as interpolated on the
    machine) has the same command sample for sample, its arcs and feed moves are used too.
    """
    axes = [a for a in recording.axes if a in machine.axes]
    if len(axes) < 2:
        raise ValueError("a contour comparison needs two axes the machine and the recording share")
    cmd = {a: recording.axes[a].commanded for a in axes}
    pred = {a: machine.axes[a].simulate(cmd[a], segment=recording.segment) for a in axes}
    act = {a: recording.axes[a].actual for a in axes}
    same = run is not None and run.t.size == recording.n_samples and all(
        a in run.commanded and np.allclose(run.commanded[a], cmd[a], atol=1e-9) for a in axes)
    if same:
        measured, predicted = contour_of_run(run, cmd, act), contour_of_run(run, cmd, pred)
        mask = _feed_moves(run)
    else:
        P = np.column_stack([cmd[a] for a in axes])
        measured = path_contour_error(P, np.column_stack([act[a] for a in axes]), t=recording.t)
        predicted = path_contour_error(P, np.column_stack([pred[a] for a in axes]), t=recording.t)
        speed = np.linalg.norm(np.gradient(P, axis=0), axis=1)
        mask = speed > 1e-9
    return Comparison(source, recording.t, measured, predicted, mask)


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

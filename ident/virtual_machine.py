"""The identified drives as a virtual machine: run any part program on them (thesis ch. 1, §4.3.3).

A :class:`VirtualMachine` is the result JSON of ``agent identify --json`` read back: one
:class:`ident.axis_model.AxisModel` per axis (eq. 3.3 plus the effects the diagnosis
accepted) and the interpolator limits the programs are run with.  :meth:`VirtualMachine.run`
interpolates programs with :func:`gcode_gen.commands.command_programs` — the same
interpolator the built-in virtual CNC uses — and predicts each axis's actual position by
:meth:`AxisModel.simulate`, the one model source of every prediction.  The result is a
:class:`Prediction`: the usual :class:`core.Recording` (its "actual" channels are the
prediction; the metadata says so) plus the program line executed at each sample.

The interpolator limits are not identified (a capture sees the commanded positions, not
the control's settings): they default to the built-in virtual CNC's (a_max 2000 mm/s²,
no jerk limit, rapids at 200 mm/s) and can be set in the JSON's ``virtual_machine``
section or per run.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from core.errors import InputError, MachineError
from core.recording import AxisTrace, Recording
from gcode_gen.commands import CommandedRun, ProgramLike, command_programs
from gcode_gen.planner_limits import PlannerLimits
from ident.axis_model import AxisModel
from ident.model_limits import check_runnable

__all__ = ["VirtualMachine", "Prediction", "load_virtual_machine", "check_result_format", "INTERPOLATOR_DEFAULTS",
           "RESULT_FORMATS"]

#: Result formats that carry a ``virtual_model`` per axis.
RESULT_FORMATS = ("rapid-ident-result/2",)

#: Interpolator limits of the built-in virtual CNC, used unless the JSON or the caller sets them.
INTERPOLATOR_DEFAULTS = {"a_max_mm_s2": 2000.0, "j_max_mm_s3": None, "rapid_feed_mm_s": 200.0,
                         "max_feed_mm_s": 200.0}

#: A program may exceed the speed the model was identified at by this factor before a warning.
EXTRAPOLATION_MARGIN = 1.1


@dataclass(frozen=True)
class Prediction:
    """A program run on a virtual machine.

    ``recording`` holds commanded and predicted positions (``AxisTrace.actual`` is the
    prediction); ``run`` the interpolated command with the program line per sample;
    ``warnings`` what the user should know (extrapolation beyond the identified speeds).
    """

    machine: "VirtualMachine"
    run: CommandedRun
    recording: Recording
    warnings: tuple[str, ...] = ()

    @property
    def tracking_error(self) -> dict[str, np.ndarray]:
        """Commanded − predicted actual position per axis, mm."""
        return {a: tr.tracking_error for a, tr in self.recording.axes.items()}


@dataclass(frozen=True)
class VirtualMachine:
    """Identified axes plus the interpolator that feeds them.

    Attributes
    ----------
    name : what the machine is called in reports (the JSON's file name by default).
    axes : axis letter -> AxisModel.
    a_max, j_max, rapid_feed, max_feed : interpolator limits, mm/s², mm/s³ (None: none), mm/s, mm/s.
    identified_range : axis -> {"max_speed_mm_s", "travel_mm"} of the identification recording.
    travel : axis -> (lo, hi) travel limits, mm, where known (a program outside them is refused).
    planner_limits : per-axis limits (LinuxCNC's planner, e.g. from its INI); None: the path
        limits a_max / rapid_feed / max_feed.
    """

    name: str
    axes: Mapping[str, AxisModel]
    a_max: float = INTERPOLATOR_DEFAULTS["a_max_mm_s2"]
    j_max: float | None = None
    rapid_feed: float = INTERPOLATOR_DEFAULTS["rapid_feed_mm_s"]
    max_feed: float = INTERPOLATOR_DEFAULTS["max_feed_mm_s"]
    identified_range: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    travel: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    planner_limits: PlannerLimits | None = None

    def __post_init__(self) -> None:
        if not self.axes:
            raise InputError(f"virtual machine {self.name!r} has no axis")
        periods = {m.sample_period for m in self.axes.values()}
        if len(periods) > 1:
            raise MachineError(f"virtual machine {self.name!r}: axes identified at different sample periods "
                               f"({', '.join(f'{p * 1e3:g} ms' for p in sorted(periods))})")
        for attr in ("a_max", "rapid_feed", "max_feed"):
            v = getattr(self, attr)
            if not (math.isfinite(v) and v > 0):
                raise MachineError(f"virtual machine {self.name!r}: {attr} must be > 0, got {v}")

    @property
    def planner(self) -> dict[str, Any]:
        """Which planner and limits the programs are run with (for the words and the JSON)."""
        if self.planner_limits is not None:
            return {**self.planner_limits.to_dict(), "words": self.planner_limits.describe()}
        return {"kind": "path", "source": "defaults", "a_max_mm_s2": self.a_max, "j_max_mm_s3": self.j_max,
                "rapid_feed_mm_s": self.rapid_feed,
                "words": f"path-limited planner ({self.a_max:g} mm/s² along the path, rapids {self.rapid_feed:g} mm/s; "
                         f"give the controller's limits with --ini)"}

    def with_planner_limits(self, limits: PlannerLimits) -> "VirtualMachine":
        """A copy planning with per-axis ``limits`` (rapids at their path speed cap, which caps feeds too)."""
        return replace(self, planner_limits=limits, rapid_feed=limits.max_linear_velocity or self.rapid_feed)

    @property
    def Ts(self) -> float:
        return next(iter(self.axes.values())).sample_period

    # -- building -----------------------------------------------------------------------
    @classmethod
    def from_result(cls, doc: Mapping[str, Any], name: str = "identified machine") -> "VirtualMachine":
        """From the parsed result JSON (:meth:`ident.IdentifyResult.to_dict`)."""
        check_result_format(doc, name)
        axes: dict[str, AxisModel] = {}
        ranges: dict[str, Any] = {}
        for axis, r in dict(doc.get("axes") or {}).items():
            vm = r.get("virtual_model") if isinstance(r, Mapping) else None
            if vm is None:
                raise InputError(f"{name}: axis {axis} has no virtual_model")
            try:
                axes[str(axis)] = AxisModel.from_dict(vm)
            except InputError as exc:
                raise InputError(f"{name}: axis {axis}: {exc}") from None
            if vm.get("identified_range"):
                ranges[str(axis)] = dict(vm["identified_range"])
        section = dict(doc.get("virtual_machine") or {})
        lim = {**INTERPOLATOR_DEFAULTS, **{k: v for k, v in section.items() if k in INTERPOLATOR_DEFAULTS}}
        travel = {str(a): (float(lo), float(hi)) for a, (lo, hi) in dict(section.get("travel_mm") or {}).items()}
        vm = cls(name=name, axes=axes, a_max=float(lim["a_max_mm_s2"]),
                 j_max=None if lim["j_max_mm_s3"] in (None, 0) else float(lim["j_max_mm_s3"]),
                 rapid_feed=float(lim["rapid_feed_mm_s"]), max_feed=float(lim["max_feed_mm_s"]),
                 identified_range=ranges, travel=travel)
        if section.get("axis_limits"):
            try:
                per_axis = {str(a): (float(v["max_velocity_mm_s"]), float(v["max_acceleration_mm_s2"]))
                            for a, v in dict(section["axis_limits"]).items()}
            except (KeyError, TypeError, ValueError):
                raise InputError(f"{name}: virtual_machine.axis_limits: per axis "
                                 f"{{max_velocity_mm_s, max_acceleration_mm_s2}}") from None
            vm = vm.with_planner_limits(PlannerLimits(per_axis, None, f"{name} virtual_machine.axis_limits"))
        return vm

    def with_overrides(self, assignments: Sequence[str]) -> "VirtualMachine":
        """A copy with ``AXIS.PARAM=VALUE`` assignments applied (``X.a1=120``, ``Y.backlash.gap_mm=0.01``).

        The thesis's use of the virtual machine: change a gain, run the program again, compare.
        """
        axes = dict(self.axes)
        for text in assignments:
            lhs, eq, rhs = text.partition("=")
            axis, dot, param = lhs.strip().partition(".")
            if not eq or not dot or not param:
                raise InputError(f"{text!r}: expected AXIS.PARAM=VALUE, e.g. X.a1=120")
            if axis not in axes:
                raise InputError(f"{text!r}: {self.name} has no axis {axis} (axes: {', '.join(axes)})")
            try:
                value = float(rhs)
            except ValueError:
                raise InputError(f"{text!r}: {rhs.strip()!r} is not a number") from None
            try:
                axes[axis] = axes[axis].with_parameter(param.strip(), value)
            except InputError as exc:
                raise InputError(f"{text!r}: {exc}") from None
            check_runnable(axes[axis].model, self.Ts, f"{text!r}")
        suffix = " with " + ", ".join(assignments) if assignments else ""
        return replace(self, axes=axes, name=self.name + suffix)

    # -- running ------------------------------------------------------------------------
    def command(self, programs: Sequence[ProgramLike], start: Mapping[str, float] | None = None) -> CommandedRun:
        """The interpolated command of ``programs`` on this machine's axes and limits, from
        ``start`` (axis -> mm; default every axis at 0)."""
        run = command_programs(programs, list(self.axes), Ts=self.Ts, a_max=self.a_max, j_max=self.j_max,
                               start=dict(start or {}),
                               rapid_feed=self.rapid_feed, machine_name=self.name,
                               axis_limits=self.planner_limits.axes if self.planner_limits else None)
        self._check_limits(run)
        return run

    def run(self, programs: Sequence[ProgramLike], start: Mapping[str, float] | None = None) -> Prediction:
        """Run ``programs`` in order from ``start`` and predict every moved axis (free run from the command,
        each program from rest on its first point: :meth:`AxisModel.simulate` with no ``x0``)."""
        run = self.command(programs, start)
        axes = {a: AxisTrace(x, self.axes[a].simulate(x, segment=run.segment)) for a, x in run.commanded.items()}
        rec = Recording(
            t=run.t, axes=axes, sample_period=run.Ts, segment=run.segment,
            metadata={
                "transport": "prediction",
                "controller": f"rapid-ident virtual machine {self.name}",
                "machine": self.name,
                "actual_is": "predicted by the identified drive models (not measured)",
                "programs": [dict(p) for p in run.programs],
                "models": {a: m.to_dict() for a, m in self.axes.items() if a in axes},
            },
        )
        return Prediction(self, run, rec, tuple(self._extrapolation_warnings(run)))

    def _check_limits(self, run: CommandedRun) -> None:
        for p, blocks in enumerate(run.blocks):
            for line, b in sorted(blocks.items()):
                # (LinuxCNC's planner lowers a feed above its limits to them, as the controller does)
                if (self.planner_limits is None and b.motion != "G0" and b.feed is not None
                        and b.feed > self.max_feed * (1 + 1e-9)):
                    raise MachineError(f"{run.programs[p]['name']}:{line}: feed {b.feed:g} mm/s is above "
                                       f"{self.name}'s maximum feed {self.max_feed:g} mm/s")
        for axis, (lo, hi) in self.travel.items():
            x = run.commanded.get(axis)
            if x is None:
                continue
            k = int(np.argmax((x < lo - 1e-9) | (x > hi + 1e-9)))
            if x[k] < lo - 1e-9 or x[k] > hi + 1e-9:
                raise MachineError(f"{run.programs[int(run.segment[k])]['name']}:{int(run.line[k])}: axis {axis} "
                                   f"goes to {x[k]:+.3f} mm, outside {self.name}'s travel {lo:+g} … {hi:+g} mm")

    def _extrapolation_warnings(self, run: CommandedRun) -> list[str]:
        out = []
        for axis, x in run.commanded.items():
            vmax = (self.identified_range.get(axis) or {}).get("max_speed_mm_s")
            if not vmax:
                continue
            v = float(np.max(np.abs(np.diff(x)))) / run.Ts if x.size > 1 else 0.0
            if v > EXTRAPOLATION_MARGIN * vmax:
                out.append(f"axis {axis} reaches {v:.0f} mm/s; the model was identified up to {vmax:.0f} mm/s, "
                           f"so faster motion is extrapolated")
        return out


def _version(fmt: str) -> int:
    tail = fmt.rpartition("/")[2]
    return int(tail) if tail.isdigit() else 0


def check_result_format(doc: Any, name: str) -> None:
    """One-line InputError unless ``doc`` is a result JSON this version reads (:data:`RESULT_FORMATS`):
    another tool's JSON is "not a rapid-ident result", an older rapid-ident's says to identify again."""
    fmt = doc.get("format") if isinstance(doc, Mapping) else None
    if fmt in RESULT_FORMATS:
        return
    axes = doc.get("axes") if isinstance(doc, Mapping) else None
    ours = isinstance(fmt, str) and fmt.startswith("rapid-ident-result/")
    unversioned = (fmt is None and isinstance(axes, Mapping) and axes
                   and all(isinstance(r, Mapping) and isinstance(r.get("model"), Mapping) and "a1" in r["model"]
                           for r in axes.values()))
    if ours or unversioned:
        newer = ours and _version(fmt) > _version(RESULT_FORMATS[-1])
        raise InputError(f"{name}: written by {'a newer' if newer else 'an older'} rapid-ident (format "
                         f"{fmt or 'unversioned'}, this one reads {RESULT_FORMATS[-1]}); run agent identify again")
    what = (f"format {fmt!r}" if fmt is not None else
            "no 'format' field" if isinstance(doc, Mapping) else f"a JSON {type(doc).__name__}")
    raise InputError(f"{name}: not a rapid-ident result ({what}); give the JSON agent identify --json wrote")


def load_virtual_machine(path: str | Path) -> VirtualMachine:
    """The virtual machine of a result JSON written by ``agent identify --json``."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"{path}: not a result JSON ({str(exc).splitlines()[0]})") from None
    return VirtualMachine.from_result(doc, name=path.name)

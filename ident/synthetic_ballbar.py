"""The synthetic ballbar: the ISO 230-4 circular test run on the identified drives.

:func:`run_ballbar` writes the test's two programs (a full circle of radius R at feed v,
counter-clockwise and clockwise, started at 45° so the four axis reversals fall in steady
motion; :func:`gcode_gen.circle`), runs them on a :class:`VirtualMachine`, and reads the
predicted paths as a QC20 user reads a ballbar plot (:mod:`ident.ballbar`).  Two readings
come from the model itself rather than from the plot:

* **servo mismatch from the transfer functions**: each axis lags its command at the
  circle's frequency ω = v/R by τ = −arg G(jω)/ω (G the tracking transfer function of
  eq. 3.3) plus its preview shift and any accepted dead time; Δτ = τ_X − τ_Y is what the
  ellipse of the plot measures.
* **what causes the reversal features**: the circle is run again with each axis's
  friction (d0, d1 and any Stribeck curve) and then its backlash removed; how much of a
  reversal spike or step disappears is how much that term causes.

With recordings of the same test (``against``) the measured plot is read the same way
and overlaid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np

from core.errors import InputError
from core.recording import Recording
from gcode_gen.toolpaths import circle
from ident.axis_model import AxisModel
from ident.ballbar import BallbarResult, BallbarRun, analyse_ballbar, ballbar_run, words
from ident.virtual_machine import VirtualMachine

__all__ = ["SyntheticBallbar", "run_ballbar", "ballbar_of_recording", "axis_lag_s", "START_DEG",
           "DEFAULT_RADIUS_MM", "DEFAULT_FEED_MM_S"]

#: Start (and end) angle of the test circles: between the reversals at 0°, 90°, 180°, 270°.
START_DEG = 45.0
#: A QC20's standard bar is 100 mm long; 1000 mm/min is the usual test feed.
DEFAULT_RADIUS_MM = 100.0
DEFAULT_FEED_MM_S = 1000.0 / 60.0


@dataclass(frozen=True)
class SyntheticBallbar:
    """A ballbar test on one virtual machine, at one radius and feed.

    ``result`` reads the predicted plot; ``model_servo_mismatch_ms`` is Δτ from the axes'
    transfer functions; ``causes`` per axis the reversal spike and step (µm) with the
    model as identified, without its friction and without its backlash; ``measured``
    reads the recorded test when given.
    """

    machine: str
    radius: float
    feed: float
    result: BallbarResult
    model_servo_mismatch_ms: float
    causes: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)
    measured: BallbarResult | None = None

    def words(self) -> list[str]:
        out = words(self.result)
        out.append(f"servo mismatch from the axes' transfer functions at {self.feed / self.radius / (2 * math.pi):.3g} Hz: "
                   f"{self.model_servo_mismatch_ms:+.2f} ms (the plot reads {self.result.servo_mismatch_ms:+.2f} ms)")
        t = self.result.threshold_um
        for axis, c in self.causes.items():
            full = c["model"]
            if full["spike_um"] < t and abs(full["step_um"]) < t:
                continue
            parts = []
            for term, key in (("friction", "without_friction"), ("backlash", "without_backlash")):
                if key in c:
                    parts.append(f"{term} {full['spike_um'] - c[key]['spike_um']:+.1f} µm spike, "
                                 f"{full['step_um'] - c[key]['step_um']:+.1f} µm step")
            out.append(f"{axis} reversals ({full['spike_um']:.1f} µm spike, {full['step_um']:+.1f} µm step) "
                       f"caused by: " + "; ".join(parts))
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"machine": self.machine, "radius_mm": self.radius, "feed_mm_s": self.feed,
                "predicted": self.result.to_dict(), "model_servo_mismatch_ms": self.model_servo_mismatch_ms,
                "causes": self.causes, "measured": self.measured.to_dict() if self.measured else None,
                "words": self.words()}


def axis_lag_s(model: AxisModel, f_hz: float) -> float:
    """Lag (s) of one axis behind its command at ``f_hz``: −arg G(j2πf)/(2πf), preview shift and dead time."""
    H, _ = model.model.freqresp(np.array([f_hz]))
    lag = -float(np.angle(H[0])) / (2 * math.pi * f_hz)
    lag -= model.shift * model.sample_period
    lag += float((model.effects.get("time_delay") or {}).get("delay_s", 0.0))
    return lag


def _runs(machine: VirtualMachine, axes: tuple[str, str], radius: float, feed: float,
          centre: tuple[float, float]) -> list[BallbarRun]:
    runs = []
    for direction in ("ccw", "cw"):
        tp = circle(size=2 * radius, feed=feed, center=centre, axes=axes, direction=direction,
                    start_deg=START_DEG, name=f"ballbar_{direction}")
        pred = machine.run([tp])
        arc = np.flatnonzero(pred.run.line == max(pred.run.blocks[0]))  # the circle is the last block
        rec = pred.recording
        x, y = rec.axes[axes[0]], rec.axes[axes[1]]
        runs.append(ballbar_run(x.actual[arc], y.actual[arc], centre=centre, radius=radius, feed=feed,
                                direction=direction, xc=x.commanded[arc], yc=y.commanded[arc], dt=rec.sample_period))
    return runs


def _reversals(result: BallbarResult) -> dict[str, dict[str, float]]:
    return {a.axis: {"spike_um": float(a.spike_um), "step_um": float(a.step_um)} for a in result.axis_reversals}


def _without(model: AxisModel, term: str) -> AxisModel | None:
    if term == "friction":
        effects = {e: p for e, p in model.effects.items() if e != "stribeck"}
        return replace(model, model=replace(model.model, d0=0.0, d1=0.0), effects=effects)
    if term == "backlash" and "backlash" in model.effects:
        effects = {e: p for e, p in model.effects.items() if e != "backlash"}
        return replace(model, effects=effects)
    return None


def run_ballbar(machine: VirtualMachine, *, radius: float = DEFAULT_RADIUS_MM, feed: float = DEFAULT_FEED_MM_S,
                axes: tuple[str, str] = ("X", "Y"), centre: tuple[float, float] = (0.0, 0.0),
                against: Sequence[Recording] = ()) -> SyntheticBallbar:
    """The ballbar test of ``machine`` in the plane of ``axes`` (see the module docstring)."""
    axes = tuple(axes)
    missing = [a for a in axes if a not in machine.axes]
    if len(axes) != 2 or missing:
        raise InputError.about("axes", f"a ballbar test needs two axes of {machine.name} "
                                       f"(it has {', '.join(machine.axes)}), got {', '.join(axes)}")
    if not (radius > 0 and feed > 0):
        raise InputError(f"radius {radius} mm and feed {feed} mm/s must be positive")
    result = analyse_ballbar(_runs(machine, axes, radius, feed, centre), axes)
    f_hz = feed / (2 * math.pi * radius)
    model_dtau = 1e3 * (axis_lag_s(machine.axes[axes[0]], f_hz) - axis_lag_s(machine.axes[axes[1]], f_hz))
    causes: dict[str, dict[str, dict[str, float]]] = {a: {"model": v} for a, v in _reversals(result).items()}
    for axis in axes:
        for term in ("friction", "backlash"):
            changed = _without(machine.axes[axis], term)
            if changed is None:
                continue
            variant = replace(machine, axes={**machine.axes, axis: changed})
            causes[axis][f"without_{term}"] = _reversals(analyse_ballbar(_runs(variant, axes, radius, feed, centre),
                                                                         axes))[axis]
    measured = ballbar_of_recording(against, axes, radius, feed, centre) if against else None
    return SyntheticBallbar(machine.name, radius, feed, result, model_dtau, causes, measured)


def ballbar_of_recording(recordings: Sequence[Recording], axes: tuple[str, str], radius: float, feed: float,
                         centre: tuple[float, float] = (0.0, 0.0)) -> BallbarResult:
    """Read recorded ballbar circles (one recording per direction) as :func:`run_ballbar` reads its own.

    The circle is the part of each recording whose command lies on the nominal circle
    (within 0.1 % of R) at the feed; its direction is the sense the command travels.
    """
    runs = []
    for rec in recordings:
        if any(a not in rec.axes for a in axes):
            raise InputError.about("against", f"a recorded ballbar circle needs axes {', '.join(axes)}, "
                                              f"the recording has {', '.join(rec.axes)}")
        xc, yc = rec.axes[axes[0]].commanded, rec.axes[axes[1]].commanded
        on = np.abs(np.hypot(xc - centre[0], yc - centre[1]) - radius) <= 1e-3 * radius
        k = np.flatnonzero(on)
        if k.size < 100:
            raise InputError.about("against", f"the recording has no circle of radius {radius:g} mm about "
                                              f"{centre[0]:g}, {centre[1]:g} in {', '.join(axes)}")
        k = np.arange(k[0], k[-1] + 1)
        ang = np.unwrap(np.arctan2(yc[k] - centre[1], xc[k] - centre[0]))
        direction = "ccw" if ang[-1] > ang[0] else "cw"
        x, y = rec.axes[axes[0]].actual[k], rec.axes[axes[1]].actual[k]
        runs.append(ballbar_run(x, y, centre=centre, radius=radius, feed=feed, direction=direction,
                                xc=xc[k], yc=yc[k], dt=rec.sample_period))
    return analyse_ballbar(runs, axes)

"""The synthetic ballbar: the ISO 230-4 circular test run on the identified drives.

:func:`run_ballbar` runs the test as it is run on the machine, one program
(:func:`ballbar_program`): to the start, a dwell, then counter-clockwise a feed-in arc of
``lead_deg`` (default 180°), the 360° data arc from 45° (so the four axis reversals fall
in steady motion) and a feed-out arc of ``lead_deg``; a dwell; then the same clockwise,
back over the same arcs.  The model runs the whole program in one go, so the clockwise
test starts from the state the counter-clockwise one left (the pid integrator's, a gap's
side), as on the machine.  **Initial state assumed**: the axes at rest on the start point
with the loop at its equilibrium there (integrator empty, as after the machine is switched
on: the model's integral holds only what standing there needs, so the test reads as the
written program run from anywhere), the contact at the gap's centre.  The predicted data arcs are read as a QC20 user reads a
ballbar plot (:mod:`ident.ballbar`).  Two readings come from the model itself rather than
from the plot:

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
from gcode_gen.commands import CommandedRun
from gcode_gen.program import ARC_ORDER, ARC_PLANES, Block, Toolpath
from ident.axis_model import AxisModel
from ident.ballbar import BallbarResult, BallbarRun, analyse_ballbar, ballbar_run, check_test_size, words
from ident.virtual_machine import VirtualMachine

__all__ = ["SyntheticBallbar", "run_ballbar", "ballbar_of_recording", "ballbar_program", "axis_lag_s", "START_DEG",
           "start_point", "data_arc_lines",
           "DEFAULT_RADIUS_MM", "DEFAULT_FEED_MM_S", "LEAD_DEG", "DWELL_S"]

#: Start (and end) angle of the test circles: between the reversals at 0°, 90°, 180°, 270°.
START_DEG = 45.0
#: A QC20's standard bar is 100 mm long; 1000 mm/min is the usual test feed.
DEFAULT_RADIUS_MM = 100.0
DEFAULT_FEED_MM_S = 1000.0 / 60.0
#: Feed-in and feed-out arcs either side of each data arc, degrees.
LEAD_DEG = 180.0
#: Dwell before each direction, s (as the validation contours).
DWELL_S = 0.2
#: The state the synthetic test starts from (module docstring).
INITIAL_STATE = ("at rest on the start point, the loop at its equilibrium there (integrator empty, as after the "
                 "machine is switched on); the cw test starts from the state the ccw one left")


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
    lead_deg: float = LEAD_DEG
    planner: dict[str, Any] = field(default_factory=dict)

    def words(self) -> list[str]:
        """The plot read as a QC20 user reads it, each reversal step named by its cause in the
        model (the step with friction or backlash removed, :attr:`causes`), then the causes."""
        out = [self._step_cause(w) for w in words(self.result)]
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

    def _step_cause(self, w: str) -> str:
        if not w.startswith("reversal step on "):
            return w
        axis = w.split()[3]
        c = self.causes.get(axis, {})
        full = c.get("model", {}).get("step_um", 0.0)
        parts = {term: full - c[f"without_{term}"]["step_um"] for term in ("friction", "backlash")
                 if f"without_{term}" in c}
        if not parts:
            return w
        cause = max(parts, key=lambda k: abs(parts[k]))
        named = {"friction": "friction" if "backlash" in parts else "friction, not backlash (the model has none)",
                 "backlash": "backlash"}[cause]
        return w[:w.index(" (lost motion")] + f", caused by {named}"

    def to_dict(self) -> dict[str, Any]:
        return {"machine": self.machine, "radius_mm": self.radius, "feed_mm_s": self.feed,
                "predicted": self.result.to_dict(), "model_servo_mismatch_ms": self.model_servo_mismatch_ms,
                "causes": self.causes, "measured": self.measured.to_dict() if self.measured else None,
                "lead_deg": self.lead_deg, "initial_state": INITIAL_STATE, "planner": self.planner,
                "words": self.words()}


def axis_lag_s(model: AxisModel, f_hz: float) -> float:
    """Lag (s) of one axis behind its command at ``f_hz``: −arg G(j2πf)/(2πf), preview shift and dead time."""
    H, _ = model.model.freqresp(np.array([f_hz]))
    lag = -float(np.angle(H[0])) / (2 * math.pi * f_hz)
    lag -= model.shift * model.sample_period
    lag += float((model.effects.get("time_delay") or {}).get("delay_s", 0.0))
    return lag


def ballbar_program(radius: float = DEFAULT_RADIUS_MM, feed: float = DEFAULT_FEED_MM_S,
                    centre: tuple[float, float] = (0.0, 0.0), axes: tuple[str, str] = ("X", "Y"),
                    lead_deg: float = LEAD_DEG, start_deg: float = START_DEG, decimals: int = 4) -> Toolpath:
    """The ballbar test as one program: ccw feed-in, data and feed-out arcs, a dwell, then cw back over them.

    ccw and cw are senses in the plane of ``axes`` as given (from the first axis towards the
    second): in the XZ plane (G18, whose arcs turn from Z towards X) ccw of ``("X", "Z")``
    is G2."""
    if not (0.0 <= lead_deg <= 360.0):
        raise InputError(f"feed-in/out arc {lead_deg}° must be within 0 … 360°")
    a, b = axes
    plane = ARC_PLANES.get(frozenset(axes))
    if plane is None:
        raise InputError.about("axes", f"a ballbar circle lies in the XY, XZ or YZ plane (G17, G18, G19 arcs); "
                                       f"got {a},{b}")
    ccw = "G3" if (a, b) == ARC_ORDER[plane] else "G2"
    cw = "G2" if ccw == "G3" else "G3"
    cx, cy = (round(float(c), decimals) for c in centre)

    def at(deg: float) -> dict[str, float]:
        phi = math.radians(deg)
        return {a: round(cx + radius * math.cos(phi), decimals), b: round(cy + radius * math.sin(phi), decimals)}

    def arc(motion: str, deg: float) -> Block:
        return Block(line=0, n=None, motion=motion, target=at(deg), feed=float(feed), center={a: cx, b: cy},
                     plane=plane)

    dwell = Block(line=0, n=None, motion="G4", dwell_s=DWELL_S)
    blocks = [Block(line=0, n=None, motion="G0", target=at(start_deg - lead_deg)), dwell]
    for motion, sign in ((ccw, 1.0), (cw, -1.0)):
        blocks += [arc(motion, start_deg)] if lead_deg > 0 else []  # feed-in
        blocks += [arc(motion, start_deg)]  # the data arc: a full circle
        blocks += [arc(motion, start_deg + sign * lead_deg)] if lead_deg > 0 else []  # feed-out
        if motion == ccw:
            blocks.append(dwell)
    header = {"program": "ballbar test", "toolpath": "ballbar", "axes": ",".join(axes), "radius": f"{radius:g}",
              "center": f"{cx:g},{cy:g}", "feed": f"{feed:g}", "feed_units": "mm/s", "start_deg": f"{start_deg:g}",
              "lead_deg": f"{lead_deg:g}", "dwell_s": f"{DWELL_S:g}"}
    return Toolpath(name="ballbar", blocks=tuple(blocks), decimals=decimals, header=header)


def _runs(machine: VirtualMachine, axes: tuple[str, str], radius: float, feed: float,
          centre: tuple[float, float], lead_deg: float = LEAD_DEG) -> list[BallbarRun]:
    pred = machine.run([ballbar_program(radius, feed, centre, axes, lead_deg)],
                       start=dict(zip(axes, start_point(radius, centre, lead_deg))))
    data = data_arc_lines(pred.run, lead_deg)
    rec = pred.recording
    x, y = rec.axes[axes[0]], rec.axes[axes[1]]
    runs = []
    for direction, line in zip(("ccw", "cw"), data):
        k = np.flatnonzero(pred.run.line == line)
        runs.append(ballbar_run(x.actual[k], y.actual[k], centre=centre, radius=radius, feed=feed,
                                direction=direction, xc=x.commanded[k], yc=y.commanded[k], dt=rec.sample_period))
    return runs


def data_arc_lines(run: CommandedRun, lead_deg: float) -> tuple[int, int]:
    """The program lines of the ccw and cw data arcs of :func:`ballbar_program` in ``run``."""
    arcs = [line for line, b in sorted(run.blocks[0].items()) if b.motion in ("G2", "G3")]
    return (arcs[1], arcs[4]) if lead_deg > 0 else (arcs[0], arcs[1])


def start_point(radius: float, centre: tuple[float, float], lead_deg: float) -> tuple[float, float]:
    """Where the test starts: on the feed-in arc's start, so the positioning move costs nothing."""
    phi = math.radians(START_DEG - lead_deg)
    return round(centre[0] + radius * math.cos(phi), 4), round(centre[1] + radius * math.sin(phi), 4)


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
                against: Sequence[Recording] = (), lead_deg: float = LEAD_DEG) -> SyntheticBallbar:
    """The ballbar test of ``machine`` in the plane of ``axes`` (see the module docstring)."""
    axes = tuple(axes)
    missing = [a for a in axes if a not in machine.axes]
    if len(axes) != 2 or missing:
        raise InputError.about("axes", f"a ballbar test needs two axes of {machine.name} "
                                       f"(it has {', '.join(machine.axes)}), got {', '.join(axes)}")
    check_test_size(radius, feed)
    result = analyse_ballbar(_runs(machine, axes, radius, feed, centre, lead_deg), axes)
    f_hz = feed / (2 * math.pi * radius)
    model_dtau = 1e3 * (axis_lag_s(machine.axes[axes[0]], f_hz) - axis_lag_s(machine.axes[axes[1]], f_hz))
    causes: dict[str, dict[str, dict[str, float]]] = {a: {"model": v} for a, v in _reversals(result).items()}
    for axis in axes:
        for term in ("friction", "backlash"):
            changed = _without(machine.axes[axis], term)
            if changed is None:
                continue
            variant = replace(machine, axes={**machine.axes, axis: changed})
            causes[axis][f"without_{term}"] = _reversals(analyse_ballbar(
                _runs(variant, axes, radius, feed, centre, lead_deg), axes))[axis]
    measured = ballbar_of_recording(against, axes, radius, feed, centre) if against else None
    return SyntheticBallbar(machine.name, radius, feed, result, model_dtau, causes, measured, lead_deg, machine.planner)


def ballbar_of_recording(recordings: Sequence[Recording], axes: tuple[str, str], radius: float, feed: float,
                         centre: tuple[float, float] = (0.0, 0.0)) -> BallbarResult:
    """Read recorded ballbar circles as :func:`run_ballbar` reads its own.

    A recording holds one direction or the whole test (:func:`ballbar_program`: ccw then
    cw).  The circle is where the command lies on the nominal circle (within 0.1 % of R)
    and moves; each stretch of it travelling one way is one direction's run, and of a run
    longer than a turn the turn in its middle is the data arc (the feed-in and feed-out
    arcs are equal).
    """
    runs = []
    for rec in recordings:
        if any(a not in rec.axes for a in axes):
            raise InputError.about("against", f"a recorded ballbar circle needs axes {', '.join(axes)}, "
                                              f"the recording has {', '.join(rec.axes)}")
        xc, yc = rec.axes[axes[0]].commanded, rec.axes[axes[1]].commanded
        on = np.abs(np.hypot(xc - centre[0], yc - centre[1]) - radius) <= 1e-3 * radius
        ang = np.unwrap(np.arctan2(yc - centre[1], xc - centre[0]))
        sense = np.sign(np.diff(ang, prepend=ang[0])) * on
        found = 0
        for s, direction in ((1.0, "ccw"), (-1.0, "cw")):
            k = np.flatnonzero(sense == s)
            if k.size < 100:
                continue
            # the longest stretch travelling this way (a step of the command elsewhere, e.g. when
            # the machine is switched on, is not part of it); exact stops between arcs are short
            parts = np.split(k, np.flatnonzero(np.diff(k) > 50) + 1)
            k = max(parts, key=lambda q: abs(ang[q[-1]] - ang[q[0]]))
            k = np.arange(k[0], k[-1] + 1)
            turn = np.abs(ang[k] - ang[k[0]])
            if turn[-1] > 2 * np.pi + 1e-6:  # feed-in and feed-out arcs: the middle turn
                mid = 0.5 * turn[-1]
                k = k[(turn >= mid - np.pi) & (turn <= mid + np.pi)]
            x, y = rec.axes[axes[0]].actual[k], rec.axes[axes[1]].actual[k]
            runs.append(ballbar_run(x, y, centre=centre, radius=radius, feed=feed, direction=direction,
                                    xc=xc[k], yc=yc[k], dt=rec.sample_period))
            found += 1
        if not found:
            raise InputError.about("against", f"the recording has no circle of radius {radius:g} mm about "
                                              f"{centre[0]:g}, {centre[1]:g} in {', '.join(axes)}")
    return analyse_ballbar(runs, axes)

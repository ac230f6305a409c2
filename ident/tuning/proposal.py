"""``tune``: from an identified machine and its controller to proposed gains (issue 42).

1. per axis, the plant from the identified model and the current gains (:mod:`.plant`),
   fitted to the recording when it is given (:mod:`.plant_fit`);
2. the current tuning's predicted figure and margins;
3. the search over matched pole placements (:mod:`.optimise`) scored by the predicted
   figure of the test (:mod:`.figures`), or the user's own proposal (``proposed``), which
   is checked against the margins and refused with one line when it violates one;
4. compensation the controller has: LinuxCNC BACKLASH from an accepted gap (FF1/FF2 are
   part of every design).

Deterministic: fixed grids, a fixed excitation, no clock, no random numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from core.errors import InputError
from core.recording import Recording
from ident.tuning.controllers import Gains
from ident.tuning.figures import Criterion, predicted_figure
from ident.tuning.margins import Margins
from ident.tuning.optimise import Design, search, violations
from ident.tuning.plant import Plant, derive_plant
from ident.virtual_machine import VirtualMachine

__all__ = ["Tuning", "tune", "TuningRefused"]


class TuningRefused(InputError):
    """A proposal violates a margin, or no design keeps them all."""


@dataclass(frozen=True)
class Tuning:
    """What ``agent tune`` prints and writes (docs/tuning.md, "Output")."""

    test: str
    plants: dict[str, Plant]
    before: dict[str, Gains]
    after: dict[str, Gains]
    margins_before: dict[str, tuple[Margins, float]]
    margins_after: dict[str, tuple[Margins, float]]
    predicted_before: float
    predicted_after: float
    lag_ms: dict[str, float]
    design: Design | None = None
    notes: tuple[str, ...] = field(default=())

    def to_dict(self) -> dict[str, Any]:
        unit = self.test
        return {
            "format": "rapid-ident-tuning/1",
            "gains": {a: {"before": self.before[a].to_dict(), "after": self.after[a].to_dict()} for a in self.before},
            "plant": {a: p.to_dict() for a, p in self.plants.items()},
            "margins": {a: {"before": {**self.margins_before[a][0].to_dict(), "step_overshoot": _f(self.margins_before[a][1])},
                            "after": {**self.margins_after[a][0].to_dict(), "step_overshoot": _f(self.margins_after[a][1])}}
                        for a in self.before},
            "predicted_before": {unit: self.predicted_before},
            "predicted_after": {unit: self.predicted_after},
            "lag_at_test_feed_ms": self.lag_ms,
            "design": None if self.design is None else self.design.__dict__,
            "notes": list(self.notes),
        }


def _f(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


#: Axes whose lags at the test feed differ by at most this are matched (ms): 1 µm of
#: servo-mismatch ellipse at 1000 mm/min (½·v·Δτ).
MATCHED_LAG_MS = 0.12


def _test_hz(test: Criterion) -> float:
    """The frequency the lags are compared at: the ballbar's circle, or the default ballbar's (R 100, 1000 mm/min)."""
    if test.kind == "ballbar":
        return test.feed / (2 * math.pi * test.radius)
    return 1000.0 / 60.0 / (2 * math.pi * 100.0)


def _lag_ms(gains: Gains, plant: Plant, Ts: float, f_hz: float) -> float:
    """Lag behind the command of a sine at ``f_hz``, ms, measured on the sampled loop (linear, no friction)."""
    from ident.tuning.figures import follow
    from gcode_gen.commands import CommandedRun

    n = int(round(3.0 / (f_hz * Ts)))
    t = np.arange(n) * Ts
    xr = np.sin(2 * math.pi * f_hz * t)
    run = CommandedRun(t=t, commanded={"A": xr}, segment=np.zeros(n, np.int64), line=np.zeros(n, np.int64),
                       Ts=Ts, programs=({"name": "sine", "sha256": ""},), blocks=({},))
    lin = Plant(plant.kj, plant.bj, 0.0, 0.0, plant.gap_mm, plant.delay_s, plant.integration)
    x = follow(run, {"A": gains}, {"A": lin}, ["A"])[0]["A"]
    k = t >= 1.0 / f_hz  # one period to settle
    c = np.column_stack([np.sin(2 * math.pi * f_hz * t[k]), np.cos(2 * math.pi * f_hz * t[k])])
    s, co = np.linalg.lstsq(c, x[k], rcond=None)[0]
    return -1e3 * math.atan2(co, s) / (2 * math.pi * f_hz)


def tune(vm: VirtualMachine, gains: Mapping[str, Gains], test: Criterion,
         proposed: Mapping[str, Gains] | None = None, integration: str = "continuous",
         recording: Recording | None = None) -> Tuning:
    """Propose (or check ``proposed``) gains for the axes of ``test`` on ``vm`` (module docstring).

    ``integration``: how the drives move between samples (:class:`ident.tuning.plant.Plant`);
    "euler" only for the headless LinuxCNC test machine.  ``recording``: the capture ``vm``
    was identified from; the plants are then fitted to it (:mod:`.plant_fit`) rather than
    to the identified models.

    Raises TuningRefused (one line) when the proposal violates a margin or nothing keeps them.
    """
    Ts = vm.Ts
    axes = list(test.axes)
    missing = [a for a in axes if a not in gains]
    if missing:
        raise InputError.about("controller", f"no controller gains for axis {missing[0]}")
    plants = {a: derive_plant(vm.axes[a], gains[a], a, integration, recording) for a in axes}
    res = {a: _resonance(vm, a) for a in axes}
    before = {a: gains[a] for a in axes}
    m_before = {a: violations(before[a], plants[a], Ts, res[a])[:2] for a in axes}
    fig_before, u_before = predicted_figure(test, before, plants)
    design = None
    notes: list[str] = []
    if proposed is not None:
        after = {a: proposed.get(a, before[a]) for a in axes}
        for a in axes:
            bad = violations(after[a], plants[a], Ts, res[a])[2]
            if bad:
                raise TuningRefused(f"proposal refused: axis {a}: " + ", ".join(bad))
        fig_after, u_ratio = predicted_figure(test, after, plants)
        if u_ratio > 1.0:
            raise TuningRefused(f"proposal refused: the output reaches {u_ratio:.2f} × its limit")
    else:
        found = search(before, plants, Ts, lambda g: predicted_figure(test, g, plants), res)
        if found is None:
            raise TuningRefused("no gains keep phase margin ≥ 45°, gain margin ≥ 6 dB, no overshoot and the "
                                "output limit on every axis; nothing proposed")
        design, after, fig_after = found
        # the current gains stay when they keep every margin, the axes are matched (equal
        # lag at the test feed within MATCHED_LAG_MS) and no design does better
        lags = [_lag_ms(before[a], plants[a], Ts, _test_hz(test)) for a in axes]
        if fig_before <= fig_after and u_before <= 1.0 and max(lags) - min(lags) <= MATCHED_LAG_MS and not any(
                violations(before[a], plants[a], Ts, res[a])[2] for a in axes):
            design, after, fig_after = None, dict(before), fig_before
            notes.append("the current gains keep every margin and no design in the search predicts better: "
                         "keep them")
    for a in axes:
        if plants[a].gap_mm > 0:
            if after[a].form == "linuxcnc-pid":
                v = dict(after[a].values)
                v["BACKLASH"] = plants[a].gap_mm
                after[a] = Gains(after[a].form, v, after[a].u_max)
            else:
                notes.append(f"axis {a}: backlash {plants[a].gap_mm * 1e3:.1f} µm accepted; compensate it in the "
                             f"controller's lost-motion setting")
    m_after = {a: violations(after[a], plants[a], Ts, res[a])[:2] for a in axes}
    lag = {a: _lag_ms(after[a], plants[a], Ts, _test_hz(test)) for a in axes}
    return Tuning(test.unit, plants, before, after, m_before, m_after, fig_before, fig_after, lag, design,
                  tuple(notes))


def _resonance(vm: VirtualMachine, axis: str) -> tuple[float, float] | None:
    r = vm.axes[axis].effects.get("resonance")
    if not r:
        return None
    return float(r["freq_hz"]), float(r.get("damping", 0.05))

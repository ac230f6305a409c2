"""Plausibility of captured positions: data that decodes but cannot be a feed drive's motion.

A position register read in the wrong word order, or with the wrong scale, still decodes
to numbers; only the motion they describe gives it away.  With the words of a 32-bit
count swapped, a change of d counts in the low word moves the value by d x 65536 counts,
so even a slow axis (1 mm/s at 1 nm per count and 1 kHz) appears to jump 65 mm per
sample.  :class:`JumpCheck` flags the first step of each axis' commanded or actual
position that is faster than any feed drive moves (:data:`MAX_SPEED`), once per axis,
as a warning: the capture goes on and records what it reads.
"""

from __future__ import annotations

from typing import Callable, Sequence

from core.recording import Sample

__all__ = ["MAX_SPEED", "JumpCheck"]

#: Speeds no feed drive reaches, per unit: linear-motor machine-tool axes reach about 5 m/s
#: (300 m/min), so 20 m/s cannot be motion; rotary axes 100 rev/s (6000 rpm, spindle speed).
MAX_SPEED: dict[str, float] = {"mm": 20_000.0, "deg": 36_000.0}


class JumpCheck:
    """Feed consecutive recorded samples to :meth:`check`; it returns each new warning once.

    Parameters
    ----------
    axes, units : recorded axis names and their units ("mm" or "deg"), in sample order.
    sample_period : controller sample period T_s, s.
    hint : axis name -> where its scale and word order are set (the driver's words).
    """

    def __init__(self, axes: Sequence[str], units: Sequence[str], sample_period: float,
                 hint: Callable[[str], str]) -> None:
        self.axes = list(axes)
        self.units = list(units)
        self.T = sample_period
        self.hint = hint
        self._prev: Sample | None = None
        self._warned: set[int] = set()  # axes already warned about

    def check(self, s: Sample) -> list[str]:
        """Warnings for the step from the previous sample to ``s`` (none once every field has warned)."""
        prev, self._prev = self._prev, s
        if prev is None or len(self._warned) == len(self.axes):
            return []
        dt = (s.counter - prev.counter) * self.T
        out = []
        for i, (axis, unit) in enumerate(zip(self.axes, self.units)):
            limit = MAX_SPEED.get(unit, MAX_SPEED["mm"])
            for label, a, b in (("commanded", prev.commanded[i], s.commanded[i]),
                                ("actual", prev.actual[i], s.actual[i])):
                step = abs(b - a)
                if step > limit * dt and i not in self._warned:
                    self._warned.add(i)
                    out.append(f"axis {axis} {label} position jumps by {step:.6g} {unit} between counters "
                               f"{prev.counter} and {s.counter} ({dt * 1e3:g} ms), {step / dt:.3g} {unit}/s: "
                               f"faster than any feed drive ({limit:g} {unit}/s); a wrong word order or "
                               f"scale reads like this: check {self.hint(axis)}")
        return out

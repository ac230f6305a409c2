"""Plausibility of captured positions: data that decodes but cannot be a feed drive's motion.

A position register read in the wrong word order, or with the wrong scale, still decodes
to numbers; only the motion they describe gives it away.  With the words of a 32-bit
count swapped, a change of d counts in the low word moves the value by d x 65536 counts,
so even a slow axis (1 mm/s at 1 nm per count and 1 kHz) appears to jump 65 mm per
sample.  :class:`JumpCheck` flags the first step of each axis' commanded or actual
position that is faster than any feed drive moves (:data:`MAX_SPEED`), once per axis,
as a warning: the capture goes on and records what it reads.

A wrong sample period (a map saying 1 ms for a controller sampling at 2 ms) or a counter
read in the wrong word order gives times that are wrong throughout, yet every sample
looks fine on its own.  Only the host clock can tell: :class:`ClockCheck` compares the
controller time the samples span (counter x period) with the host time over which they
arrived, and reports a capture whose controller clock runs more than
:data:`CLOCK_TOLERANCE` times faster or slower than the host's as an error.
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

from core.recording import Sample

__all__ = ["MAX_SPEED", "JumpCheck", "CLOCK_TOLERANCE", "CLOCK_WINDOW_S", "CLOCK_SLACK_S", "ClockCheck"]

#: Speeds no feed drive reaches, per unit: linear-motor machine-tool axes reach about 5 m/s
#: (300 m/min), so 20 m/s cannot be motion; rotary axes 100 rev/s (6000 rpm, spindle speed).
MAX_SPEED: dict[str, float] = {"mm": 20_000.0, "deg": 36_000.0}

#: A controller clock this many times faster or slower than the host's is wrong.  Quartz
#: clocks agree to 1e-4; the margin covers when samples arrive, not how fast time runs:
#: a poll, a USB transfer or a scheduler stall can hand samples over ~0.1 s late, which
#: over :data:`CLOCK_WINDOW_S` is a ratio of 1.1.  The errors it is there for are 2x
#: (a period of 1 ms announced for 2 ms, or the reverse) and 65536x (swapped counter words).
CLOCK_TOLERANCE = 1.5
#: Host time, s, that must have passed since the reference sample before the clocks are
#: compared; shorter captures are not judged (their late arrivals would dominate).
CLOCK_WINDOW_S = 1.0
#: The two clocks must also differ by this much, s of host time, before the ratio counts:
#: a capture process stalled by a loaded machine receives samples late, which lowers the
#: ratio early on without the clocks being wrong; a wrong clock builds up a difference
#: that grows with the capture (0.5 s after 1 s at half or double speed).
CLOCK_SLACK_S = 0.5


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


class ClockCheck:
    """Compare the controller's clock with the host's as batches of samples arrive.

    The reference is the last sample of the first batch, when it arrived: a buffered
    transport (a Modbus trace ring, a serial stream joined before its info frame) hands
    its backlog over in that batch, after which samples arrive as they are made.

    A sample can arrive late (a stalled controller, network or capture process hands a
    batch over after the pause) but never early, so each arrival's delay is read against
    the controller's clock: offset = host time - (c - c_ref) x T / expected.  A clock that
    runs at the wrong rate makes the offset drift steadily; a stall raises it for the
    arrivals of one moment only.  So, as :class:`drivers.transports.can_ticks.CounterUnwrapper`
    reads a replay's pace, the clocks are compared between the least delayed arrival of
    each third of the host time since the reference, and both steps must say the same:
    outside ``expected / CLOCK_TOLERANCE .. expected x CLOCK_TOLERANCE``, on the same
    side.  The error also needs :data:`CLOCK_WINDOW_S` of host time since the reference
    and the clocks to differ by :data:`CLOCK_SLACK_S` or more between the first and last
    of those arrivals; a third without an arrival judges nothing.

    The least delayed arrival is kept per bin of host time (:data:`_BINS` bins at most;
    their width doubles when the capture outgrows them), so a check costs the same at
    any length of capture.

    Each :meth:`check` takes a counter and a host time by which the controller had made
    that sample: when the sample arrived or, where the transport reports it, when the
    controller's newest counter was read (a trace ring's head; then a reader falling behind
    the ring does not read as a slow clock).

    Parameters
    ----------
    sample_period : the controller sample period T_s the capture stamps samples with, s.
    expected : how fast the controller's clock runs against the host's (1 for a real
        controller; F for one replaying at F times real time, ``agent serve --speed F``).
    hint : where the period and the counter's word order are set (the driver's words).
    """

    _BINS = 96

    def __init__(self, sample_period: float, expected: float = 1.0, hint: str = "") -> None:
        self.T = sample_period
        self.expected = expected
        self.hint = hint
        self._ref: tuple[int, float] | None = None
        self._width = CLOCK_WINDOW_S / 32  # host s per bin
        self._least: dict[int, tuple[float, int, float]] = {}  # bin -> (offset, counter, host s)

    def _offset(self, counter: int, host_s: float) -> float:
        c0, h0 = self._ref  # type: ignore[misc]
        return (host_s - h0) - (counter - c0) * self.T / self.expected

    def _keep(self, counter: int, host_s: float) -> None:
        """Keep the arrival if it is the least delayed of its bin; halve the bins when too many."""
        h0 = self._ref[1]  # type: ignore[index]
        while (host_s - h0) / self._width >= self._BINS:
            self._width *= 2
            merged: dict[int, tuple[float, int, float]] = {}
            for b, e in self._least.items():
                if b // 2 not in merged or e < merged[b // 2]:
                    merged[b // 2] = e
            self._least = merged
        b = int((host_s - h0) / self._width)
        e = (self._offset(counter, host_s), counter, host_s)
        if b not in self._least or e < self._least[b]:
            self._least[b] = e

    def check(self, counter: int, host_s: float) -> str | None:
        """The error for the newest sample ``counter`` having arrived at host time ``host_s`` (s,
        monotonic), or None while the clocks agree (or too little host time has passed)."""
        if not math.isfinite(self.expected):
            return None
        if self._ref is None:
            self._ref = (counter, host_s)
            self._keep(counter, host_s)
            return None
        self._keep(counter, host_s)
        h0 = self._ref[1]
        host = host_s - h0
        if host < CLOCK_WINDOW_S:
            return None
        least: list[tuple[float, int, float] | None] = [None, None, None]
        for e in self._least.values():
            k = min(2, int(3 * (e[2] - h0) / host))
            if least[k] is None or e < least[k]:
                least[k] = e
        if None in least:
            return None
        ratios = [(b[1] - a[1]) * self.T / (b[2] - a[2]) / self.expected
                  for a, b in zip(least, least[1:])]  # type: ignore[index]
        slow = max(ratios) < 1.0 / CLOCK_TOLERANCE
        fast = min(ratios) > CLOCK_TOLERANCE
        (_, ca, ha), (_, cb, hb) = least[0], least[2]  # type: ignore[misc]
        ctrl, span = (cb - ca) * self.T, hb - ha
        if not (slow or fast) or abs(ctrl / self.expected - span) < CLOCK_SLACK_S:
            return None
        ratio = ctrl / span / self.expected
        speed = "" if self.expected == 1.0 else f" (expected {self.expected:g} times, a replay at that speed)"
        measured = span * self.expected / (cb - ca) if cb > ca else float("inf")
        return (f"the controller's clock runs {ratio * self.expected:.3g} times as fast as the host's{speed}: "
                f"counters {ca}..{cb} span {ctrl:.6g} s at the announced sample period {self.T:g} s but "
                f"came over {span:.3f} s of host time (a sample every {measured:.3g} s); the log's times "
                f"would be wrong: check {self.hint or 'the sample period the controller announces'}")

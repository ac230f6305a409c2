"""Assemble controller sample ticks from CAN frames: one tick-opening frame, then the parts.

On a CANopen bus a tick is one SYNC (carrying the CiA 301 SYNC counter 1..240) followed
by the SYNC-triggered TPDOs of every axis node; with a DBC file it is the frame holding
the ``counter`` signal followed by the position frames.  This module knows nothing of
either: it is told "a tick opened with raw counter c at host time ts" and "part p of
the current tick arrived with these axis values", and it emits a :class:`Sample` as soon
as every part of a tick is in.

Rules (docs/can.md):

* the raw counter wraps (SYNC: 1..240, a 16-bit DBC counter: 0..65535); it is unwrapped
  to a monotonic controller counter that starts at the first raw value seen (minus the
  lowest raw value: 0..modulus-1).  A gap longer than one wrap (the bus went silent) is
  resolved with the host receive times: after more than ``wrap_min_s`` (0.1 s) of
  silence the number of whole wraps is the one that best matches the elapsed host time
  divided by the observed host time per tick.
* a tick whose parts are not all in when the next tick opens is not emitted (a lost or
  rejected frame); the capture loop sees the gap in the counter.
* a part arriving twice within one tick means its tick-opening frame was lost; the
  frames cannot be stamped, so they are ignored (their tick is already counted lost).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from drivers.base import Sample

__all__ = ["TickAssembler", "CounterUnwrapper"]


@dataclass
class CounterUnwrapper:
    """Unwrap a counter that runs ``first .. first+modulus-1`` and then wraps.

    Parameters
    ----------
    modulus : number of distinct counter values (240 for the SYNC counter, 2**16 for a
        16-bit counter signal).
    first : the lowest raw value (1 for the SYNC counter, 0 for a DBC counter).
    period_s : nominal controller sample period in s, the host time per tick assumed
        until enough ticks have been seen to measure it.
    """

    modulus: int
    first: int = 0
    period_s: float = 0.001
    #: host seconds of bus silence below which a gap is taken to span less than one wrap
    #: (one wrap of the SYNC counter is 0.24 s at 1 kHz); keeps scheduling jitter of a
    #: faster-than-real-time replay from being read as whole wraps
    wrap_min_s: float = 0.1
    _last_raw: int | None = None
    _last_u: int = 0
    _last_ts: float = 0.0
    _anchor: tuple[float, int] | None = None
    _ticks_seen: int = 0

    def host_period(self) -> float:
        """Observed host seconds per controller tick (the nominal period until 100 ticks are in)."""
        if self._anchor is not None and self._last_u - self._anchor[1] >= 100:
            measured = (self._last_ts - self._anchor[0]) / (self._last_u - self._anchor[1])
            if measured > 0:
                return measured
        return self.period_s

    def __call__(self, raw: int, ts: float) -> int:
        """The unwrapped counter of a raw counter received at host time ``ts`` (s).

        The first call returns ``raw - first`` (0..modulus-1), so a capture that starts
        with the controller's counter at 0 numbers its samples like the controller.
        """
        raw = int(raw) - self.first
        if self._last_raw is None:
            u = raw  # 0..modulus-1: a capture started with the controller counts like it
            self._anchor = (ts, u)
        else:
            delta = (raw - self._last_raw) % self.modulus
            if delta == 0:
                delta = self.modulus  # the same value again is at least one whole wrap later
            dt = ts - self._last_ts
            wraps = 0
            # a stream arriving faster than half the controller's clock is a replay: a pause
            # there is its sender's (a garbage collection), not ticks lost on the bus, and
            # at a host period of microseconds it would read as whole wraps that never were
            if dt > self.wrap_min_s and self.host_period() >= 0.5 * self.period_s:
                est = dt / self.host_period()
                wraps = max(0, int(round((est - delta) / self.modulus)))
            u = self._last_u + delta + wraps * self.modulus
        self._last_raw, self._last_u, self._last_ts = raw, u, ts
        self._ticks_seen += 1
        return u


@dataclass
class TickAssembler:
    """Collect the parts of each tick and emit complete samples.

    Parameters
    ----------
    n_axes : number of axes in a sample.
    n_parts : number of frames (parts) that make one tick.
    unwrap : the counter unwrapper of the tick-opening frames.
    period_s : controller sample period in s (t_s = counter x period_s).
    """

    n_axes: int
    n_parts: int
    unwrap: CounterUnwrapper
    period_s: float
    segment: int = 0
    lost_ticks: int = 0  # ticks known lost: counter gaps + incomplete ticks
    incomplete_ticks: int = 0
    orphan_parts: int = 0  # parts that arrived without their tick-opening frame
    _counter: int | None = None
    _mask: int = 0
    _emitted: bool = True
    _cmd: list[float] = field(default_factory=list)
    _act: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._cmd = [0.0] * self.n_axes
        self._act = [0.0] * self.n_axes
        self._full = (1 << self.n_parts) - 1

    def open_tick(self, raw_counter: int, ts: float) -> int:
        """A tick-opening frame arrived (raw counter, host time in s); returns the unwrapped counter."""
        if self._counter is not None and not self._emitted:
            self.incomplete_ticks += 1
            self.lost_ticks += 1
        u = self.unwrap(raw_counter, ts)
        if self._counter is not None and u > self._counter + 1:
            self.lost_ticks += u - self._counter - 1
        self._counter = u
        self._mask = 0
        self._emitted = False
        return u

    def part(self, index: int, values: list[tuple[int, float, float]]) -> Sample | None:
        """Part ``index`` of the current tick arrived with (axis index, commanded mm, actual mm) values.

        Returns the sample when this part completes the tick, else None.
        """
        bit = 1 << index
        if self._counter is None or self._emitted or self._mask & bit:
            self.orphan_parts += 1
            return None
        self._mask |= bit
        for axis, cmd, act in values:
            self._cmd[axis] = cmd
            self._act[axis] = act
        if self._mask != self._full:
            return None
        self._emitted = True
        return Sample(self._counter, self._counter * self.period_s, tuple(self._cmd), tuple(self._act),
                      self.segment)

    @property
    def counter(self) -> int | None:
        """Unwrapped counter of the tick being assembled (None before the first)."""
        return self._counter

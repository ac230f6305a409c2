"""Assemble controller sample ticks from CAN frames: one tick-opening frame, then the parts.

On a CANopen bus a tick is one SYNC (carrying the CiA 301 SYNC counter 1..0x1019, or no
counter at all when the drive has no 0x1019) followed by the SYNC-triggered TPDOs of every
axis node; with a DBC file it is the frame holding the ``counter`` signal followed by the
position frames.  This module knows nothing of either: it is told "a tick opened with raw
counter c at host time ts" and "part p of the current tick arrived with these axis
values", and it emits a :class:`Sample` as soon as every part of a tick is in.

Numbering ticks (docs/can.md, "Numbering ticks across silences"): a wrapping counter says
how many ticks passed only modulo its number of values M (a counterless SYNC says nothing:
M = 1).  The host receive times say the rest.  :class:`CounterUnwrapper` keeps the
*envelope*, the host time at which each tick arrives when nothing delays it (the earliest
line through the receive times), the *jitter* (how far frames have been off it) and the
*slack* (how early frames have come: how far off the envelope itself was).  The advance of
a new frame is the largest one the counter allows that does not make the frame early;
when fewer wraps are also plausible (the frame would then be late by a whole wrap, and
frames have been that late), or the frame is later than any jitter seen, it says so
(:class:`CounterError`) instead of guessing.  A counter that advances further than the
host time allows (it jumped back: the controller restarted) is a
:class:`ControllerRestart`.  One frame repeated (same counter, no time passed) is ignored.  Ticks numbered
across a silence of more than a wrap are held back until later frames have confirmed
the host clock, so a wrongly numbered tick is never emitted.

Other rules:

* a tick whose parts are not all in when the next tick opens is not emitted (a lost or
  rejected frame); the capture loop sees the gap in the counter.
* a part arriving twice within one tick, or before any tick, means its tick-opening frame
  was lost; the frames cannot be stamped, so they are ignored (counted per tick in
  ``orphan_ticks``).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

from core.errors import ControllerRestartError, StreamError
from drivers.base import Sample

__all__ = ["TickAssembler", "CounterUnwrapper", "CounterError", "ControllerRestart"]


class CounterError(StreamError):
    """The tick counter cannot be followed past this frame (a restart, or a silence the host clock cannot span)."""


class ControllerRestart(CounterError, ControllerRestartError):
    """The controller restarted: its counter jumped back, or a node sent its NMT boot-up message."""


#: a frame is numbered with the largest advance that makes it at most this early (ticks)
EARLY_TICKS = 0.5
#: how early (ticks) the first frame after a silence may be before the host clock is in doubt
EARLY_AT_SILENCE = 0.25
#: distance from the envelope (ticks) always allowed, also before any jitter was seen
MIN_ALLOWED_LATENESS = 0.5
#: the jitter a frame's lateness is compared with decays with this time constant (s)
JITTER_MEMORY_S = 2.0
#: how fast the envelope may drift later (s per s), for host and controller clock rates
ENVELOPE_LEAK = 1e-4
#: the stream's rate is measured between the least delayed frame of its first this many ticks and
#: the least delayed of its last this many: a frame can come late, never early, so the earliest
#: of a few ticks lies on the line frames arrive on when nothing delays them
RATE_WINDOW_TICKS = 25
#: ticks before the stream's own rate is known; until then the controller's period is assumed,
#: a doubt is reported only when the stream so far runs near it, and frames may be as early
#: as they have been late (the envelope may still be drawn through late first frames)
ESTABLISH_TICKS = 100
#: a stream whose measured period is further than this from the controller's does not run at
#: its controller's clock (a replay); a live controller is within parts per million
RATE_TOLERANCE = 0.02


@dataclass
class CounterUnwrapper:
    """Turn (raw counter, host receive time) pairs into a monotonic controller tick counter.

    Parameters
    ----------
    modulus : number of distinct counter values: 240 for the default SYNC counter, 2**bits
        for a DBC counter signal, 1 for a SYNC without counter (ticks from arrival order and
        host time alone).
    first : the lowest raw value (1 for the SYNC counter, 0 for a DBC counter).
    period_s : the controller's sample period, s.
    what : the counter's name in error messages.
    """

    modulus: int
    first: int = 0
    period_s: float = 0.001
    what: str = "counter"
    _last_raw: int = 0
    _u: int | None = None  # unwrapped counter of the last tick
    _ts: float = 0.0  # its host receive time
    _env: float = 0.0  # envelope: host time tick _u arrives at when nothing delays it
    _jitter: float = 0.0  # decaying maximum of the distance from the envelope, ticks
    _slack: float = 0.0  # decaying maximum of how early frames came, ticks (how far off the envelope was)
    _start: tuple[float, int] = (0.0, 0)  # (host time, counter) of the first tick
    _confirm_until: float = -math.inf  # ticks opened before this host time are unconfirmed
    _window_early: float = MIN_ALLOWED_LATENESS  # how early a frame may be until then, ticks
    _confirmed_u: int = 0  # the last tick before that silence
    # (counter, host time − counter × period) of the least delayed frame of the first ticks, and
    # of the last ones as a sliding minimum (increasing offsets, the oldest first)
    _first_min: tuple[int, float] | None = None
    _recent_min: deque = field(default_factory=deque)
    _early: list = field(default_factory=list)  # (counter, offset) of every tick before ESTABLISH_TICKS
    _replaying: bool = False  # a frame before ESTABLISH_TICKS was numbered as a replay's

    def host_period(self) -> float:
        """Host seconds per controller tick: the nominal period, or for a stream that does not run
        at it (within 2 %, measured over the whole capture) the measured one.

        Measured between the least delayed frame of the first :data:`RATE_WINDOW_TICKS` ticks
        and that of the last ones, not between the first and the last frame: measured from a
        first frame a few ms late (held back by the sender), or to a late last frame, a live
        stream would read as a replay for hundreds of ticks, and a silence of more than a wrap in
        them would be numbered as the counter reads, without a word."""
        if self._first_min is None or not self._recent_min:
            return self.period_s
        (u0, o0), (u1, o1) = self._first_min, self._recent_min[0]
        span = u1 - u0  # at least ESTABLISH_TICKS − 2 × RATE_WINDOW_TICKS once established
        if (self._u or 0) - self._start[1] >= ESTABLISH_TICKS and span > 0:
            measured = self.period_s + (o1 - o0) / span
            if measured > 0 and abs(measured / self.period_s - 1) > RATE_TOLERANCE:
                return measured
        return self.period_s

    def _note_arrival(self, u: int, ts: float) -> None:
        """Keep the least delayed frames the rate is measured between (:meth:`host_period`)."""
        o = ts - u * self.period_s
        if u - self._start[1] < ESTABLISH_TICKS:
            self._early.append((u, o))
        if u - self._start[1] <= RATE_WINDOW_TICKS and (self._first_min is None or o <= self._first_min[1]):
            self._first_min = (u, o)
        q = self._recent_min
        while q and q[-1][1] >= o:
            q.pop()
        q.append((u, o))
        while q[0][0] <= u - RATE_WINDOW_TICKS:
            q.popleft()

    def _replay(self, host_period: float) -> bool:
        """Whether the stream is known not to run at its controller's period: a replay (``agent
        serve --speed``, a trace played into an adapter), whose host times are not the
        controller's clock.  Its counter is taken as it reads."""
        return self.modulus > 1 and host_period != self.period_s

    def _young_replay(self) -> bool:
        """Before the rate is established: a frame already taken as a replay's on this evidence
        (its stall breaks the pace later frames show), or a replay's pace so far
        (:meth:`_early_pace`).  Until the 3rd tick nothing shows a pace: a frame the host clock
        cannot number is then taken as it reads, but the stream is not called a replay for it.
        After, :meth:`host_period` alone decides: a live stream whose first frames came in a
        burst was taken for a replay there, and is not one."""
        if (self._u or 0) - self._start[1] >= ESTABLISH_TICKS:
            return False
        return self._replaying or self._early_pace() != 0

    def _early_pace(self) -> int:
        """Before the rate is established: +1 (slower) or −1 (faster) when the ticks so far run
        steadily more than 25 % off the controller's period — a replay's pace — else 0.

        Measured as :meth:`host_period` is, between least delayed frames (so a late first frame
        does not make a live stream look fast), here those of each third of the ticks so far,
        and both slopes must say it: a sender that held frames back makes one third late, which
        reads as a pace between two of them only.  Too few ticks (under 3) show nothing."""
        span = (self._u or 0) - self._start[1]
        if self.modulus == 1 or not 3 <= span < ESTABLISH_TICKS:
            return 0
        u0 = self._start[1]
        edges = (u0, u0 + span // 3, u0 + 2 * span // 3, u0 + span + 1)
        least = [min((e for e in self._early if lo <= e[0] < hi), key=lambda e: e[1], default=None)
                 for lo, hi in zip(edges, edges[1:])]
        if None in least:
            return 0
        slopes = [(b[1] - a[1]) / (b[0] - a[0]) / self.period_s for a, b in zip(least, least[1:]) if b[0] > a[0]]
        if len(slopes) < 2:
            return 0
        return 1 if min(slopes) > 0.25 else -1 if max(slopes) < -0.25 else 0

    @property
    def unconfirmed_until(self) -> float:
        """Host time until which ticks numbered across a silence wait for later frames to confirm them."""
        return self._confirm_until

    def __call__(self, raw: int, ts: float) -> int | None:
        """The unwrapped counter of a tick-opening frame received at host time ``ts`` (s);
        None for a repeated frame (ignore it).  Raises :class:`CounterError`.

        The first call returns ``raw - first`` (0..modulus-1), so a capture that starts
        with the controller's counter at 0 numbers its samples like the controller.
        """
        r = int(raw) - self.first if self.modulus > 1 else 0
        if self._u is None:
            self._u, self._last_raw, self._ts, self._env = r, r, ts, ts
            self._start = (ts, r)
            self._note_arrival(r, ts)
            return r
        M = self.modulus
        d0 = (r - self._last_raw) % M
        Th = self.host_period()
        if self._replay(Th):
            # a replay's receive times are not the controller's clock: they say nothing of its
            # envelope or jitter, which would otherwise be kept in the replay's ticks and read in
            # the controller's ones if the replay's average rate came near it (one served as
            # fast as possible that stalled)
            if d0 == 0:
                return None
            self._u += d0
            self._last_raw, self._ts, self._env = r, ts, ts
            self._note_arrival(self._u, ts)
            return self._u
        try:
            a = self._advance(d0, ts, Th)
        except CounterError:
            if self.modulus == 1:
                raise
            paced = self._young_replay()
            if not (paced or (self._u or 0) - self._start[1] < 3):
                raise
            a = d0  # before its rate is known a replay cannot be told from a restart: as it reads
            self._replaying = paced  # kept only on a replay's evidence, not for the first ticks' doubt
        if a == 0:
            return None  # the same value again right away: a repeated frame
        dt = ts - self._ts
        predicted = self._env + a * Th + ENVELOPE_LEAK * min(dt, 10 * Th)
        env = min(predicted, ts)
        # a frame later than the envelope shows jitter; so does one earlier than it: the
        # frames the envelope was drawn through were late by that much.  Frames of a live
        # controller are never early, so earliness says only how far off the envelope was
        # (it was drawn through late first frames, say) and is kept apart.
        off = (ts - predicted) / Th
        decay = math.exp(-max(dt, 0.0) / JITTER_MEMORY_S)
        self._jitter = max(abs(off), self._jitter * decay)
        self._slack = max(-off, self._slack * decay)
        self._u += a
        self._last_raw, self._ts, self._env = r, ts, env
        self._note_arrival(self._u, ts)
        return self._u

    def _advance(self, d0: int, ts: float, Th: float) -> int:
        """Ticks from the last frame to this one: d0 + n x modulus, n from the host time; 0 = a repeat."""
        M = self.modulus
        h = (ts - self._env) / Th  # ticks since the last tick, if this frame is not delayed
        base = d0 if d0 or M > 1 else 1  # the fewest ticks the counter allows (0: a repeat)
        allowed = max(2 * self._jitter, MIN_ALLOWED_LATENESS)  # how late a frame may be
        # How early: by as much as the envelope has been off.  In the first ticks it may still be
        # drawn through frames that were all late: by as much as frames have been late.  While
        # ticks numbered across a silence are not yet confirmed, as it was then (frames that come
        # early under that numbering would otherwise widen it themselves).
        window = ts < self._confirm_until
        if window:
            early = self._window_early
        else:
            young = (self._u or 0) - self._start[1] < ESTABLISH_TICKS
            early = max(2 * self._slack, 2 * self._jitter if young else 0.0, MIN_ALLOWED_LATENESS)
        # the next counter value is never "ahead": frames a sender held back arrive in a burst,
        # and a restart that lands on the next value mislabels nothing (unless a silence was
        # just bridged: then the burst is what shows it was a stall)
        if base > h + early and (base != 1 or window or M == 1):
            # without a counter, or right after a bridged silence, it is the receive times that jitter
            kind = CounterError if window or M == 1 else ControllerRestart
            raise kind(self._ahead_message(d0, ts, h))
        n = max(0, int((h + EARLY_TICKS - base) // M))
        if n >= 1 and self._early_pace() > 0:  # (0 once the rate is established)
            # a stall of a replay played slower than the controller: the host clock would count the
            # stall's time in the controller's ticks, so its counter is taken as it reads.  (Only
            # slower: a live stream whose first frames came in a burst looks fast for a while, and
            # a fast replay's stall is numbered right by the host clock.)
            n = 0
        a = base + n * M
        if n >= 1:
            late = h - a  # how late the frame is behind the envelope if a ticks passed
            # resolved only if this frame is on the envelope as closely as frames have been, and
            # the next fewer wraps would make it later than any frame has been
            if late > allowed or late < -max(EARLY_AT_SILENCE, self._slack) or late + M <= allowed:
                raise CounterError(self._ambiguous_message(a, late, allowed, ts, Th))
            # a stall of the sender longer than a wrap would look the same until the frames it
            # held back arrive in a burst: keep this tick back until they would have
            self._confirm_until, self._window_early = ts + (allowed + 2) * Th, early
            self._confirmed_u = self._u
        return a

    def _ahead_message(self, d0: int, ts: float, h: float) -> str:
        gap_ms = (ts - self._ts) * 1e3
        if ts < self._confirm_until:
            return (f"frames arrive faster than the sample period right after {self._u - self._confirmed_u} "
                    f"ticks were counted across a silence ({self.what}): the sender had held them back, which "
                    f"the host clock cannot tell from a silence (after counter {self._confirmed_u}); the log "
                    f"ends there")
        if self.modulus == 1:
            return (f"a {self.what} arrived {gap_ms:.2f} ms after the previous one, before the next was due "
                    f"({self.period_s * 1e3:g} ms period): the host receive times jitter too much to number "
                    f"ticks by arrival (after counter {self._u}); the log ends there")
        return (f"the {self.what} jumped by {d0} ({self._last_raw + self.first} -> "
                f"{(self._last_raw + d0) % self.modulus + self.first}) in {gap_ms:.1f} ms, where at most "
                f"{max(h, 0):.1f} sample periods passed: the controller restarted or its counter was reset, or "
                f"its frames arrive more unevenly than so far (after counter {self._u}); the log ends there")

    def _ambiguous_message(self, a: int, late: float, allowed: float, ts: float, Th: float) -> str:
        gap_ms = (ts - self._ts) * 1e3
        wraps = f"the {self.what} wraps every {self.modulus * Th * 1e3:g} ms" if self.modulus > 1 else \
            f"a {self.what} says nothing of it"
        return (f"the host clock cannot tell how many ticks passed ({a} or {a - self.modulus}) in the "
                f"{gap_ms:.1f} ms since the last tick: {wraps}, frames arrive up to "
                f"{self._jitter * Th * 1e3:.2f} ms late and this one would be {late * Th * 1e3:+.2f} ms off "
                f"(after counter {self._u}); the log ends there")


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
    orphan_ticks: int = 0  # ticks' worth of orphan parts: counted once per tick-opening window
    repeated_openings: int = 0  # tick-opening frames repeated (ignored)
    _counter: int | None = None
    _mask: int = 0
    _emitted: bool = True
    _orphan_counted: bool = False
    _orphan_mask: int = 0
    _hold: bool = False  # the current tick waits for the host clock to be confirmed
    _held: list[Sample] = field(default_factory=list)
    _cmd: list[float] = field(default_factory=list)
    _act: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._cmd = [0.0] * self.n_axes
        self._act = [0.0] * self.n_axes
        self._full = (1 << self.n_parts) - 1

    def open_tick(self, raw_counter: int, ts: float) -> list[Sample]:
        """A tick-opening frame arrived (raw counter, host time in s).

        Returns the samples held back until now that this frame confirms (usually none).
        Raises :class:`CounterError`; the held samples are then dropped.
        """
        try:
            u = self.unwrap(raw_counter, ts)
        except CounterError:
            self._held.clear()
            raise
        if u is None:
            self.repeated_openings += 1
            return []
        if self._counter is not None and not self._emitted:
            self.incomplete_ticks += 1
            self.lost_ticks += 1
        if self._counter is not None and u > self._counter + 1:
            self.lost_ticks += u - self._counter - 1
        self._counter = u
        self._mask = 0
        self._emitted = False
        self._orphan_counted, self._orphan_mask = False, 0
        self._hold = ts < self.unwrap.unconfirmed_until
        if self._held and not self._hold:
            return self.release()
        return []

    def part(self, index: int, values: list[tuple[int, float, float]]) -> Sample | None:
        """Part ``index`` of the current tick arrived with (axis index, commanded mm, actual mm) values.

        Returns the sample when this part completes the tick (and it is not held back), else None.
        """
        bit = 1 << index
        if self._counter is None or self._emitted or self._mask & bit:
            self.orphan_parts += 1
            if not self._orphan_counted or self._orphan_mask & bit:  # a part again: another tick's
                self.orphan_ticks += 1
                self._orphan_counted, self._orphan_mask = True, 0
            self._orphan_mask |= bit
            return None
        self._mask |= bit
        for axis, cmd, act in values:
            self._cmd[axis] = cmd
            self._act[axis] = act
        if self._mask != self._full:
            return None
        self._emitted = True
        sample = Sample(self._counter, self._counter * self.period_s, tuple(self._cmd), tuple(self._act),
                        self.segment)
        if self._hold:
            self._held.append(sample)
            return None
        return sample

    def release(self) -> list[Sample]:
        """The held-back samples, now confirmed (also at the end of the program: nothing can contradict them)."""
        out, self._held = self._held, []
        return out

    @property
    def counter(self) -> int | None:
        """Unwrapped counter of the tick being assembled (None before the first)."""
        return self._counter

    @property
    def skipped_ticks(self) -> int:
        """Ticks that arrived but could not become samples: incomplete, or parts without their opening frame."""
        return self.incomplete_ticks + self.orphan_ticks

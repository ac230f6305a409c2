"""The capture loop shared by every transport: driver -> :class:`~core.writer.McapRecorder`.

:func:`capture` opens the driver picked by the ``--port`` URL scheme, writes the
stream description into the log's channel metadata, then records every sample as it
arrives until

* the controller signals the end of the program (``driver.ended``),
* ``duration`` seconds of controller time have been recorded (exactly
  ``duration / T_s`` samples; or ``duration`` + 1 s of host time if the controller is
  slower or silent),
* SIGINT (Ctrl-C) or SIGTERM, or
* the transport fails for good (e.g. a serial adapter unplugged and not back in time),

and in every case closes the log properly: the ``rapid-ident.summary`` metadata says
how many samples were received, dropped and corrupt, how many reconnects happened and
why the capture ended.  A second Ctrl-C while closing is ignored (with a message) so it
cannot cut the file short.  Until the close, the recorder flushes every second, so a
capture killed outright (SIGKILL, power cut) still leaves a loadable log missing at
most the last second (the recorder is flushed every 0.5 s).

Who counts what (no loss is counted twice):

* ``dropped`` — counted HERE, only from gaps in the controller's sample counter: a
  jump from counter c to c + k + 1 means k samples are missing, whatever the cause
  (not sent, lost on the wire, rejected as corrupt, missed during a reconnect).  Each
  gap is also an ``/events`` entry ``dropped`` at the first missing counter.  A
  driver's own ``stats.dropped`` is added on top and must therefore only count losses
  that cannot show as a counter gap (drivers in this package leave it at 0).
* ``corrupt`` — counted by the DRIVER: frames, lines or responses rejected by a CRC,
  checksum or format check (``stats.corrupt``).  A corrupt sample frame is thus also
  one of the ``dropped`` samples: ``dropped`` is what the recording misses,
  ``corrupt`` says how many of those were seen damaged.
* ``received`` — samples written to the log; ``reconnects`` — from the driver.
* ``duplicates`` — samples whose counter did not advance (repeated, or one stray sample
  behind the last); not written, since recording time must increase.

A second sample behind the last one recorded that counts on from the first is a
controller restart: the capture ends ``"controller restarted"`` (its samples would land
on the old run's times).  :class:`~drivers.plausibility.ClockCheck` compares the
controller time the samples span with the host time they took to arrive (or, where the
transport reports it, with the host time over which the controller made them: a trace
ring's head, so that a reader falling behind the ring is no slow clock); a clock more
than 1.5 times off ends the capture ``"clock mismatch"`` (a wrong sample period or counter
word order).  A capture that records no sample fails whatever stopped it.  Once the
inputs are valid (URL, options, register map) and before connecting, a file left at
``out`` by an earlier capture is removed, so a capture that fails before its stream starts
leaves no file that could pass for its log.

A capture that reads sample data but records none of it, or less than
:data:`MIN_RECORDED_SHARE` of it (the rest rejected as corrupt or counted in the driver's
``stats.skipped``), ends ``"unusable data"`` with the driver's reason in ``error``, never
as an empty log that looks like a success.  Positions that jump faster than any feed
drive moves are warned about once per axis (drivers.plausibility).  The summary's ``end``
is always one of :data:`core.log_format.END_REASONS`; an ``/events`` entry ``end``
repeats it, with the error, at the end of the log.
"""

from __future__ import annotations

import signal
import sys
import threading
import time
import warnings
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Iterator

from core.errors import (ControllerRestartError, InputError, RapidIdentError, RapidIdentWarning, StreamError,
                         TransportError)
from core.log_format import FAILED_ENDS
from drivers.base import Driver, Sample, StreamInfo
from core.writer import McapRecorder
from drivers.plausibility import ClockCheck, JumpCheck
from drivers.registry import open_driver
from drivers.url import PortURL, parse_port_url

__all__ = ["CaptureSummary", "capture", "select_axes", "MIN_RECORDED_SHARE", "REPLAY_OPTION"]

#: URL option of every transport, taken by the capture loop itself: the controller replays
#: at this many times real time (``agent serve --speed F`` prints it in its URL), so its
#: clock is expected to run that much faster than the host's (drivers.plausibility.ClockCheck).
REPLAY_OPTION = "replay_speed"

#: Below this share of the sample records read (recorded + corrupt + skipped) being recorded,
#: the capture has failed: a faulty link loses a few per cent, a map that does not fit the
#: controller loses everything.
MIN_RECORDED_SHARE = 0.5


@dataclass
class CaptureSummary:
    """What a capture did; ``duration_s`` is controller time covered, ``wall_s`` host time."""

    path: Path
    port: str
    axes: list[str]
    sample_period: float
    received: int = 0
    dropped: int = 0
    corrupt: int = 0
    reconnects: int = 0
    duplicates: int = 0
    first_counter: int | None = None
    last_counter: int | None = None
    duration_s: float = 0.0
    wall_s: float = 0.0
    end: str = ""  # one of core.log_format.END_REASONS
    error: str = ""  # what went wrong, "" if nothing did
    skipped: int = 0  # intact sample records the driver could not use (CaptureStats.skipped)
    warnings: list[str] = field(default_factory=list)  # plausibility warnings, as also in /events

    def as_metadata(self) -> dict:
        """The ``rapid-ident.summary`` record (JSON-able values)."""
        d = asdict(self)
        d["path"] = str(self.path)
        return d


def select_axes(info: StreamInfo, wanted: list[str] | None) -> list[int]:
    """Indices into ``info.axes`` of the axes to record; an unknown axis is a one-line error."""
    if not wanted:
        return list(range(len(info.axes)))
    out = []
    for a in wanted:
        if a not in info.axes:
            raise InputError.about("axes", f"the controller has no axis {a!r} (available: {', '.join(info.axes)})")
        if info.axes.index(a) in out:
            raise InputError.about("axes", f"axis {a!r} given twice")
        out.append(info.axes.index(a))
    return out


class _Stop:
    """Set by SIGINT/SIGTERM; the loop polls it between reads (read timeouts are short)."""

    def __init__(self) -> None:
        self.reason = ""
        self.closing = False
        self.event = threading.Event()

    def __call__(self, signum, frame) -> None:  # noqa: ANN001 - signal handler
        if self.closing or self.event.is_set():
            print("still closing the log, please wait", file=sys.stderr, flush=True)
            return
        self.reason = "interrupted" if signum == signal.SIGINT else "terminated"
        self.event.set()


@contextmanager
def _signals(stop: _Stop) -> Iterator[None]:
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in old.items():
            # Once stopped by a signal the process is on its way out: a repeated Ctrl-C
            # must not turn the clean exit into a KeyboardInterrupt or a kill.
            signal.signal(s, signal.SIG_IGN if stop.event.is_set() else h)


class _Progress:
    """The live line on stderr: samples, rate, drops, corrupt, elapsed.

    On a terminal a rich live line refreshed 4 times a second; otherwise (a log file,
    a test) a plain line every 10 s so logs stay short.
    """

    def __init__(self, enabled: bool, port: str) -> None:
        self.port = port
        self._live = None
        self._console = None
        self._next = 0.0
        self._every = 0.25
        if enabled:
            from rich.console import Console
            from rich.live import Live

            self._console = Console(stderr=True)
            if self._console.is_terminal:
                self._live = Live("", console=self._console, refresh_per_second=4, transient=False)
                self._live.start()
            else:
                self._every = 10.0
                self._next = time.monotonic() + self._every

    def update(self, s: CaptureSummary, t0: float, force: bool = False) -> None:
        if self._console is None:
            return
        now = time.monotonic()
        if now < self._next and not force:
            return
        self._next = now + self._every
        wall = now - t0
        rate = s.received / wall if wall > 0 else 0.0
        line = (f"capture {self.port}  {s.received:,} samples  {rate:,.0f}/s  dropped {s.dropped}  "
                f"corrupt {s.corrupt}  reconnects {s.reconnects}  {wall:,.1f} s")
        if self._live is not None:
            from rich.text import Text

            self._live.update(Text(line))  # plain text: a URL may contain [ ] that markup would eat
        elif not force:
            print(line, file=sys.stderr, flush=True)  # no rich wrapping in log files

    def stop(self) -> None:
        if self._live is not None:
            self._live.stop()
            self._live = None
        self._console = None


def capture(
    port: str,
    out: str | Path,
    axes: list[str] | None = None,
    duration: float | None = None,
    progress: bool = True,
    read_timeout: float = 0.1,
) -> CaptureSummary:
    """Record commanded/actual positions from ``port`` into the MCAP log ``out``.

    Parameters
    ----------
    port : ``--port`` URL (SPEC §3); its scheme picks the driver.
    out : the ``.mcap`` file to write.  A file already there is replaced once the stream is
        described and its axes found, when recording starts; a capture that fails before
        leaves it as it was (docs/capture.md, What is written when).
    axes : axis names to record (default: every axis the controller streams).
    duration : stop after this much controller time, s (None: until the program ends or Ctrl-C).
    progress : show the live progress line on stderr.
    read_timeout : longest wait for data per driver read, s (bounds the reaction to Ctrl-C).

    Returns the :class:`CaptureSummary` (also written into the log).  Raises
    :class:`~core.errors.InputError` / :class:`~core.errors.TransportError` before
    anything is recorded (bad URL, unknown axis, port cannot be opened); a transport
    failure after recording has started ends the capture with ``end="transport error"``,
    the message in ``summary.error`` and a complete log.
    """
    if duration is not None and not duration > 0:
        raise InputError.about("duration", f"duration must be > 0 s, got {duration}")
    out = Path(out)
    if out.suffix.lower() != ".mcap":
        raise InputError(f"-o {out}: a capture is written as MCAP; use a .mcap file name")
    if not out.parent.is_dir():
        raise InputError(f"-o {out}: directory {out.parent} does not exist")
    url, speed = _replay_speed(parse_port_url(port))
    driver = open_driver(url, axes)  # checks every option (and loads a register map) before any I/O
    stop = _Stop()
    with _signals(stop):
        info = driver.open()
        try:
            if stop.event.is_set():
                raise TransportError(f"{stop.reason} while connecting to {url.raw}; nothing recorded")
            idx = select_axes(info, axes)
            # The stream is described and its axes are there: recording starts, and only now
            # does a log left at -o by an earlier capture go.  A capture that fails before
            # (a port that does not open, a silent controller, an unknown axis) recorded
            # nothing and loses nothing: the earlier log stays as it was, beside the error.
            if out.is_file() or out.is_symlink():
                out.unlink()
            return _record(driver, info, idx, url.raw, url.scheme, out, duration, progress, read_timeout, stop,
                           speed)
        finally:
            driver.close()


def _replay_speed(url: PortURL) -> tuple[PortURL, float]:
    """The URL without :data:`REPLAY_OPTION` (no driver knows it), and its value (1 if absent)."""
    if REPLAY_OPTION not in url.query:
        return url, 1.0
    speed = url.option(REPLAY_OPTION, float)
    if not speed > 0:  # inf: a replay as fast as possible, whose clock is not checked
        raise InputError.about("port", f"{url.raw}: {REPLAY_OPTION}={speed:g} must be > 0")
    query = {k: v for k, v in url.query.items() if k != REPLAY_OPTION}
    return replace(url, query=query), speed


def _record(driver: Driver, info: StreamInfo, idx: list[int], port: str, scheme: str, out: Path,
            duration: float | None, progress: bool, read_timeout: float, stop: _Stop,
            speed: float = 1.0) -> CaptureSummary:
    names = [info.axes[i] for i in idx]
    units = [info.units[i] for i in idx] if len(info.units) == len(info.axes) else ["mm"] * len(idx)
    T = info.sample_period
    summary = CaptureSummary(path=out, port=port, axes=names, sample_period=T)
    meta = {
        "transport": scheme,
        "port": port,
        "controller": info.controller,
        "programs": list(info.programs),
        "stream_axes": list(info.axes),
        "units": ",".join(units),
        "capture_started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    if info.extra:
        meta["stream"] = info.extra
    # Flush every 0.5 s so that a SIGKILL loses < 1 s even with a slow last read.
    rec = McapRecorder(out, names, T, meta, flush_interval_s=0.5)
    all_axes = idx == list(range(len(info.axes)))
    n_max = None if duration is None else max(1, int(round(duration / T)))
    t0 = time.monotonic()
    bar = _Progress(progress, port)
    jumps = JumpCheck(names, units, T, driver.position_hint)
    clock = ClockCheck(T, speed, getattr(driver, "clock_hint", lambda: "")())
    last = None  # last counter written
    behind = None  # counter of the sample just read that went back (a stray one, or a restart)
    last_seg = None
    seen_corrupt = seen_reconnects = 0
    try:
        while True:
            if stop.event.is_set():
                summary.end = stop.reason
                break
            try:
                batch = driver.read(read_timeout)
            except TransportError as exc:
                summary.end = ("controller restarted" if isinstance(exc, ControllerRestartError)
                               else "unusable data" if isinstance(exc, StreamError) else "transport error")
                summary.error = str(exc)
                break
            now_ns = time.time_ns()
            for s in batch:
                c = s.counter
                if last is not None:
                    if c <= last:
                        if c < last and behind is not None and behind < c:
                            # Two samples behind the last one, counting on: the controller restarted.
                            summary.duplicates -= 1  # ``behind`` was no duplicate but the new run's start
                            summary.end = "controller restarted"
                            summary.error = (f"the controller restarted: its sample counter went back from {last} "
                                             f"to {behind} and counted on ({c}); the samples up to counter {last} "
                                             f"are recorded, the new run needs a new capture")
                            break
                        summary.duplicates += 1
                        behind = c if c < last else None
                        continue
                    behind = None
                    gap = c - last - 1
                    if gap:
                        summary.dropped += gap
                        rec.event("dropped", last + 1, gap, f"counters {last + 1}..{c - 1} missing")
                else:
                    summary.first_counter = c
                if n_max is not None and c - summary.first_counter >= n_max:
                    summary.end = "duration"
                    break
                if s.segment != last_seg:
                    rec.event("segment", c, s.segment, f"segment {s.segment} starts")
                    last_seg = s.segment
                if not all_axes:
                    s = Sample(c, s.t_s, tuple(s.commanded[i] for i in idx), tuple(s.actual[i] for i in idx),
                               s.segment)
                rec.write(s, now_ns)
                summary.received += 1
                last = c
                for msg in jumps.check(s):
                    _warn(rec, summary, c, msg)
            for msg in driver.notices:
                _warn(rec, summary, last or 0, msg)
            driver.notices.clear()
            if batch and last is not None and not summary.end:
                wrong = clock.check(*(driver.newest or (last, time.monotonic())))
                if wrong:
                    summary.end, summary.error = "clock mismatch", wrong
            st = driver.stats
            if st.corrupt != seen_corrupt:
                rec.event("corrupt", last or 0, st.corrupt - seen_corrupt, "frames rejected by the integrity check")
                seen_corrupt = st.corrupt
            if st.reconnects != seen_reconnects:
                rec.event("reconnect", last or 0, st.reconnects - seen_reconnects, f"reconnected to {port}")
                seen_reconnects = st.reconnects
            summary.corrupt, summary.reconnects = st.corrupt, st.reconnects
            summary.last_counter = last
            rec.maybe_flush()  # also while the controller is quiet
            bar.update(summary, t0)
            if summary.end:
                break
            if driver.ended:
                summary.end = "program ended"
                break
            if duration is not None and time.monotonic() - t0 >= duration + 1.0:
                summary.end = "duration (host clock)"
                break
    except Exception as exc:  # closing the log below keeps what was recorded, and says why it ended
        summary.end = "error"
        summary.error = str(exc) if isinstance(exc, RapidIdentError) else f"internal error {type(exc).__name__}: {exc}"
        raise
    finally:
        stop.closing = True
        st = driver.stats
        summary.corrupt, summary.reconnects = st.corrupt, st.reconnects
        summary.dropped += st.dropped  # driver-known losses that are not counter gaps
        summary.last_counter = last
        if last is not None:
            summary.duration_s = (last - summary.first_counter) * T  # first to last sample, as Recording.duration
        summary.wall_s = time.monotonic() - t0
        summary.skipped = st.skipped
        if not summary.end:  # a BaseException other than Exception (e.g. SystemExit)
            summary.end = "error"
        _judge(summary, driver)
        rec.event("end", last if last is not None else 0, summary.received,
                  summary.end + (f": {summary.error}" if summary.error else ""))
        bar.update(summary, t0, force=True)
        bar.stop()
        rec.close(summary.as_metadata())
    return summary


def _warn(rec: McapRecorder, summary: CaptureSummary, counter: int, message: str) -> None:
    """A plausibility warning or a driver's notice: in the log (``/events`` and the summary) and to the caller."""
    rec.event("warning", counter, 0, message)
    summary.warnings.append(message)
    warnings.warn(message, RapidIdentWarning, stacklevel=3)


def _judge(summary: CaptureSummary, driver: Driver) -> None:
    """End ``"unusable data"`` when sample records were read but (almost) none recorded,
    and fail a capture that recorded no sample at all, whatever stopped it.

    A capture that already failed keeps its own end and error.
    """
    if summary.end in FAILED_ENDS:
        return
    read = summary.received + summary.corrupt + summary.skipped
    if not read:
        why = driver.unusable_reason()
        summary.error = (f"no sample recorded (stopped by: {summary.end}): "
                         + (why or f"the controller sent no sample in {summary.wall_s:.1f} s"))
        summary.end = "unusable data" if why else "transport error"
        return
    if not read or summary.received >= MIN_RECORDED_SHARE * read:
        return
    why = []
    if summary.skipped:
        why.append(f"{summary.skipped} unusable ({driver.unusable_reason() or 'the driver cannot say why'})")
    if summary.corrupt:
        why.append(f"{summary.corrupt} rejected by the integrity check (checksum, length or format)")
    got = "none" if not summary.received else f"only {summary.received}"
    summary.error = (f"{read} sample records arrived but {got} could be recorded (stopped by: {summary.end}): "
                     + "; ".join(why))
    summary.end = "unusable data"

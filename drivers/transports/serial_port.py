"""Serial driver: read a controller's pushed sample stream (binary frames or ASCII lines).

URL (SPEC §3)::

    serial:///dev/ttyUSB0?format=binary&baud=921600
    serial:///dev/serial/by-id/usb-FTDI_...?format=ascii&baud=115200&reconnect=10
    /dev/ttyUSB0                                   (bare path = serial, binary, 921600 baud)

Options: ``format`` (binary | ascii, see :mod:`drivers.transports.serial_framing`),
``baud`` (int), ``open_timeout`` (s to wait for the first info frame; default 3),
``reconnect`` (s to keep trying to re-open the port after it vanished; default 5,
0 = give up at once).

Passive: the driver opens the port (8N1, no flow control) and only reads; it never
writes a byte.  The port is opened exclusively (flock) so two captures cannot share it.

Counting (see docs/capture.md): the driver counts ``received`` samples, ``corrupt``
frames (from the codec) and ``reconnects``; it leaves ``dropped`` at 0 because every
lost sample — lost on the wire, rejected as corrupt, missed while unplugged — shows as
a gap in the controller counter, which the capture loop counts once.

Disconnect: an unplugged USB adapter makes ``read`` fail (pyserial: "device reports
readiness to read but returned no data" or EIO).  The driver then re-opens the same
path every 0.2 s for ``reconnect`` s (udev gives the adapter back under the same
/dev/serial/by-id name); on success it counts a reconnect and carries on, the samples
missed meanwhile showing as a counter gap; otherwise it raises a one-line
:class:`~core.errors.TransportError`.
"""

from __future__ import annotations

import errno
import os
import select
import time

import serial

from core.errors import InputError, StreamError, TransportError, TransportTimeout
from drivers.base import Driver, Sample, StreamInfo
from drivers.transports.serial_framing import EndFrame, InfoFrame, SampleFrame, codec_for
from drivers.url import PortURL

__all__ = ["SerialDriver"]

_WRAP = 1 << 32


class SerialDriver(Driver):
    """Capture from a serial port; see the module docstring for URL options and behaviour."""

    schemes = ("serial",)
    options = {"format": str, "baud": int, "open_timeout": float, "reconnect": float}

    def __init__(self, url: PortURL, axes: list[str] | None = None) -> None:
        super().__init__(url, axes)
        if not url.path:
            raise InputError.about("port", f"{url.raw}: no device path; use serial:///dev/ttyUSB0")
        self.path = url.path
        self.format = url.option("format", str, "binary")
        self.codec = codec_for(self.format)
        self.baud = url.option("baud", int, 921600)
        self.open_timeout = url.option("open_timeout", float, 3.0)
        self.reconnect_s = url.option("reconnect", float, 5.0)
        if self.baud <= 0:
            raise InputError.about("port", f"{url.raw}: baud must be > 0, got {self.baud}")
        self._ser: serial.Serial | None = None
        self._frame_info: InfoFrame | None = None
        self._pending: list[SampleFrame] = []  # samples seen before the first info frame
        self._early: list[Sample] = []  # samples decoded while opening, returned by the first read
        self._last_raw: int | None = None
        self._last_full = 0
        self._lost_at: float | None = None
        self._next_try = 0.0
        #: why the port was lost, for the error message
        self._lost_reason = ""

    # -- port handling -----------------------------------------------------------------
    def _open_port(self) -> serial.Serial:
        try:
            ser = serial.Serial(self.path, self.baud, timeout=0, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise TransportError(f"cannot open serial port {self.path}: {_open_reason(exc)}") from exc
        self.codec.reset()  # open() discarded what was queued: the stream resumes mid-frame
        return ser

    def _open(self) -> StreamInfo:
        self._ser = self._open_port()
        deadline = time.monotonic() + self.open_timeout
        seen = 0
        try:
            while self._frame_info is None:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TransportTimeout(
                        f"no info frame from serial port {self.path} within {self.open_timeout:g} s; "
                        + self._no_info_hint(seen))
                data = self._receive(min(left, 0.1))
                seen += len(data)
                self._handle(self.codec.feed(data), self._early)
        except TransportError:  # before OSError: TransportTimeout is a TimeoutError, an OSError
            self._ser.close()
            raise
        except (serial.SerialException, OSError) as exc:
            self._ser.close()
            raise TransportError(f"serial port {self.path} failed while opening: {_reason(exc)}") from exc
        fi = self._frame_info
        units = fi.units if len(fi.units) == len(fi.axes) else tuple(["mm"] * len(fi.axes))
        return StreamInfo(
            axes=fi.axes,
            sample_period=fi.period_ns * 1e-9,
            controller=fi.controller,
            units=units,
            programs=tuple(fi.programs),
            extra={"format": self.format, "baud": self.baud, "counts_per_mm": fi.counts_per_mm},
        )

    def _no_info_hint(self, seen: int) -> str:
        """What arrived instead of an info frame: the words tell a silent line, a wrong format or
        baud rate, a rejected info frame and a controller that never repeats its info frame apart."""
        samples, rejected = len(self._pending), self.codec.rejected_info
        if rejected:
            return (f"{rejected} info frame(s) arrived intact but were rejected: an info message needs a period "
                    f"and a scale > 0 and at least one axis name (docs/serial-protocol.md, info)")
        if samples:
            return (f"{samples} valid {self.format} sample frames arrived but no info frame: the controller must "
                    f"send its info message when it starts streaming and then repeat it (every second is "
                    f"recommended), since opening the port discards what was queued (docs/serial-protocol.md)")
        if seen:
            return f"{seen} bytes arrived but none formed a {self.format} frame - wrong format= or baud="
        return "nothing arrived - is the controller streaming?"

    def clock_hint(self) -> str:
        """Where the sample period is set, for the capture's clock check."""
        return "the period_ns the controller announces in its info message"

    def _close(self) -> None:
        if self._ser is not None:
            self._ser.close()
            self._ser = None

    # -- reading -----------------------------------------------------------------------
    def _read(self, timeout: float) -> list[Sample]:
        if self._ser is None:
            return self._try_reconnect(timeout)
        out, self._early = self._early, []
        try:
            data = self._receive(0.0 if out else timeout)
        except (serial.SerialException, OSError) as exc:
            self._port_lost(exc)
            return out
        self._handle(self.codec.feed(data), out)
        return out

    def _receive(self, timeout: float) -> bytes:
        """Whatever bytes are queued, waiting up to ``timeout`` s for the first.

        The port is opened with timeout 0 and waited on with select(): setting
        pyserial's ``timeout`` re-applies the termios settings on every call.
        """
        ready, _, _ = select.select([self._ser.fileno()], [], [], timeout)
        if not ready:
            return b""
        return self._ser.read(max(1, self._ser.in_waiting))

    def _port_lost(self, exc: Exception) -> None:
        self._lost_reason = _reason(exc)
        try:
            self._ser.close()
        except (serial.SerialException, OSError):
            pass
        self._ser = None
        if self.reconnect_s <= 0:
            raise TransportError(f"serial port {self.path} disconnected ({self._lost_reason})")
        self._lost_at = time.monotonic()
        self._next_try = self._lost_at + 0.2

    def _try_reconnect(self, timeout: float) -> list[Sample]:
        end = time.monotonic() + timeout
        while True:
            now = time.monotonic()
            if now - self._lost_at > self.reconnect_s:
                raise TransportError(
                    f"serial port {self.path} disconnected ({self._lost_reason}) and did not come back "
                    f"within {self.reconnect_s:g} s")
            if now >= self._next_try:
                self._next_try = now + 0.2
                try:
                    self._ser = self._open_port()
                except TransportError:
                    pass
                else:
                    self.stats.reconnects += 1
                    self._lost_at = None
                    return []
            now = time.monotonic()
            if now >= end:
                return []
            time.sleep(max(min(self._next_try, end) - now, 0.0))

    def _handle(self, frames: list, out: list[Sample]) -> None:
        for fr in frames:
            if isinstance(fr, SampleFrame):
                if self._frame_info is None:
                    self._pending.append(fr)
                else:
                    self._emit(fr, out)
            elif isinstance(fr, InfoFrame):
                self._take_info(fr, out)
            elif isinstance(fr, EndFrame):
                if self._frame_info is not None:
                    self.ended = True
        self.stats.corrupt = self.codec.corrupt

    def _take_info(self, fr: InfoFrame, out: list[Sample]) -> None:
        old = self._frame_info
        if old is None:
            self._frame_info = fr
            for s in self._pending:
                self._emit(s, out)
            self._pending.clear()
            return
        if (fr.axes, fr.period_ns, fr.counts_per_mm) != (old.axes, old.period_ns, old.counts_per_mm):
            raise StreamError(
                f"serial port {self.path}: the controller changed its stream mid-capture "
                f"(axes {','.join(old.axes)} -> {','.join(fr.axes)}, period {old.period_ns} -> {fr.period_ns} ns, "
                f"scale {old.counts_per_mm} -> {fr.counts_per_mm} counts/mm); start a new capture")

    def _emit(self, fr: SampleFrame, out: list[Sample]) -> None:
        fi = self._frame_info
        n = len(fi.axes)
        if len(fr.commanded) != n:  # checksum fine but not this stream's layout
            self.codec.corrupt += 1
            return
        # Unwrap the uint32 counter by the shortest modular step from the last one.
        if self._last_raw is None:
            full = fr.counter
        else:
            step = (fr.counter - self._last_raw) % _WRAP
            full = self._last_full + (step if step < _WRAP // 2 else step - _WRAP)
        self._last_raw, self._last_full = fr.counter, full
        cpm = fi.counts_per_mm
        self.stats.received += 1
        out.append(Sample(
            counter=full,
            t_s=full * fi.period_ns / 1e9,
            commanded=tuple(c / cpm for c in fr.commanded),
            actual=tuple(a / cpm for a in fr.actual),
            segment=fr.segment,
        ))


def _open_reason(exc: BaseException) -> str:
    """Why a port did not open, in a few words (pyserial repeats the errno text twice)."""
    err = getattr(exc, "errno", None)
    if err in (errno.EAGAIN, errno.EWOULDBLOCK) and "lock" in str(exc):
        return "in use by another process (exclusive lock held)"
    if err == errno.ENOTTY or "Inappropriate ioctl" in str(exc):
        return "not a serial port"
    if isinstance(err, int) and err > 0:
        return os.strerror(err)
    return _reason(exc)


def _reason(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]

"""Simulated serial controller: pushes the sample stream into a pseudo-terminal.

The endpoint opens a pty (``os.openpty``) and gives it a stable name, a symlink
``<tmpdir>/ttyVCNC0`` to the ``/dev/pts/N`` slave — the way udev's
``/dev/serial/by-id/...`` links name a real USB adapter — and prints
``port: serial://<link>?format=binary&baud=921600``.  It writes frames (binary or
ASCII, :mod:`drivers.transports.serial_framing`) on the master side, paced by the
:class:`~drivers.endpoints.source.RealTimeSource`: an info frame first and every
``info_every`` s, one sample frame per tick, an end frame after the last tick (repeated
while lingering).

Options (``agent serve --opt NAME=VALUE``): ``format`` binary|ascii; ``baud`` (only
put in the URL: a pty has no line rate); ``scale`` counts per mm (default 10 000);
``info_every`` s; ``wait`` (default true: start the program once a capture has
opened the port, detected by the raw mode pyserial sets on the tty, so a test sees
every tick; false: stream from the start like a controller that pushes from power-on);
``outage`` s a disconnect lasts (default 0.5).

Faults: a dropped tick is not sent; a corrupted tick is sent with one bit flipped
(binary) or one digit changed (ASCII) inside the positions, so the CRC/checksum fails
and the frame boundaries stay intact.  A disconnect looks like a USB-serial adapter
being unplugged and plugged back: the pty is closed (the reader's ``read`` fails with
EIO/hang-up, the device node disappears), after ``outage`` s a new pty appears under
the same link, and streaming resumes once a reader has re-opened it; ticks in between
are not sent and are listed in the fault log as ``unsent_counters``.
"""

from __future__ import annotations

import fcntl
import os
import random
import shutil
import struct
import sys
import tempfile
import termios
import time
import tty
from pathlib import Path

import numpy as np

from core.errors import InputError
from drivers.base import StreamInfo
from drivers.endpoints.base import Endpoint
from drivers.endpoints.source import RealTimeSource
from drivers.transports.serial_framing import DEFAULT_COUNTS_PER_MM, InfoFrame, codec_for

__all__ = ["SerialEndpoint"]

#: send buffer above which new ticks are not queued (≈ 1 s of 6-axis binary frames)
MAX_PENDING = 64 * 1024
#: pause after a reader has set raw mode before the handshake info frame (pyserial
#: flushes the input queue right after; see SerialEndpoint._handshake)
OPEN_GUARD_S = 0.05


class SerialEndpoint(Endpoint):
    """Serve a recording over a pseudo-terminal; see the module docstring."""

    name = "serial"
    option_types = {"format": str, "baud": int, "scale": int, "info_every": float, "wait": bool,
                    "outage": float}

    def __init__(self, source: RealTimeSource, info: StreamInfo, options: dict | None = None) -> None:
        super().__init__(source, info, options)
        o = self.options
        self.format = o.get("format", "binary")
        self.codec = codec_for(self.format)
        self.baud = int(o.get("baud", 921600))
        self.counts_per_mm = int(o.get("scale", DEFAULT_COUNTS_PER_MM))
        self.info_every = float(o.get("info_every", 1.0))
        self.wait = bool(o.get("wait", True))
        self.outage_s = float(o.get("outage", 0.5))
        if self.counts_per_mm <= 0 or self.info_every <= 0 or self.outage_s < 0:
            raise InputError("serial endpoint: scale and info_every must be > 0 and outage >= 0")
        cmd = np.rint(source.commanded * self.counts_per_mm)
        act = np.rint(source.actual * self.counts_per_mm)
        big = max(np.abs(cmd).max(initial=0), np.abs(act).max(initial=0))
        if big >= 2**31:
            raise InputError(f"serial endpoint: a position of {big / self.counts_per_mm:g} mm does not fit "
                             f"int32 at {self.counts_per_mm} counts/mm; lower the scale option")
        self._cmd = cmd.astype(np.int64).tolist()
        self._act = act.astype(np.int64).tolist()
        self._counter = source.counter.tolist()
        self._segment = source.recording.segment.tolist()
        self._rng = random.Random(source.faults.seed)
        self._dir: Path | None = None
        self.link: Path | None = None
        self._master = self._slave = -1
        self._out = bytearray()
        self._last_sent = -1

    # -- the pty -------------------------------------------------------------------------
    def start(self) -> None:
        self._dir = Path(tempfile.mkdtemp(prefix="rapid-ident-serial-"))
        self.link = self._dir / "ttyVCNC0"
        self._open_pty()

    def _open_pty(self) -> None:
        self._master, self._slave = os.openpty()
        if not self.wait:
            tty.setraw(self._slave)  # a controller's UART has no line discipline
        os.set_blocking(self._master, False)
        tmp = self._dir / "ttyVCNC0.new"
        if tmp.is_symlink():
            tmp.unlink()
        tmp.symlink_to(os.ttyname(self._slave))
        os.replace(tmp, self.link)  # atomic: the capture never sees a missing link mid-switch
        self._out.clear()
        print(f"serial endpoint: {self.link} -> {os.ttyname(self._slave)} ({self.format})", file=sys.stderr,
              flush=True)

    def _hang_up(self) -> None:
        for fd in (self._master, self._slave):
            if fd >= 0:
                os.close(fd)
        self._master = self._slave = -1
        if self.link is not None and self.link.is_symlink():
            self.link.unlink()

    def _reader_present(self) -> bool:
        # pyserial puts the tty in raw mode on open(); a fresh pty is canonical.
        return not termios.tcgetattr(self._slave)[3] & termios.ICANON

    def port_url(self) -> str:
        return f"serial://{self.link}?format={self.format}&baud={self.baud}"

    def _close(self) -> None:
        self._hang_up()
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)

    # -- writing -------------------------------------------------------------------------
    def _info_frame(self, counter: int) -> bytes:
        i = self.info
        return self.codec.encode_info(InfoFrame(
            counter=counter,
            period_ns=int(round(i.sample_period * 1e9)),
            counts_per_mm=self.counts_per_mm,
            axes=tuple(i.axes),
            units=tuple(i.units),
            controller=i.controller,
            programs=tuple(i.programs),
        ))

    def _send(self, data: bytes) -> None:
        self._out += data
        if not self._out:
            return
        try:
            n = os.write(self._master, self._out)
        except BlockingIOError:
            n = 0
            if not self.wait:
                # Streaming from power-on: with the tty queue full nobody is reading, and a
                # UART's bytes would be gone; keeping them would hand stale data to a
                # capture that opens later.
                self._out.clear()
                return
        except OSError:  # EIO: nobody holds the slave (cannot happen while we keep it open)
            n = len(self._out)
        del self._out[:n]

    def _queued(self) -> int:
        """Bytes written by us and not yet read (or discarded) on the reader's side."""
        return struct.unpack("i", fcntl.ioctl(self._slave, termios.FIONREAD, b"\0\0\0\0"))[0]

    def _handshake(self, counter: int) -> bool:
        """After a reader has opened the port, make sure its open() has finished flushing.

        pyserial sets raw mode, then discards the input queue.  An info frame is sent and
        we wait until the queue is empty: either the reader read it (so open() had
        returned) or open() discarded it (so the flush is over).  Samples sent after that
        are not thrown away; an info frame lost this way is repeated within
        ``info_every`` s and the driver keeps earlier samples until it arrives.
        """
        if self.stop_event.wait(OPEN_GUARD_S):
            return False
        self._send(self._info_frame(counter))
        deadline = time.monotonic() + 5.0
        self.stop_event.wait(0.005)
        while (self._out or self._queued()) and time.monotonic() < deadline:
            self._send(b"")
            if self.stop_event.wait(0.005):
                return False
        return True

    def _wait_for_reader(self) -> bool:
        """Block until a capture has opened the port; False if told to stop."""
        if not self._reader_present():  # say what it waits for: a silent wait looks like a hang
            print(f"waiting for a client on {os.ttyname(self._slave)} ({self.link})", file=sys.stderr, flush=True)
        while not self._reader_present():
            if self.stop_event.wait(0.01):
                return False
        return self._handshake(self._counter[0])

    def serve_ticks(self) -> None:
        src = self.source
        if self.wait and not self._wait_for_reader():
            return
        dropped, corrupted = src.dropped.tolist(), src.corrupted.tolist()
        disconnect_k = -1
        if src.faults.disconnect_at_s is not None:
            later = np.flatnonzero(src.recording.t >= src.faults.disconnect_at_s)
            disconnect_k = int(later[0]) if later.size else -1
        state = "up"  # up | down (unplugged) | waiting (plugged back, no reader yet)
        down_until = 0.0
        next_info = 0.0
        codec, cmd, act, cnt, seg = self.codec, self._cmd, self._act, self._counter, self._segment
        for ticks, _t in src.batches():
            if self.stop_event.is_set():
                return
            now = time.monotonic()
            if state == "down" and now >= down_until:
                self._open_pty()
                state = "waiting"
            if state == "waiting" and self._reader_present():
                if not self._handshake(cnt[ticks[0]]):
                    return
                state, next_info = "up", 0.0
                # the ticks that passed during the handshake are unsent
                self.unsent_counters.extend(cnt[k] for k in ticks)
                continue
            if state == "up" and len(self._out) > MAX_PENDING:
                self.unsent_counters.extend(cnt[k] for k in ticks)
                self._send(b"")
                continue
            chunk = bytearray()
            if state == "up" and now >= next_info:
                chunk += self._info_frame(cnt[ticks[0]])
                next_info = now + self.info_every
            for k in ticks:
                if state == "up" and k == disconnect_k:
                    self._send(bytes(chunk))
                    chunk.clear()
                    self._hang_up()
                    state, down_until = "down", time.monotonic() + self.outage_s
                    print(f"serial endpoint: disconnected at counter {cnt[k]} for {self.outage_s:g} s",
                          file=sys.stderr, flush=True)
                if state != "up":
                    self.unsent_counters.append(cnt[k])
                    continue
                if dropped[k]:
                    continue
                frame = codec.encode_sample(cnt[k], seg[k], cmd[k], act[k])
                if corrupted[k]:
                    frame = codec.damage(frame, self._rng)
                chunk += frame
                self._last_sent = cnt[k]
            if state == "up":
                self._send(bytes(chunk))
                self.note_sent(self._last_sent)

    def linger(self) -> None:
        """Send the end frame, repeat it every 0.25 s while lingering, then stop."""
        end = time.monotonic() + self.linger_s
        frame = self.codec.encode_end(self._counter[-1])
        while self._master >= 0:
            self._send(frame)
            if self.stop_event.wait(min(0.25, max(end - time.monotonic(), 0.0))) or time.monotonic() >= end:
                break

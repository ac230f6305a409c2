"""A serial controller written from docs/serial-protocol.md (not drivers/endpoints): a pty sender.

Frames are built here from the document's tables (binary: ``A5 5A``, type, uint16 length,
payload, zlib CRC-32 over type..payload, little endian; ASCII: ``$...*HH`` with the XOR
checksum), not with the project's codec.  The capture opens the pty's slave path; the
sender starts once it sees the raw mode pyserial sets, so no tick is sent to nobody.

Tick k (paced at ``period_s`` of host time) carries commanded = k and actual = -k counts
(``counts_per_mm`` = 10 000), so a capture's every sample can be checked against its tick.
The controller's faults: ticks not sent (``skip``), a counter that restarts at
``restart_at`` (the new run counts from 0, positions go on with the true tick), an
announced period (``announced_period_s``) that is not the real one, no info message
(``info=False``) or no sample message (``samples=False``).
"""

from __future__ import annotations

import json
import os
import struct
import termios
import threading
import time
import zlib

COUNTS_PER_MM = 10_000


def binary_frame(ftype: bytes, payload: bytes) -> bytes:
    body = ftype + struct.pack("<H", len(payload)) + payload
    return b"\xa5\x5a" + body + struct.pack("<I", zlib.crc32(body))


def ascii_line(body: str) -> bytes:
    x = 0
    for b in body.encode():
        x ^= b
    return b"$" + body.encode() + b"*%02X\r\n" % x


class TickSender:
    """Context manager: a pty whose slave path is :attr:`url`; streams in its own thread."""

    def __init__(self, ticks: int = 1500, period_s: float = 0.001, announced_period_s: float | None = None,
                 fmt: str = "binary", restart_at: int | None = None, skip: frozenset[int] = frozenset(),
                 info: bool = True, samples: bool = True) -> None:
        self.ticks, self.period_s = ticks, period_s
        self.announced = period_s if announced_period_s is None else announced_period_s
        self.fmt, self.restart_at, self.skip = fmt, restart_at, skip
        self.info, self.samples = info, samples
        self.master, self.slave = os.openpty()
        os.set_blocking(self.master, False)  # a capture that has gone must not block the sender
        self.url = f"serial://{os.ttyname(self.slave)}?format={fmt}"
        self.stop = threading.Event()
        self._th = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> "TickSender":
        self._th.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self._th.join(5)
        os.close(self.master)
        os.close(self.slave)

    def counter_of(self, k: int) -> int:
        return k - self.restart_at if self.restart_at is not None and k >= self.restart_at else k

    # -- messages, from the document's tables ------------------------------------------------
    def info_msg(self, next_counter: int) -> bytes:
        period_ns = round(self.announced * 1e9)
        if self.fmt == "binary":
            text = json.dumps({"axes": ["X"], "units": ["mm"], "controller": "fault peer"}).encode()
            return binary_frame(b"I", struct.pack("<III", next_counter, period_ns, COUNTS_PER_MM) + text)
        return ascii_line(f"I,{next_counter},{period_ns},{COUNTS_PER_MM},X,mm,fault peer,")

    def sample_msg(self, k: int) -> bytes:
        c = self.counter_of(k) & 0xFFFFFFFF
        if self.fmt == "binary":
            return binary_frame(b"S", struct.pack("<IHBBii", c, 0, 1, 0, k, -k))
        return ascii_line(f"S,{c},0,{k},{-k}")

    def end_msg(self, last: int) -> bytes:
        if self.fmt == "binary":
            return binary_frame(b"E", struct.pack("<II", last, 0))
        return ascii_line(f"E,{last}")

    # -- streaming -----------------------------------------------------------------------------
    def _write(self, data: bytes) -> None:
        try:
            os.write(self.master, data)
        except BlockingIOError:  # nobody reads any more (the capture stopped)
            pass

    def _reader_ready(self) -> bool:
        """pyserial has opened the slave: it set raw mode (no ICANON)."""
        return not termios.tcgetattr(self.slave)[3] & termios.ICANON

    def _run(self) -> None:
        deadline = time.monotonic() + 30
        while not self._reader_ready():
            if self.stop.is_set() or time.monotonic() > deadline:
                return
            time.sleep(0.005)
        time.sleep(0.05)  # pyserial discards what is queued right after opening
        t0 = time.monotonic()
        next_info = t0
        k = 0
        while k < self.ticks and not self.stop.is_set():
            now = time.monotonic()
            out = b""
            if self.info and now >= next_info:
                out += self.info_msg(self.counter_of(k))
                next_info = now + 0.3
            due = min(int((now - t0) / self.period_s) + 1, self.ticks)
            if self.samples:
                out += b"".join(self.sample_msg(j) for j in range(k, due) if j not in self.skip)
            k = due
            if out:
                self._write(out)
            time.sleep(0.002)
        end = time.monotonic() + 0.5
        while not self.stop.is_set() and time.monotonic() < end:
            self._write(self.end_msg(self.counter_of(self.ticks - 1)))
            time.sleep(0.1)

"""A Modbus TCP controller written from docs/modbus.md with raw sockets (not drivers/endpoints).

It serves the default register layout of the document for one axis X: the info block at
0 (byte count, then ASCII two characters per register, high byte first), status at 256
(bit 0 running, bit 1 ended), the 32-bit counter at 257, segment at 259, the trace head at
260, the capacity at 262, X commanded/actual at 264/266 and the trace ring from 1024
(records of 7 registers: counter, segment, commanded, actual).  Only FC 3 is answered;
anything else gets exception 1.

Tick k (paced at ``period_s`` of host time from the first request) carries commanded = k
and actual = -k counts (1 nm each), so a capture's every sample can be checked against
the tick it belongs to.  Faults are the controller's own: a counter that restarts
(``restart_at``), a word order (``word_order``) the map may not say, an announced period
(``announced_period_s``) that is not the real one, a status register that never says
running (``running=False``).  Without ``info_period`` the info block names no period,
so a capture takes it from its register map.
"""

from __future__ import annotations

import socket
import struct
import threading
import time

import numpy as np

STATUS, COUNTER, SEGMENT, HEAD, CAPACITY, X_CMD, X_ACT, BASE = 256, 257, 259, 260, 262, 264, 266, 1024
RECORD = 7
SCALE_MM = 1e-6  # mm per count


def _u32_words(value: int, order: str) -> tuple[int, int]:
    hi, lo = (value >> 16) & 0xFFFF, value & 0xFFFF
    return (hi, lo) if order == "big" else (lo, hi)


def _i32_words(value: int, order: str) -> tuple[int, int]:
    return _u32_words(value & 0xFFFFFFFF, order)


class TickServer:
    """Context manager: listens on 127.0.0.1, ticks in its own thread once a client has asked."""

    def __init__(self, ticks: int = 1500, period_s: float = 0.001, announced_period_s: float | None = None,
                 word_order: str = "big", restart_at: int | None = None, running: bool = True,
                 capacity: int = 2000, programs: tuple[str, ...] = (), info_period: bool = True) -> None:
        self.ticks, self.period_s = ticks, period_s
        self.announced = period_s if announced_period_s is None else announced_period_s
        self.order, self.restart_at, self.running = word_order, restart_at, running
        self.capacity = capacity
        self.info_period = info_period
        self.regs = np.zeros(65536, dtype=np.uint16)
        self.lock = threading.Lock()
        self.started = threading.Event()
        self.stop = threading.Event()
        self._write_info(programs)
        self.regs[CAPACITY] = capacity
        self.sock = socket.socket()
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(4)
        self.port = self.sock.getsockname()[1]
        self.url = f"modbus-tcp://127.0.0.1:{self.port}"
        self._threads = [threading.Thread(target=self._accept, daemon=True),
                         threading.Thread(target=self._tick, daemon=True)]

    def _write_info(self, programs: tuple[str, ...]) -> None:
        text = "controller=fault peer\naxes=X\n"
        if self.info_period:  # else the capture takes the period from the register map
            text += f"period_s={self.announced!r}\n"
        text += "".join(f"program={p}\n" for p in programs)
        raw = text.encode()
        raw += b"\0" * (len(raw) % 2)
        self.regs[0] = len(text)
        self.regs[1:1 + len(raw) // 2] = np.frombuffer(raw, dtype=">u2")

    def __enter__(self) -> "TickServer":
        for th in self._threads:
            th.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.sock.close()
        for th in self._threads:
            th.join(2)

    # -- the controller --------------------------------------------------------------------
    def counter_of(self, k: int) -> int:
        """The counter the controller gives tick k (it starts again from 0 at a restart)."""
        return k - self.restart_at if self.restart_at is not None and k >= self.restart_at else k

    def _tick(self) -> None:
        if not self.started.wait(30):
            return
        t0 = time.monotonic()
        k = 0
        while k < self.ticks and not self.stop.is_set():
            due = int((time.monotonic() - t0) / self.period_s) + 1
            with self.lock:
                for j in range(k, min(due, self.ticks)):
                    self._write_tick(j)
            k = min(due, self.ticks)
            time.sleep(0.001)
        with self.lock:
            self.regs[STATUS] = 0x2 if self.running else 0

    def _write_tick(self, k: int) -> None:
        r, o = self.regs, self.order
        c = self.counter_of(k)
        slot = BASE + (c % self.capacity) * RECORD
        r[slot:slot + 2] = _u32_words(c, o)
        r[slot + 2] = 0
        r[slot + 3:slot + 5] = _i32_words(k, o)
        r[slot + 5:slot + 7] = _i32_words(-k, o)
        r[HEAD:HEAD + 2] = _u32_words(c + 1, o)
        r[COUNTER:COUNTER + 2] = _u32_words(c, o)
        r[X_CMD:X_CMD + 2] = _i32_words(k, o)
        r[X_ACT:X_ACT + 2] = _i32_words(-k, o)
        r[STATUS] = 0x1 if self.running else 0

    # -- Modbus TCP --------------------------------------------------------------------------
    def _accept(self) -> None:
        while not self.stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        with conn:
            while not self.stop.is_set():
                head = _recv(conn, 7)
                if head is None:
                    return
                tid, _pid, length, unit = struct.unpack(">HHHB", head)
                pdu = _recv(conn, length - 1)
                if pdu is None:
                    return
                self.started.set()
                fc = pdu[0]
                if fc != 3 or len(pdu) != 5:
                    body = bytes([fc | 0x80, 1])
                else:
                    addr, count = struct.unpack(">HH", pdu[1:5])
                    with self.lock:
                        values = self.regs[addr:addr + count].astype(">u2").tobytes()
                    body = bytes([3, 2 * count]) + values
                conn.sendall(struct.pack(">HHHB", tid, 0, len(body) + 1, unit) + body)


def _recv(conn: socket.socket, n: int) -> bytes | None:
    buf = b""
    while len(buf) < n:
        try:
            part = conn.recv(n - len(buf))
        except OSError:
            return None
        if not part:
            return None
        buf += part
    return buf

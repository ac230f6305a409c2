"""Simulated Modbus controller: a pymodbus server (TCP on 127.0.0.1, or RTU over a pseudo-terminal).

The endpoint serves one register image laid out by a register map
(:mod:`drivers.modbus_map`; default: :func:`~drivers.modbus_map.default_map` for the
recording's axes, which for X, Y, Z is ``fixtures/modbus/default_map.toml``):

* the info block (ASCII ``key=value``: controller, axes, period_s, program=<name> <sha256>),
* the status register (bit 0 running, bit 1 program ended),
* the live registers (sample counter, segment, commanded/actual per axis): a read shows the
  tick due at that moment of the real-time clock (not the last batch), as a controller's
  real-time loop updates them every tick,
* the trace buffer: a ring of (counter, segment, positions) records plus the head counter
  and the capacity, appended in real time from a :class:`RealTimeSource` (1 kHz, in batches).

Positions are 32-bit signed counts, ``count = rint(mm / scale_mm)`` (default 1 nm).
The image is read-only: every write request (and any table other than the map's) is
answered with exception 1 (illegal function).

Fault injection (from the source's fault plan, decided up front so tests can compare):

* dropped tick: its record is never written to the ring (its slot keeps an older record,
  so the reader sees a counter gap) and the live registers skip it;
* corrupted tick: the first response that carries its record (or its live values) is
  damaged -- over RTU the frame's CRC is wrong (the client rejects it), over TCP (which
  has no Modbus checksum; the stack's own checksums would catch a bit flip) the server
  answers exception 4 "server device failure", as a controller does when its trace
  memory check fails.  A retry gets the good data, so each corrupted tick costs exactly
  one rejected response and no sample;
* disconnect at ``disconnect_at_s``: TCP -- the server closes every client connection and
  keeps listening; RTU -- the line goes silent for ``outage`` s (a pulled cable).

Options (``agent serve --transport modbus --opt NAME=VALUE``): ``link`` tcp|rtu (default
tcp), ``port`` TCP port (0 = a free one), ``map`` register map TOML, ``unit``, ``mode``
(trace|live, written into the printed URL), ``baud`` (RTU, written into the URL), ``pace``
(RTU: carry the bytes at ``baud``, 10 bits each, as a real line does; default false, since a
pty has no line rate and runs as fast as the copying thread), ``capacity`` ring slots,
``wait`` s to wait for the first request before starting the program (so a capture started
a moment later misses nothing), ``outage`` s of RTU silence at the disconnect.
"""

from __future__ import annotations

import asyncio
import logging
import os
import select
import threading
import time
import tty
from collections import Counter
from typing import Any

import numpy as np
from pymodbus.constants import ExcCodes
from pymodbus.datastore import ModbusServerContext
from pymodbus.exceptions import NoSuchIdException
from pymodbus.framer import FramerType
from pymodbus.server import ModbusSerialServer, ModbusTcpServer

from core.errors import InputError, MachineError, TransportError
from drivers.base import StreamInfo
from drivers.endpoints.base import Endpoint
from drivers.endpoints.source import RealTimeSource
from drivers.modbus_map import (
    STATUS_ENDED,
    STATUS_RUNNING,
    RegisterMap,
    default_map,
    encode_info,
    encode_u32,
    load_map,
)

__all__ = ["ModbusEndpoint", "RegisterImage", "encode_records"]

logging.getLogger("pymodbus").addHandler(logging.NullHandler())

#: largest ring the default layout offers (records); 6 axes fit 2389, 3 axes 4300
MAX_DEFAULT_CAPACITY = 10000


def encode_records(source: RealTimeSource, rmap: RegisterMap) -> np.ndarray:
    """Every tick of the source as a trace record, shape (n, record_words), uint16 in wire order.

    Positions become ``rint(mm / scale_mm)`` 32-bit counts; a position that does not fit
    in int32 at the map's scale is a MachineError naming the axis.
    """
    n = source.n
    rec = np.zeros((n, rmap.record_words), dtype=np.uint16)
    rec[:, 0:2] = encode_u32(source.counter & 0xFFFFFFFF, rmap.word_order)
    rec[:, 2] = source.recording.segment.astype(np.int64) & 0xFFFF
    for i, ax in enumerate(rmap.axes):
        j = source.axes.index(ax.name)
        for col, values in ((3 + 4 * i, source.commanded[:, j]), (5 + 4 * i, source.actual[:, j])):
            counts = np.rint(values / ax.scale_mm)
            if counts.size and np.abs(counts).max() > 2**31 - 1:
                raise MachineError(f"axis {ax.name}: position {np.abs(values).max():.6g} {ax.unit} does not fit "
                                   f"a 32-bit register at scale_mm = {ax.scale_mm:g}; use a coarser scale")
            rec[:, col:col + 2] = encode_u32(counts.astype(np.int64), ax.word_order)
    return rec


class RegisterImage(ModbusServerContext):
    """The controller's register image, served to pymodbus as its datastore.

    pymodbus calls :meth:`async_getValues` from its event-loop thread; the feeder thread
    writes ticks under the same lock, so a response never mixes two updates.
    """

    def __init__(self, rmap: RegisterMap, capacity: int, corrupt_style: str) -> None:
        # Deliberately not calling ModbusServerContext.__init__: this is a custom datastore
        # (pymodbus uses such a context as-is when ``old_simulator`` is true).
        self.old_simulator = True
        self.simdevices = []
        self.rmap = rmap
        self.capacity = capacity
        self.W = rmap.record_words
        self.base = rmap.trace.base if rmap.trace else 0
        ring_end = self.base + capacity * self.W if rmap.trace else 0
        fields_end = max(a + w for _, a, w, _ in rmap.live_fields())
        if rmap.trace:
            fields_end = max(fields_end, rmap.trace.head + 2, rmap.trace.capacity + 1)
        if rmap.info_address is not None:
            fields_end = max(fields_end, rmap.info_address + rmap.info_length)
        self.size = max(ring_end, fields_end)
        if self.size > 65536:
            raise MachineError(f"a trace ring of {capacity} records x {self.W} registers does not fit the "
                               f"register space above trace.base = {self.base}; lower capacity")
        self.regs = np.zeros(self.size, dtype=np.uint16)
        self.lock = threading.Lock()
        self.corrupt_style = corrupt_style  # "exception" (TCP) or "crc" (RTU)
        #: unspent corrupted records: ring slot -> counter
        self.pending_corrupt: dict[int, int] = {}
        # live view: computed at request time from the clock (see :meth:`start_clock`)
        self._clock: tuple[float, float, float] | None = None  # (start monotonic s, speed, T_s)
        self._records: np.ndarray | None = None
        self._last_kept: np.ndarray | None = None
        self._corrupted: np.ndarray | None = None
        self._live_k = -1  # tick shown in the live registers
        self.live_corrupt = False
        self.corrupt_next_frame = False  # RTU: damage the CRC of the next response frame
        self.corrupted_responses = 0
        self.function_codes: Counter[int] = Counter()
        self.first_request = threading.Event()
        #: counter + 1 of the newest trace record a client has read; host time of the last request
        self.uploaded_to = 0
        self.last_request = 0.0
        #: how far the trace a client had read (:attr:`uploaded_to`) when it last read the
        #: end-of-program status; None before.  A client has seen the end once this covers
        #: the last record: a status read in the middle of the upload says ended, yet the
        #: client still has records to read and its next status read to make.
        self.end_seen_after: int | None = None
        # live registers: (address, offset in record, words) of each live field
        self._live = [(rmap.counter, 0, 2)]
        if rmap.segment is not None:
            self._live.append((rmap.segment, 2, 1))
        for i, ax in enumerate(rmap.axes):
            self._live += [(ax.commanded, 3 + 4 * i, 2), (ax.actual, 5 + 4 * i, 2)]
        # registers whose read delivers a (possibly corrupted) live position
        self._live_pos = [(ax.commanded, 2) for ax in rmap.axes] + [(ax.actual, 2) for ax in rmap.axes]
        self._live_start = min(a for a, _, _ in self._live)
        self._live_end = max(a + w for a, _, w in self._live)
        if rmap.trace:
            self.regs[rmap.trace.capacity] = capacity

    # -- feeder side (serve thread) --------------------------------------------------------
    def set_info(self, text: dict[str, Any]) -> None:
        if self.rmap.info_address is not None:
            a = self.rmap.info_address
            self.regs[a:a + self.rmap.info_length] = encode_info(text, self.rmap.info_length)

    def publish(self, records: np.ndarray, counters: np.ndarray, dropped: np.ndarray,
                corrupted: np.ndarray) -> None:
        """Append a batch of ticks to the trace buffer: the records first, then the head."""
        keep = ~dropped
        with self.lock:
            self.regs[self.rmap.status] |= STATUS_RUNNING
            if self.rmap.trace is not None and keep.any():
                slots = counters[keep] % self.capacity
                ring = self.regs[self.base:self.base + self.capacity * self.W].reshape(self.capacity, self.W)
                ring[slots] = records[keep]
                for slot in slots.tolist():  # an overwritten corrupted record can no longer be served
                    self.pending_corrupt.pop(slot, None)
                for c in counters[keep & corrupted].tolist():
                    self.pending_corrupt[c % self.capacity] = c
            if self.rmap.trace is not None:
                head = (int(counters[-1]) + 1) & 0xFFFFFFFF
                h = self.rmap.trace.head
                self.regs[h:h + 2] = encode_u32(np.array(head), self.rmap.word_order)

    def start_clock(self, start: float, speed: float, period: float, records: np.ndarray,
                    dropped: np.ndarray, corrupted: np.ndarray) -> None:
        """Start the live registers: at host time t they show the tick due then (the newest one
        not dropped), as a controller's real-time loop updates them every tick."""
        idx = np.where(~dropped, np.arange(len(dropped)), -1)
        with self.lock:
            self._records, self._corrupted = records, corrupted
            self._last_kept = np.maximum.accumulate(idx)
            self._clock = (start, speed, period)

    def _update_live(self) -> None:
        start, speed, T = self._clock  # type: ignore[misc]
        k = int((time.monotonic() - start) * speed / T)
        k = int(self._last_kept[min(max(k, 0), len(self._last_kept) - 1)])  # type: ignore[index]
        if k < 0 or k == self._live_k:
            return
        self._live_k = k
        rec = self._records[k]  # type: ignore[index]
        for addr, off, words in self._live:
            self.regs[addr:addr + words] = rec[off:off + words]
        self.live_corrupt = bool(self._corrupted[k])  # type: ignore[index]

    def set_ended(self) -> None:
        with self.lock:
            self.regs[self.rmap.status] |= STATUS_ENDED

    # -- pymodbus side (event-loop thread) ------------------------------------------------
    def device_ids(self) -> list[int]:
        return [self.rmap.unit]

    async def async_getValues(self, device_id: int, func_code: int, address: int, count: int = 1):
        self.first_request.set()
        if device_id not in (self.rmap.unit, 0):
            raise NoSuchIdException(f"unit {device_id}")
        if func_code != self.rmap.function_code:
            return ExcCodes.ILLEGAL_FUNCTION
        if address + count > self.size:
            return ExcCodes.ILLEGAL_ADDRESS
        self.last_request = time.monotonic()
        with self.lock:
            if self.rmap.trace is not None and address + count > self.base:
                self._note_upload(address, count)
            if address <= self.rmap.status < address + count and self.regs[self.rmap.status] & STATUS_ENDED:
                self.end_seen_after = self.uploaded_to
            if self._clock is not None and address < self._live_end and address + count > self._live_start:
                self._update_live()
            if self._take_corruption(address, count):
                self.corrupted_responses += 1
                if self.corrupt_style == "exception":
                    return ExcCodes.DEVICE_FAILURE
                self.corrupt_next_frame = True
            return self.regs[address:address + count].tolist()

    async def async_setValues(self, device_id: int, func_code: int, address: int, values) -> ExcCodes:
        self.first_request.set()
        return ExcCodes.ILLEGAL_FUNCTION  # the image is read-only

    def _note_upload(self, address: int, count: int) -> None:
        """Remember the newest record a client has read (the endpoint lingers until it is the last)."""
        s0 = (max(address, self.base) - self.base) // self.W
        s1 = min((address + count - self.base) // self.W, self.capacity)  # whole records only
        if s1 > s0:
            ring = self.regs[self.base:self.base + self.capacity * self.W].reshape(self.capacity, self.W)
            words = ring[s0:s1, 0:2].astype(np.int64)
            c = words[:, 0] << 16 | words[:, 1] if self.rmap.word_order == "big" else words[:, 1] << 16 | words[:, 0]
            self.uploaded_to = max(self.uploaded_to, int(c.max()) + 1)

    def _take_corruption(self, address: int, count: int) -> bool:
        """Whether this read carries a not yet damaged corrupted tick (then mark it spent)."""
        end = address + count
        if self.live_corrupt and any(a < end and address < a + w for a, w in self._live_pos):
            self.live_corrupt = False
            return True
        if self.pending_corrupt and self.rmap.trace is not None and end > self.base:
            s0 = (max(address, self.base) - self.base) // self.W
            s1 = (end - self.base - 1) // self.W
            for slot in sorted(self.pending_corrupt):
                if s0 <= slot <= s1:
                    del self.pending_corrupt[slot]
                    return True
        return False

    # pymodbus trace hooks
    def trace_pdu(self, sending: bool, pdu):
        if not sending:
            self.function_codes[pdu.function_code] += 1
        return pdu

    def trace_packet(self, sending: bool, data: bytes) -> bytes:
        if sending and self.corrupt_next_frame:
            self.corrupt_next_frame = False
            return data[:-1] + bytes([data[-1] ^ 0x5A])  # wrong CRC low byte
        return data


class _PtyLine:
    """A serial line between two pseudo-terminals: the server opens one end, the capture the other.

    pymodbus' serial server needs a device path and so does the capture, while a single pty
    has a path for one side only; so two ptys are joined by a copying thread (like socat).
    The thread is also where a pulled cable is simulated (:meth:`cut`) and, with ``baud``,
    where the line's rate is: RS-485 is half duplex, so the bytes of both directions share
    one line, each chunk delivered when its last byte (start, 8 data and stop bits) would
    have arrived.
    """

    BITS_PER_BYTE = 10

    def __init__(self, baud: int | None = None) -> None:
        self._byte_s = self.BITS_PER_BYTE / baud if baud else 0.0
        self._free_at = 0.0  # host time the line is free again
        self._busy = False  # the thread holds bytes it has read and not yet written
        self.m_server, self.s_server = os.openpty()
        self.m_client, self.s_client = os.openpty()
        for fd in (self.s_server, self.s_client):
            tty.setraw(fd)  # no echo or line editing before pyserial opens the slave
        self.server_path = os.ttyname(self.s_server)
        self.client_path = os.ttyname(self.s_client)
        self._silent_until = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="modbus-rtu-line", daemon=True)
        self._thread.start()

    def cut(self, seconds: float) -> None:
        """Drop every byte in both directions for ``seconds`` s."""
        self._silent_until = time.monotonic() + seconds

    def _run(self) -> None:
        peer = {self.m_server: self.m_client, self.m_client: self.m_server}
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select(list(peer), [], [], 0.1)
            except (OSError, ValueError):
                return
            for fd in ready:
                self._busy = True  # from here until written, the bytes are on the line
                try:
                    data = os.read(fd, 4096)
                except OSError:
                    self._busy = False
                    time.sleep(0.001)
                    continue
                if data and time.monotonic() >= self._silent_until:
                    if self._byte_s:
                        self._free_at = max(self._free_at, time.monotonic()) + len(data) * self._byte_s
                        time.sleep(max(0.0, self._free_at - time.monotonic()))
                    try:
                        os.write(peer[fd], data)
                    except OSError:
                        pass
                self._busy = False

    def _carrying(self) -> bool:
        """Whether bytes are still on their way (waiting to be copied, or being carried)."""
        if self._busy:
            return True
        try:
            ready, _, _ = select.select([self.m_server, self.m_client], [], [], 0)
        except (OSError, ValueError):
            return False
        return bool(ready)

    def drain(self, timeout: float = 1.0) -> None:
        """Wait (at most ``timeout`` s) until the bytes on their way are delivered: the server's
        last response (the end of the program, which the client stops on) may still be in the
        thread, carried at the line's rate."""
        deadline = time.monotonic() + timeout
        while self._carrying() and time.monotonic() < deadline:
            time.sleep(0.005)

    def close(self) -> None:
        self.drain()
        self._stop.set()
        self._thread.join(timeout=1.0)
        for fd in (self.m_server, self.s_server, self.m_client, self.s_client):
            try:
                os.close(fd)
            except OSError:
                pass


class ModbusEndpoint(Endpoint):
    """A simulated controller serving its samples over Modbus TCP or RTU (module docstring)."""

    name = "modbus"
    option_types = {"link": str, "port": int, "map": str, "unit": int, "mode": str, "baud": int,
                    "pace": bool, "capacity": int, "wait": float, "outage": float}

    def __init__(self, source: RealTimeSource, info: StreamInfo, options: dict[str, Any] | None = None) -> None:
        super().__init__(source, info, options)
        self.link = str(self.options.get("link", "tcp")).lower()
        if self.link not in ("tcp", "rtu"):
            raise InputError(f"modbus endpoint: link={self.link!r}; use tcp or rtu")
        self.mode = str(self.options.get("mode", "trace")).lower()
        if self.mode not in ("trace", "live"):
            raise InputError(f"modbus endpoint: mode={self.mode!r}; use trace or live")
        self.wait_s = float(self.options.get("wait", 30.0))
        self.outage_s = float(self.options.get("outage", 1.0))
        self.baud = int(self.options.get("baud", 115200))
        if self.baud <= 0:
            raise InputError(f"modbus endpoint: baud={self.baud}; use a positive line rate (bit/s)")
        self.pace = bool(self.options.get("pace", False))
        if self.pace and self.link != "rtu":
            raise InputError("modbus endpoint: pace=true paces a serial line's bytes; use it with link=rtu")
        map_path = self.options.get("map")
        if map_path:
            self.rmap = load_map(map_path)
            missing = [a for a in self.rmap.axis_names if a not in source.axes]
            if missing:
                raise MachineError(f"register map {map_path}: axis {missing[0]!r} is not in the program "
                                   f"(axes: {', '.join(source.axes)})")
        else:
            units = list(info.units) if info.units else None
            self.rmap = default_map(source.axes, sample_period_s=info.sample_period, units=units)
        if "unit" in self.options:
            from dataclasses import replace
            self.rmap = replace(self.rmap, unit=int(self.options["unit"]))
        W = self.rmap.record_words
        base = self.rmap.trace.base if self.rmap.trace else 65536
        self.capacity = int(self.options.get("capacity", min(MAX_DEFAULT_CAPACITY, (65536 - base) // W)))
        if self.rmap.trace is not None and not 1 <= self.capacity <= 65535:
            raise InputError(f"modbus endpoint: capacity={self.capacity}; use 1..65535 records")
        self.records = encode_records(source, self.rmap)
        self.image = RegisterImage(self.rmap, self.capacity, "exception" if self.link == "tcp" else "crc")
        self.image.set_info(self._info_text())
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._server = None
        self._line: _PtyLine | None = None
        self._port: int | None = None
        self.disconnects = 0

    def _info_text(self) -> dict[str, Any]:
        return {
            "controller": self.info.controller or "rapid-ident virtual CNC",
            "axes": ",".join(self.rmap.axis_names),
            "period_s": repr(self.info.sample_period),
            "program": [f"{p.get('name', '')} {p.get('sha256', '')}".strip() for p in self.info.programs],
        }

    # -- life cycle -------------------------------------------------------------------------
    def start(self) -> None:
        if self.link == "rtu":
            self._line = _PtyLine(self.baud if self.pace else None)
        ready = threading.Event()
        errors: list[BaseException] = []

        def run_loop() -> None:
            loop = asyncio.new_event_loop()
            self._loop = loop
            asyncio.set_event_loop(loop)
            try:
                loop.run_until_complete(self._start_server())
            except BaseException as exc:  # reported to start()
                errors.append(exc)
                ready.set()
                loop.close()
                return
            ready.set()
            loop.run_forever()
            loop.run_until_complete(self._stop_server())
            loop.close()

        self._thread = threading.Thread(target=run_loop, name="modbus-server", daemon=True)
        self._thread.start()
        if not ready.wait(10.0) or errors:
            cause = errors[0] if errors else "timed out"
            raise TransportError(f"modbus endpoint: the {self.link} server did not start ({cause})")

    async def _start_server(self) -> None:
        img = self.image
        if self.link == "tcp":
            port = int(self.options.get("port", 0))
            self._server = ModbusTcpServer(img, address=("127.0.0.1", port), framer=FramerType.SOCKET,
                                           trace_packet=img.trace_packet, trace_pdu=img.trace_pdu)
            await self._server.serve_forever(background=True)
            self._port = self._server.transport.sockets[0].getsockname()[1]
        else:
            assert self._line is not None
            self._server = ModbusSerialServer(img, port=self._line.server_path, framer=FramerType.RTU,
                                              baudrate=self.baud, ignore_missing_devices=True,
                                              trace_packet=img.trace_packet, trace_pdu=img.trace_pdu)
            await self._server.serve_forever(background=True)

    async def _stop_server(self) -> None:
        if self._server is not None:
            await self._server.shutdown()

    def port_url(self) -> str:
        query = f"mode={self.mode}&unit={self.rmap.unit}"
        if self.options.get("map"):
            query += f"&map={self.options['map']}"
        if self.link == "tcp":
            if self._port is None:
                raise RuntimeError("port_url() before start()")
            return f"modbus-tcp://127.0.0.1:{self._port}?{query}"
        assert self._line is not None
        return f"modbus-rtu://{self._line.client_path}?baud={self.baud}&{query}"

    def serve_ticks(self) -> None:
        src = self.source
        # A controller's trace runs regardless of a client; here the program starts with the
        # first request (or after `wait` s) so that a capture started a moment later sees tick 0.
        deadline = time.monotonic() + self.wait_s
        while not self.image.first_request.is_set() and not self.stop_event.is_set():
            if time.monotonic() >= deadline:
                break
            self.image.first_request.wait(0.05)
        disconnect_at = src.faults.disconnect_at_s
        # batches() starts its clock at the first step; the live registers use the same origin
        self.image.start_clock(time.monotonic(), src.speed, src.recording.sample_period, self.records,
                               src.dropped, src.corrupted)
        for ticks, t in src.batches():
            if self.stop_event.is_set():
                return
            k = np.arange(ticks.start, ticks.stop)
            self.image.publish(self.records[k], src.counter[k], src.dropped[k], src.corrupted[k])
            self.note_sent(int(src.counter[k[-1]]))
            if disconnect_at is not None and t >= disconnect_at:
                disconnect_at = None
                self.disconnect()
        self.image.set_ended()

    def linger(self) -> None:
        """Keep serving ``linger`` s after the program -- longer (at most 60 s more) while a client is
        still reading (a request within the last 2 s) and has not yet read every trace record and
        the end-of-program status."""
        t_end = time.monotonic() + self.linger_s
        t_max = t_end + 60.0
        last = int(self.source.counter[-1]) + 1 if self.source.n else 0
        img = self.image
        while not self.stop_event.is_set():
            now = time.monotonic()
            active = now - img.last_request < 2.0
            done = img.end_seen_after is not None and (self.mode != "trace" or self.rmap.trace is None
                                                       or img.end_seen_after >= last)
            if now >= t_max or (now >= t_end and (done or not active)):
                return
            self.stop_event.wait(0.05)

    def disconnect(self) -> None:
        """Break the link once: TCP closes every client connection (still listening); RTU goes silent."""
        self.disconnects += 1
        if self.link == "rtu":
            assert self._line is not None
            self._line.cut(self.outage_s)
            return
        loop, server = self._loop, self._server

        def drop_all() -> None:
            for conn in list(server.active_connections.values()):
                conn.close()

        if loop is not None and server is not None:
            loop.call_soon_threadsafe(drop_all)

    def _close(self) -> None:
        if self._line is not None:
            self._line.drain()  # before the server stops: its last response may be on the line
        if self._loop is not None and self._thread is not None:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout=5.0)
        if self._line is not None:
            self._line.close()

    def report(self) -> dict[str, Any]:
        """Base report plus the Modbus side: requests by function code, damaged responses, disconnects."""
        out = super().report()
        out.update({"function_codes": {str(k): v for k, v in sorted(self.image.function_codes.items())},
                    "corrupted_responses": self.image.corrupted_responses, "disconnects": self.disconnects,
                    "link": self.link, "trace_capacity": self.capacity})
        return out

    # -- for tests ---------------------------------------------------------------------------
    @property
    def function_codes(self) -> dict[int, int]:
        """Requests received so far by function code (the capture must send only 3/4)."""
        return dict(self.image.function_codes)

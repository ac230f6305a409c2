"""Modbus driver (TCP and RTU, pymodbus 3.x): live polling or trace-buffer upload.

URLs (SPEC §3)::

    modbus-tcp://127.0.0.1:5020?mode=trace&unit=1&map=controller.toml
    modbus-rtu:///dev/ttyUSB0?baud=115200&unit=1&mode=live

Options: ``mode`` trace|live (default trace when the map has a trace block), ``map``
register-map TOML (default: the built-in layout of :func:`drivers.modbus_map.default_map`,
axes taken from the controller's info block), ``unit`` Modbus unit id, ``timeout`` s per
request (default 0.3), ``reconnect_s`` s to keep trying after the link is lost before
giving up (default 10), ``poll_ms`` pause between trace-buffer polls (default 10 ms),
``baud``, ``parity`` (N/E/O), ``stopbits`` (RTU), ``retries`` per read before it is an
error (default 5).

Passive (SPEC §8): the only requests this driver sends are reads -- FC 3 (read holding
registers) or FC 4 (read input registers), whichever the map's table is.  A guard on the
client's outgoing PDUs (:func:`_read_only_guard`) refuses any other function code, so no
code path (nor a later change) can write a register through this driver.

Modes
-----
*trace* (how 1 kHz data gets through Modbus): the controller appends a record
(counter, segment, positions) per sample tick to a ring buffer.  Each poll reads the
status and head registers, then the records from the last counter read up to the head in
as few requests as the 125-register limit allows (``floor(125 / record_words)`` records
per request, split at the ring's end).  Every record carries its counter: a slot still
holding an older or already a newer counter means that tick is missing (the controller
dropped it, or the ring overran while we were away) and it is skipped; if the head ran
more than a ring ahead, the overwritten records are skipped.  Missing ticks show as gaps
in the counter of the samples returned, which is how the capture loop counts them as
dropped (``stats.dropped`` stays 0 so nothing is counted twice; :attr:`ModbusDriver.gaps`
has the driver's own count).  After a reconnect the upload continues where it stopped,
so a short outage loses nothing that is still in the ring.  A read uploads for at most its
timeout and leaves the rest of a backlog to the next.  While the controller runs, the head
read with its host time is :attr:`~drivers.base.Driver.newest`: a slow line makes the reader
fall behind the ring, and the capture's clock check then judges the controller's clock by the
head, not by when the records arrive.

*live*: each poll reads status, counter and positions in one request (the default layout
keeps them contiguous).  A counter that moved by more than one tick since the previous
poll leaves a gap (ticks the poller never saw, counted as dropped by the capture).  A
counter that went back is handed over as read, for the capture loop to tell a restart;
the first :data:`LIVE_ORDER_SAMPLES` counters are checked for the other word order.  Polls
whose status says neither running nor ended are not samples (:attr:`idle_polls`); a
capture that sees only those says so (:meth:`unusable_reason`).  A
poll is a request/response round trip scheduled by two
processes, so polling never sees every 1 kHz tick (how many it sees depends on the
machine's load: benchmarks/bench_capture.py --transport modbus measures it); over a real RS-485 line at
115200 baud a poll of 6 axes takes ~8 ms.  Use trace mode for identification.

The register map file is loaded and checked when the driver is made, before any
connection is tried.

Errors: a Modbus exception 4 (server device failure) or 8 (memory parity error), a frame
with a bad CRC (RTU) or a response of the wrong length is rejected, counted in
``stats.corrupt`` and the read is retried; exception 5/6 (acknowledge/busy) is retried
after a short pause; other exceptions (1 illegal function, 2 illegal address, ...) mean the
register map does not fit the controller and end the capture with a one-line
TransportError.  A lost connection (TCP closed, or RTU silent for several timeouts) is
re-established with exponential backoff (50 ms doubling to 1 s); each recovery counts in
``stats.reconnects``; after ``reconnect_s`` without success a TransportError says so.
Trace records that hold none of their counters from the start of the capture (the first
:data:`MISMATCH_LIMIT` written ones) mean the map does not fit the controller: a
:class:`~core.errors.StreamError` names the word order to set when the records fit the
other one, else the trace fields to check.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException
from pymodbus.framer import FramerType
from pymodbus.framer.rtu import FramerRTU

from core.errors import InputError, MachineError, StreamError, TransportError
from drivers.base import Driver, Sample, StreamInfo
from drivers.modbus_map import (
    STATUS_ENDED,
    STATUS_RUNNING,
    RegisterMap,
    decode_info,
    decode_u32,
    default_map,
    load_map,
    plan_reads,
)
from drivers.scaling import counts_per_unit
from drivers.url import PortURL

__all__ = ["ModbusDriver", "ALLOWED_FUNCTION_CODES", "ReadOnlyViolation"]

logging.getLogger("pymodbus").addHandler(logging.NullHandler())

#: the only Modbus function codes this driver may send: read coils, read discrete inputs,
#: read holding registers, read input registers
ALLOWED_FUNCTION_CODES = frozenset({1, 2, 3, 4})

_EXC_NAMES = {1: "illegal function", 2: "illegal data address", 3: "illegal data value",
              4: "server device failure", 5: "acknowledge", 6: "server device busy",
              8: "memory parity error", 10: "gateway path unavailable", 11: "gateway target failed to respond"}
#: written trace records read from the start of a capture, none holding its counter, after which
#: the map cannot fit the controller (a controller that drops ticks still writes most of them)
MISMATCH_LIMIT = 32
#: live counters read before the word-order check judges them
LIVE_ORDER_SAMPLES = 8
_CORRUPT_EXC = {4, 8}  # the data could not be delivered intact this time: retry
_BUSY_EXC = {5, 6}


class ReadOnlyViolation(TransportError):
    """Something tried to send a Modbus request that is not a read (capture is passive)."""


class _BadFrame(Exception):
    """An RTU response whose CRC does not match (raised from the packet hook to skip pymodbus' wait)."""


def _read_only_guard(sending: bool, pdu):
    """pymodbus ``trace_pdu`` hook: refuse to send any request that is not a read."""
    if sending and pdu.function_code not in ALLOWED_FUNCTION_CODES:
        raise ReadOnlyViolation(
            f"refused to send Modbus function code {pdu.function_code}: capture only reads (FC 1-4)")
    return pdu


class ModbusDriver(Driver):
    """Capture commanded/actual positions from a Modbus TCP or RTU controller (module docstring)."""

    schemes = ("modbus-tcp", "modbus-rtu")
    options = {"mode": str, "map": str, "unit": int, "timeout": float, "reconnect_s": float, "poll_ms": float,
               "baud": int, "parity": str, "stopbits": int, "retries": int}

    def __init__(self, url: PortURL, axes: list[str] | None = None) -> None:
        super().__init__(url, axes)
        self.timeout = url.option("timeout", float, 0.3)
        self.reconnect_s = url.option("reconnect_s", float, 10.0)
        self.poll_s = url.option("poll_ms", float, 10.0) / 1000.0
        self.retries = url.option("retries", int, 5)
        self.unit_option = url.option("unit", int)
        self.mode_option = url.option("mode", str)
        self.map_path = url.option("map", str)
        if self.unit_option is not None and not 0 <= self.unit_option <= 247:
            raise InputError.about("port", f"{url.raw}: unit={self.unit_option}; a Modbus unit id is 0..247")
        if self.mode_option is not None and self.mode_option not in ("trace", "live"):
            raise InputError.about("port", f"{url.raw}: mode={self.mode_option!r}; use trace or live")
        for name, value in (("timeout", self.timeout), ("reconnect_s", self.reconnect_s)):
            if not value > 0:
                raise InputError.about("port", f"{url.raw}: {name}={value} must be > 0 s")
        if url.scheme == "modbus-tcp" and not url.host:
            raise InputError.about("port", f"{url.raw}: no host; use modbus-tcp://HOST:PORT")
        if url.scheme == "modbus-rtu" and not url.path:
            raise InputError.about("port", f"{url.raw}: no device; use modbus-rtu:///dev/ttyUSB0?baud=115200")
        # Every input is checked before the network is touched: the register map file too.
        self._map_file = load_map(Path(self.map_path)) if self.map_path else None
        if self._map_file is not None:
            self._check_axes(self._map_file)
            if self.mode_option == "trace" and self._map_file.trace is None:
                raise InputError.about("port", f"{url.raw}: mode=trace but register map {self._map_file.source} "
                                               f"has no [trace] block")
        self.rmap: RegisterMap | None = None
        #: extra counts beyond CaptureStats: ticks missing (counter gaps; the capture loop counts
        #: these as dropped, so stats.dropped stays 0), timeouts, busy answers, requests sent
        self.gaps = 0
        self.timeouts = 0
        self.busy = 0
        self.requests = 0
        self._client = self._make_client()
        self._down_since: float | None = None  # monotonic time the link was found lost
        self._next: int | None = None  # trace: unwrapped counter of the next record to read
        self._overran = False  # trace: the ring overran once (said once, in :attr:`notices`)
        self._overtaken = False  # trace: a lapped record was read since the head was last read
        self._last_live: int | None = None  # live: unwrapped counter of the last sample seen
        self._deferred_error: TransportError | None = None
        self._matched_any = False  # some trace record held its counter: the layout fits
        self._unmatched: list[tuple[np.ndarray, np.ndarray]] = []  # (counters, records) read before a match
        self.idle_polls = 0  # live: polls whose status did not say running (nothing valid to record)
        self._last_status = 0
        self._live_words: list[tuple[int, int]] = []  # live: counter register pairs of the first samples

    def _check_axes(self, rmap: RegisterMap) -> None:
        """``--axes`` must name axes of the map (known before connecting when a map file is given)."""
        names = list(rmap.axis_names)
        unknown = [a for a in (self.wanted_axes or []) if a not in names]
        if unknown:
            raise InputError.about("axes", f"the controller has no axis {unknown[0]!r} (axes: {', '.join(names)})")

    # -- connection ---------------------------------------------------------------------------
    def _make_client(self):
        url = self.url
        if url.scheme == "modbus-tcp":
            return ModbusTcpClient(url.host, port=url.port or 502, timeout=self.timeout, retries=0,
                                   trace_pdu=_read_only_guard)
        parity = url.option("parity", str, "N").upper()
        if parity not in ("N", "E", "O"):
            raise InputError.about("port", f"{url.raw}: parity={parity!r}; use N, E or O")
        stopbits = url.option("stopbits", int, 1)
        if stopbits not in (1, 2):
            raise InputError.about("port", f"{url.raw}: stopbits={stopbits}; use 1 or 2")
        baud = url.option("baud", int, 115200)
        client = ModbusSerialClient(url.path, framer=FramerType.RTU, baudrate=baud,
                                    parity=parity, stopbits=stopbits, timeout=self.timeout, retries=0,
                                    trace_pdu=_read_only_guard, trace_packet=self._check_crc)
        # pymodbus polls for the answer every >= 1 ms, which caps a fast line (or a pty) at ~200
        # requests/s; poll every 4 character times instead (0.2 ms at least).
        if hasattr(client, "_recv_interval"):
            client._recv_interval = max(4 * 11 / baud, 0.0002)
        return client

    def _check_crc(self, sending: bool, data: bytes) -> bytes:
        """pymodbus ``trace_packet`` hook (RTU): reject a complete response frame with a bad CRC.

        pymodbus itself silently drops such a frame and waits for the timeout; raising here
        lets the driver count it and retry at once.
        """
        if sending or len(data) < 5:
            return data
        fc = data[1]
        if fc & 0x80:
            size = 5
        elif fc in (3, 4, 1, 2):
            size = 5 + data[2]
        else:
            return data
        if len(data) < size:
            return data  # not complete yet
        crc = (data[size - 2] << 8) | data[size - 1]
        if not FramerRTU.check_CRC(data[:size - 2], crc):
            raise _BadFrame()
        return data

    def _connect(self) -> bool:
        try:
            return bool(self._client.connect())
        except Exception:  # pyserial raises assorted errors for a missing device
            return False

    def _link_lost(self, why: str) -> None:
        """Close, then reconnect with backoff until ``reconnect_s`` has passed since the loss."""
        now = time.monotonic()
        if self._down_since is None:
            self._down_since = now
        delay = 0.05
        attempts = 0
        while True:
            self._client.close()
            attempts += 1
            if self._connect():
                return  # counted as a reconnect once a read succeeds again
            if time.monotonic() - self._down_since >= self.reconnect_s:
                raise TransportError(
                    f"{self.url.raw}: connection lost ({why}) and not re-established within "
                    f"{self.reconnect_s:g} s ({attempts} attempts)")
            time.sleep(delay)
            delay = min(2 * delay, 1.0)

    def _read_registers(self, address: int, count: int) -> np.ndarray:
        """One FC 3/4 read of ``count`` registers as uint16, with retries, corrupt counting, reconnects."""
        assert self.rmap is not None
        unit = self.rmap.unit
        read = (self._client.read_holding_registers if self.rmap.table == "holding"
                else self._client.read_input_registers)
        failures = 0
        while True:
            if self._down_since is not None and time.monotonic() - self._down_since >= self.reconnect_s:
                raise TransportError(f"{self.url.raw}: no answer from the controller for "
                                     f"{self.reconnect_s:g} s (registers {address}..{address + count - 1})")
            self.requests += 1
            try:
                rr = read(address, count=count, device_id=unit)
            except _BadFrame:
                self.stats.corrupt += 1
                failures += 1
                self._check_failures(failures, address, count, "bad CRC")
                continue
            except ReadOnlyViolation:
                raise
            except ConnectionException:
                self._link_lost("the controller closed the connection" if self.url.scheme == "modbus-tcp"
                                else "the serial port failed")
                continue
            except (ModbusException, OSError):  # no (complete) answer within the timeout
                self.timeouts += 1
                failures += 1
                if self.url.scheme == "modbus-tcp" and not self._client.connected:
                    self._link_lost(f"no answer within {self.timeout:g} s")
                    continue
                if failures >= 2:  # silent for two timeouts in a row: treat the link as lost
                    if self._down_since is None:
                        self._down_since = time.monotonic()
                    if self.url.scheme == "modbus-tcp":
                        self._link_lost(f"no answer within {self.timeout:g} s")
                continue
            if rr.isError():
                code = getattr(rr, "exception_code", 0)
                if code in _CORRUPT_EXC:
                    self.stats.corrupt += 1
                    failures += 1
                    self._check_failures(failures, address, count, _EXC_NAMES[code])
                    continue
                if code in _BUSY_EXC:
                    self.busy += 1
                    failures += 1
                    self._check_failures(failures, address, count, _EXC_NAMES[code])
                    time.sleep(0.002)
                    continue
                fc = self.rmap.function_code
                raise TransportError(
                    f"{self.url.raw}: controller answered exception {code} ({_EXC_NAMES.get(code, 'unknown')}) "
                    f"to FC {fc} registers {address}..{address + count - 1} (unit {unit}); check the register map "
                    f"{self.rmap.source}")
            regs = getattr(rr, "registers", None)
            if regs is None or len(regs) != count:
                self.stats.corrupt += 1  # wrong length: a format check failed
                failures += 1
                self._check_failures(failures, address, count, "wrong response length")
                continue
            if self._down_since is not None:
                self._down_since = None
                self.stats.reconnects += 1
            return np.asarray(regs, dtype=np.uint16)

    def _check_failures(self, failures: int, address: int, count: int, why: str) -> None:
        if failures > self.retries:
            raise TransportError(f"{self.url.raw}: registers {address}..{address + count - 1}: "
                                 f"{failures} bad answers in a row (last: {why})")

    def _read_span(self, spans: list[tuple[int, int]]) -> np.ndarray:
        return np.concatenate([self._read_registers(a, n) for a, n in spans])

    # -- Driver interface -------------------------------------------------------------------
    def _open(self) -> StreamInfo:
        try:
            return self._open_stream()
        except BaseException:
            self._client.close()
            raise

    def _open_stream(self) -> StreamInfo:
        if not self._connect():
            where = self.url.path if self.url.scheme == "modbus-rtu" else f"{self.url.host}:{self.url.port or 502}"
            raise TransportError(f"{self.url.raw}: cannot connect to {where}")
        rmap = self._map_file
        base = rmap or default_map(["X"])  # the info block is at the same place in any default layout
        if self.unit_option is not None:
            base = replace(base, unit=self.unit_option)
        self.rmap = base
        info: dict = {}
        if base.info_address is not None:
            info = decode_info(self._read_span(plan_reads([(base.info_address, base.info_length)], base.max_registers, 0)))
        if rmap is None:
            axes = [a for a in str(info.get("axes", "")).split(",") if a]
            if not axes:
                raise TransportError(f"{self.url.raw}: the controller's info block names no axes; "
                                     f"give the register map with map=FILE.toml")
            period = float(info.get("period_s", base.sample_period_s))
            rmap = default_map(axes, sample_period_s=period)
            if self.unit_option is not None:
                rmap = replace(rmap, unit=self.unit_option)
            self.rmap = rmap
        elif "axes" in info and info["axes"].split(",") != list(rmap.axis_names):
            raise MachineError(f"register map {rmap.source} has axes {','.join(rmap.axis_names)} but the "
                               f"controller reports {info['axes']}")
        period = float(info.get("period_s", rmap.sample_period_s))
        self.mode = self.mode_option or ("trace" if rmap.trace is not None else "live")
        if self.mode == "trace" and rmap.trace is None:
            raise InputError.about("port", f"{self.url.raw}: mode=trace but register map {rmap.source} has no [trace] block")
        names = list(rmap.axis_names)
        self._check_axes(rmap)
        # Every axis is decoded; the capture loop keeps the --axes it wants.
        self._cols = list(range(len(names)))
        self._per_unit = np.array([counts_per_unit(rmap.axes[i].scale_mm) for i in self._cols])
        self.period = period
        self._prepare_decoders(rmap)
        extra = {"transport": self.url.scheme, "mode": self.mode, "unit": rmap.unit,
                 "register_map": rmap.source, "function_codes_sent": sorted({rmap.function_code})}
        if self.mode == "trace":
            hdr = self._read_header()
            self.capacity = hdr[2]
            if self.capacity < 1:
                raise TransportError(f"{self.url.raw}: trace buffer capacity register reads 0")
            extra["trace_capacity"] = self.capacity
        programs = []
        for entry in info.get("program", []):
            # "<name> <sha256>": a name may hold spaces ("low speed.nc"), a SHA-256 cannot
            name, _, sha = entry.rpartition(" ") if " " in entry else (entry, "", "")
            programs.append({"name": name, "sha256": sha})
        return StreamInfo(axes=tuple(names), sample_period=period,
                          controller=str(info.get("controller", f"Modbus unit {rmap.unit}")),
                          units=tuple(rmap.axes[i].unit for i in self._cols), programs=tuple(programs),
                          extra=extra)

    def _prepare_decoders(self, rmap: RegisterMap) -> None:
        # trace record columns
        W = rmap.record_words
        self._W = W
        self._per_read = max(1, rmap.max_registers // W)
        orders = [rmap.axes[i].word_order for i in self._cols]
        self._rec_cols = [(3 + 4 * i, 5 + 4 * i) for i in self._cols]
        self._orders = orders
        # header: status + head + capacity
        if rmap.trace is not None:
            self._hdr_spans = plan_reads([(rmap.status, 1), (rmap.trace.head, 2), (rmap.trace.capacity, 1)],
                                         rmap.max_registers)
        # live: status, counter, segment, positions
        fields = [(a, w) for _, a, w, _ in rmap.live_fields()]
        self._live_spans = plan_reads(fields, rmap.max_registers)

    def _at(self, spans: list[tuple[int, int]], address: int) -> int:
        """Index of ``address`` in the concatenation of ``spans``."""
        off = 0
        for a, n in spans:
            if a <= address < a + n:
                return off + address - a
            off += n
        raise KeyError(address)

    def _read_header(self) -> tuple[int, int, int]:
        """(status, head u32, capacity) of the trace buffer."""
        rmap = self.rmap
        assert rmap is not None and rmap.trace is not None
        regs = self._read_span(self._hdr_spans)
        s = int(regs[self._at(self._hdr_spans, rmap.status)])
        h = self._at(self._hdr_spans, rmap.trace.head)
        head = int(decode_u32(regs[h], regs[h + 1], rmap.word_order, signed=False))
        cap = int(regs[self._at(self._hdr_spans, rmap.trace.capacity)])
        return s, head, cap

    def _read(self, timeout: float) -> list[Sample]:
        if self._deferred_error is not None:
            exc, self._deferred_error = self._deferred_error, None
            raise exc
        if self.mode == "trace":
            return self._read_trace(timeout)
        return self._read_live(timeout)

    def _close(self) -> None:
        self._client.close()

    # -- trace mode ----------------------------------------------------------------------------
    def _unwrap(self, u32: int, ref: int) -> int:
        """The unwrapped counter nearest above ``ref - 2**31`` whose low 32 bits are ``u32``."""
        return ref + ((u32 - ref + (1 << 31)) % (1 << 32)) - (1 << 31)

    def _read_trace(self, timeout: float) -> list[Sample]:
        deadline = time.monotonic() + timeout
        out: list[Sample] = []
        while True:
            status, head_u32, _ = self._read_header()
            read_at = time.monotonic()
            if self._next is None:
                # First poll: upload what the ring still holds (a trace started before the capture).
                self._next = head_u32 - min(head_u32, self.capacity)
            head = self._unwrap(head_u32, self._next)
            if status & STATUS_RUNNING and not status & STATUS_ENDED and head > 0:
                self.newest = (head - 1, read_at)  # the head moves with the controller's clock
            pending = head - self._next
            if pending < 0:
                raise TransportError(f"{self.url.raw}: the trace head went back from counter {self._next} to "
                                     f"{head}: the controller restarted its trace; start a new capture")
            # Records overwritten before we could read them (an outage, a slow link): resume at the
            # oldest record the ring still holds -- or, once the controller has overtaken the reader
            # (a lapped record was read), at the newest, the one furthest from being overwritten:
            # from the oldest a slower reader reads little but lapped records.
            keep = 1 if self._overtaken else self.capacity
            self._overtaken = False
            if pending > keep:
                lost = pending - keep
                if not self._overran:
                    self._overran = True
                    self.notices.append(
                        f"the controller's trace ring ({self.capacity} records) overran at counter {self._next}: "
                        f"the capture fell more than the ring's {self.capacity * self.period:g} s behind, in an "
                        f"outage or on a link that carries fewer records than the controller writes "
                        f"({1 / self.period:g} a second); it resumes at the oldest record still in the ring, or "
                        f"at the newest once the controller overtakes it, and counts the records lost as "
                        f"dropped (a faster link, fewer axes in the map or a larger ring keep up)")
                self.gaps += lost
                self._next += lost
                pending = keep
            if pending > 0:
                out += self._upload(self._next, head, deadline)
                # Return after one pass so the caller writes and shows progress regularly.
                if out or time.monotonic() >= deadline:
                    return out
                continue
            if status & STATUS_ENDED:
                self.ended = True
                return out
            if time.monotonic() >= deadline:
                return out
            time.sleep(min(self.poll_s, max(0.0, deadline - time.monotonic())))

    def _upload(self, first: int, head: int, deadline: float) -> list[Sample]:
        """Read records ``first .. head-1`` in as few requests as possible; decode; advance.

        Stops at ``deadline`` (host monotonic s) after at least one request, the rest left for
        the next read: over a slow line a backlog takes seconds, and the caller must write,
        flush and show progress meanwhile.
        """
        rmap = self.rmap
        assert rmap is not None and rmap.trace is not None
        W, cap, base = self._W, self.capacity, rmap.trace.base
        samples: list[Sample] = []
        c = first
        while c < head and not (samples and time.monotonic() >= deadline):
            slot = c % cap
            k = min(self._per_read, head - c, cap - slot)  # a request never crosses the ring's end
            try:
                regs = self._read_registers(base + slot * W, k * W)
            except TransportError as exc:
                if not samples:
                    raise
                # Hand over what was read; the failure is raised by the next read().
                self._deferred_error = exc
                break
            samples += self.decode_records(c, regs.reshape(k, W))
            c += k
            self._next = c
            if self._overtaken:  # the rest is being overwritten as we read: re-read the head
                break
        self.stats.received += len(samples)
        return samples

    def decode_records(self, c0: int, rec: np.ndarray) -> list[Sample]:
        """Trace records read for counters ``c0, c0+1, ...`` (uint16, shape (k, record_words)) -> Samples.

        A record whose own counter is not the expected one (stale or overwritten slot) is
        skipped and counted in :attr:`gaps` and, unless a later lap overwrote it (then the
        controller has overtaken the reader, :meth:`_read_trace` resumes at the newest
        record), in ``stats.skipped``; if the first
        :data:`MISMATCH_LIMIT` records of the capture all are, the map does not fit the
        controller and a :class:`StreamError` says which field to check.  Positions:
        ``count / counts_per_unit(scale_mm)`` (drivers.scaling).
        """
        k = rec.shape[0]
        expect = np.arange(c0, c0 + k)
        got = decode_u32(rec[:, 0], rec[:, 1], self.rmap.word_order, signed=False)
        ok = got == (expect & 0xFFFFFFFF)
        self.gaps += int(k - ok.sum())  # stale (never written) or already overwritten slots
        # A lapped record (a ring newer than expected) is a record lost to an overrun, not one
        # that cannot be used: the map read it right.
        laps = self._laps(got, expect)
        own_slot = laps % self.capacity == 0  # stale (ring older), right, or lapped (ring newer)
        lapped = own_slot & (laps > 0)
        self._overtaken |= bool(lapped.any())
        self.stats.skipped += int((~ok & ~lapped).sum())
        if not self._matched_any:
            if ok.any():
                self._matched_any = True
                self._unmatched.clear()
            else:
                # Evidence of a map that does not fit is a record that does not belong in its
                # slot at all: an empty slot (0, a ring read beyond what was written, as a
                # misread head makes the driver do), a stale one (counter - k x capacity: the
                # controller skipped that tick) or one lapped since the head was read
                # (counter + k x capacity) are what a fitting map also reads.
                foreign = (got != 0) & ~own_slot
                self._unmatched.append((expect[foreign], rec[foreign]))
                n = sum(len(e) for e, _ in self._unmatched)
                if n >= MISMATCH_LIMIT:
                    raise StreamError(f"{self.url.raw}: {n} trace records read, none holding "
                                      f"its counter: {self.unusable_reason()}")
        if not ok.any():
            return []
        rec = rec[ok]
        counters = expect[ok]
        seg = rec[:, 2].astype(np.int64)
        cmd = np.column_stack([decode_u32(rec[:, a], rec[:, a + 1], o, True)
                               for (a, _), o in zip(self._rec_cols, self._orders)]) / self._per_unit
        act = np.column_stack([decode_u32(rec[:, b], rec[:, b + 1], o, True)
                               for (_, b), o in zip(self._rec_cols, self._orders)]) / self._per_unit
        T = self.period
        return [Sample(cnt, cnt * T, tuple(cm), tuple(ac), sg)
                for cnt, sg, cm, ac in zip(counters.tolist(), seg.tolist(), cmd.tolist(), act.tolist())]

    @staticmethod
    def _laps(got: np.ndarray, expect: np.ndarray) -> np.ndarray:
        """How many counters each 32-bit counter ``got`` is ahead of ``expect`` (negative: behind),
        the nearer way round the 32-bit wrap; a whole number of rings when ``got`` belongs in
        the slot of ``expect``."""
        return (got.astype(np.int64) - expect + (1 << 31)) % (1 << 32) - (1 << 31)

    def unusable_reason(self) -> str:
        if getattr(self, "mode", None) == "live":
            if self.idle_polls and not self.stats.received and self.rmap is not None:
                return (f"the status register (address {self.rmap.status} of register map {self.rmap.source}) "
                        f"never said running (bit 0) or ended (bit 1) in {self.idle_polls} polls (last read "
                        f"0x{self._last_status:04x}); check [status] address, or is the program started?")
            return ""
        if not self.stats.received and not self.stats.skipped and self.rmap is not None and self.rmap.trace:
            return (f"the trace head (address {self.rmap.trace.head} of register map {self.rmap.source}) did "
                    f"not advance: the controller wrote no trace record; is the program started?")
        if self._matched_any or not self._unmatched:
            return "trace slots did not hold the counters expected in them (ticks the controller did not write)"
        expect = np.concatenate([e for e, _ in self._unmatched])
        if not len(expect):
            return "the trace slots read were empty or held older records; the head register may be misread"
        return self._explain_mismatch(expect, np.concatenate([r for _, r in self._unmatched]))

    def _explain_mismatch(self, expect: np.ndarray, rec: np.ndarray) -> str:
        """Why trace records read from slots ``expect % capacity`` hold none of their counters.

        The slot a record was read from is known whatever the head said, so a record of
        counter c written low word first (or high word first) shows by sitting in slot
        c mod capacity once decoded in the other word order.
        """
        rmap = self.rmap
        assert rmap is not None and rmap.trace is not None
        where = (f"in [device] of register map {rmap.source}" if rmap.source != "default"
                 else "in a register map (map=FILE.toml; the default layout is high word first)")
        slots = expect % self.capacity
        other = "little" if rmap.word_order == "big" else "big"
        got = decode_u32(rec[:, 0], rec[:, 1], rmap.word_order, signed=False)
        alt = decode_u32(rec[:, 0], rec[:, 1], other, signed=False)
        if np.all(alt % self.capacity == slots):
            i = 0
            first = "low" if other == "little" else "high"
            return (f"they do in \"{other}\" word order (slot {int(slots[i])} holds counter {int(alt[i])}, "
                    f"not {int(got[i])}): the controller writes 32-bit values {first} word first; "
                    f"set word_order = \"{other}\" {where}")
        return (f"slot {int(slots[0])} holds {int(got[0])} where counter {int(expect[0])} was expected: "
                f"trace.base = {rmap.trace.base}, the capacity register ({self.capacity} slots), "
                f"device.word_order = \"{rmap.word_order}\" or the record layout of register map "
                f"{rmap.source} do not match the controller (docs/modbus.md, Trace record)")

    def _check_live_word_order(self, first: int, second: int) -> None:
        """Stop when the first live counters only make sense in the other word order.

        Read in the wrong order, counter c of a controller below 65536 ticks decodes as
        c x 65536: successive polls step by whole multiples of 65536, a clock running 65536
        times too fast.  The other order then gives small forward steps.
        """
        words = self._live_words
        if len(words) >= LIVE_ORDER_SAMPLES:
            return
        words.append((first, second))
        if len(words) < LIVE_ORDER_SAMPLES:
            return
        rmap = self.rmap
        assert rmap is not None
        a = np.array([w[0] for w in words], dtype=np.uint16)
        b = np.array([w[1] for w in words], dtype=np.uint16)
        other = "little" if rmap.word_order == "big" else "big"
        steps = np.diff(decode_u32(a, b, rmap.word_order, signed=False).astype(np.int64))
        alt = np.diff(decode_u32(a, b, other, signed=False).astype(np.int64))
        if np.all(np.abs(steps) >= 1 << 16) and np.all((alt > 0) & (alt < 1 << 16)):
            first_word = "low" if other == "little" else "high"
            where = (f"in [device] of register map {rmap.source}" if rmap.source != "default"
                     else "in a register map (map=FILE.toml; the default layout is high word first)")
            raise StreamError(
                f"{self.url.raw}: the live sample counter steps by {int(np.median(np.abs(steps)))} per poll in "
                f"\"{rmap.word_order}\" word order but by {int(np.median(alt))} in \"{other}\": the controller "
                f"writes 32-bit values {first_word} word first; set word_order = \"{other}\" {where}")

    def clock_hint(self) -> str:
        """Where the sample period and the counter's word order are set, for the clock check."""
        src = self.rmap.source if self.rmap is not None else "default"
        return (f"the sample period (period_s in the controller's info block, else device.sample_period_s "
                f"of register map {src}) and device.word_order of the counter")

    def position_hint(self, axis: str) -> str:
        src = self.rmap.source if self.rmap is not None else "default"
        return f"word_order and scale_mm of axis {axis} in register map {src}"

    # -- live mode -----------------------------------------------------------------------------
    def _read_live(self, timeout: float) -> list[Sample]:
        rmap = self.rmap
        assert rmap is not None
        deadline = time.monotonic() + timeout
        batch_end = time.monotonic() + 0.02  # hand samples over every ~20 ms
        spans = self._live_spans
        i_status = self._at(spans, rmap.status)
        i_cnt = self._at(spans, rmap.counter)
        i_seg = self._at(spans, rmap.segment) if rmap.segment is not None else None
        i_cmd = [self._at(spans, rmap.axes[i].commanded) for i in self._cols]
        i_act = [self._at(spans, rmap.axes[i].actual) for i in self._cols]
        out: list[Sample] = []
        T = self.period
        while True:
            try:
                regs = self._read_span(spans)
            except TransportError as exc:
                if not out:
                    raise
                self._deferred_error = exc  # hand over what was polled; raise on the next read()
                return out
            status = int(regs[i_status])
            self._last_status = status
            u32 = int(decode_u32(regs[i_cnt], regs[i_cnt + 1], rmap.word_order, signed=False))
            counter = u32 if self._last_live is None else self._unwrap(u32, self._last_live)
            if not status & (STATUS_RUNNING | STATUS_ENDED):
                self.idle_polls += 1
            else:  # nothing is valid before the controller runs
                if self._last_live is None or counter != self._last_live:
                    # A counter that went back is handed over too: the capture loop tells a
                    # restart (it counts on from there) from a stray sample.
                    if self._last_live is not None and counter > self._last_live:
                        self.gaps += counter - self._last_live - 1
                    self._check_live_word_order(int(regs[i_cnt]), int(regs[i_cnt + 1]))
                    self._last_live = counter
                    cmd = [int(decode_u32(regs[j], regs[j + 1], o, True)) / float(n)
                           for j, o, n in zip(i_cmd, self._orders, self._per_unit)]
                    act = [int(decode_u32(regs[j], regs[j + 1], o, True)) / float(n)
                           for j, o, n in zip(i_act, self._orders, self._per_unit)]
                    seg = int(regs[i_seg]) if i_seg is not None else 0
                    out.append(Sample(counter, counter * T, tuple(cmd), tuple(act), seg))
                    self.stats.received += 1
                elif status & STATUS_ENDED:
                    self.ended = True
                    return out
            now = time.monotonic()
            if now >= deadline or (out and now >= batch_end):
                return out

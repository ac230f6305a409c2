"""CAN driver (python-can): CiA 402 drives over CANopen, or raw frames described by a DBC file.

URL (docs/can.md)::

    can://<interface>/<channel>?<options>

    can://udp_multicast/239.74.163.2?port=43113&nodes=1,2&axes=X,Y&status=64
    can://virtual/channel0?node=3                      (python-can's in-process bus)
    can://slcan//dev/pts/5?bitrate=1000000&nodes=1,2,3  (serial-line CAN adapter)
    can://udp_multicast/239.74.163.2?dbc=fixtures/can/positions.dbc&axes=X,Y&period=0.001

``interface`` is a python-can interface name, ``channel`` its channel (the path without
its first slash).  Options:

========== ======================================================================
nodes      CANopen node ids, one per axis, e.g. ``1,2,3`` (``node=3`` for one axis)
axes       axis names in node (or DBC) order; default X,Y,Z,A,B,C...
status     node id of the controller's program-status node (0x2100, end of program and
           segment); 0 = none: the capture then ends on --duration, Ctrl-C or silence
eds        EDS of the axis nodes (default fixtures/can/cia402_axis.eds)
scale      position units of 0x6062/0x6064 (CiA 402 user-defined units) per mm (deg), one
           value or one per axis (default 10000: 0.1 um units); mm = value / scale
sdo        1 (default): read the TPDO mapping, 0x1019 and 0x1006 from each drive by SDO
           upload; 0: take them from the EDS
sync       0 (default): only listen; 1: the agent is the SYNC producer at ``period``
period     sample period in s (overrides 0x1006; needed with sync=1 or dbc= if the DBC
           has no GenMsgCycleTime on the counter frame)
dbc        DBC file: decode raw frames by its signals instead of CANopen
timeout    s of bus silence after which the capture gives up (default 5)
port, ttl  udp_multicast UDP port (default 43113) and hop limit (default 1)
bitrate    bit rate for interfaces that need one (slcan, real adapters)
========== ======================================================================

What the driver sends (SPEC §8, passive capture): with ``sdo=1`` SDO *upload* requests
(reads) of 0x1800.., 0x1A00.. (TPDO communication and mapping parameters), 0x1005,
0x1019 and 0x1006 of each axis node and of the status node, once while opening; with
``sync=1`` the SYNC frame (COB-ID 0x80, counter byte).  Never NMT commands, RPDOs or
SDO downloads.

Sample counter: the CiA 301 SYNC counter (1..0x1019 overflow, 240 by default; none when
the drive has no 0x1019), numbered with the host receive times by
:class:`~drivers.transports.can_ticks.CounterUnwrapper`; a tick whose SYNC or any axis
TPDO is missing is a drop, a TPDO whose length differs from its mapping is corrupt
(counted, never decoded).  A restart (the counter jumps back, an NMT boot-up message) or a
silence the host clock cannot span stops the capture with one line (docs/can.md).
Opening waits up to ``timeout`` for the first frame the capture reads, so a silent bus
fails before any log is written.
"""

from __future__ import annotations

import collections
import logging
import socket
import threading
import time
from pathlib import Path
from typing import Any

import can

from core.errors import InputError, TransportError, TransportTimeout
from drivers.base import Driver, Sample, StreamInfo
from drivers.transports import canopen_map as com
from drivers.transports.can_ticks import ControllerRestart, CounterError, CounterUnwrapper, TickAssembler

# A library's loggers report to the application's handlers only: without one, Python's
# last-resort handler would print canopen's own "Transfer aborted by client ..." next to
# the one-line error this driver raises for the same failure (an absent node).  The agent
# CLI shows them with RAPID_IDENT_DEBUG=1.
for _name in ("canopen", "can", "cantools"):
    logging.getLogger(_name).addHandler(logging.NullHandler())

__all__ = ["CanDriver", "DEFAULT_SCALE", "DEFAULT_AXES", "explain_bus_error"]

DEFAULT_SCALE = 10_000.0  # position units per mm (deg): a drive set up for 0.1 um units
DEFAULT_AXES = ("X", "Y", "Z", "A", "B", "C", "U", "V", "W")
_DEFAULT_CHANNEL = {"udp_multicast": "239.74.163.2", "virtual": "channel0"}
RECV_BUFFER_BYTES = 8 << 20  # requested udp_multicast socket buffer (the kernel caps it at rmem_max)
_DRAIN_MAX = 4000  # frames handled per read() call before returning to the capture loop


def _int_list(url, name: str) -> list[int] | None:
    text = url.option(name, str)
    if text is None:
        return None
    try:
        return [int(v, 0) for v in text.split(",") if v.strip()]
    except ValueError:
        raise InputError.about("port", f"{url.raw}: option {name}={text!r} is not a comma-separated list of integers") from None


class CanDriver(Driver):
    """Capture commanded/actual positions from CANopen CiA 402 drives or DBC-described frames."""

    schemes = ("can",)
    options = {
        "nodes": str, "node": int, "axes": str, "status": int, "eds": str, "scale": str, "sdo": bool,
        "sync": bool, "period": float, "dbc": str, "timeout": float, "port": int, "ttl": int,
        "bitrate": int,
    }

    def __init__(self, url, axes: list[str] | None = None) -> None:
        super().__init__(url, axes)
        self.interface = url.host
        if not self.interface:
            raise InputError.about("port", f"{url.raw}: name the python-can interface, e.g. can://udp_multicast/239.74.163.2")
        channel = url.path[1:] if url.path.startswith("/") else url.path
        self.channel = channel or _DEFAULT_CHANNEL.get(self.interface, "")
        self.timeout_s = url.option("timeout", float, 5.0)
        if not self.timeout_s > 0:
            raise InputError.about("port", f"{url.raw}: timeout must be > 0 s")
        self._bus: can.BusABC | None = None
        self._dispatch: dict[int, tuple] = {}
        self._backlog: collections.deque = collections.deque()  # frames read while opening
        self._asm: TickAssembler | None = None
        self._sync_stop = threading.Event()
        self._sync_thread: threading.Thread | None = None
        self._opened_at = 0.0  # host monotonic time the driver finished opening, s
        self._last_rx = 0.0  # host monotonic time of the last frame the capture reads, s
        self._stop_error: CounterError | None = None  # the counter cannot be followed: raised next read
        self._bootup: dict[int, int] = {}  # NMT boot-up COB-ID -> node id of the nodes read
        self._last_ts: float | None = None  # receive timestamp of the last frame, s
        self._silence_s = 0.25  # s of silence (receive timestamps) counted as a reconnect

    # -- opening --------------------------------------------------------------------------
    def _make_bus(self) -> can.BusABC:
        kw: dict[str, Any] = {}
        if self.interface == "udp_multicast":
            kw["port"] = self.url.option("port", int, 43113)
            kw["hop_limit"] = self.url.option("ttl", int, 1)
        elif self.url.option("port", int) is not None or self.url.option("ttl", int) is not None:
            raise InputError.about("port", f"{self.url.raw}: port= and ttl= apply to udp_multicast only")
        if self.url.option("sync", bool, False) and self.interface != "udp_multicast":
            # our own SYNC must come back in the receive stream, in order with the TPDOs
            # answering it (udp_multicast loops every datagram back to its own socket anyway)
            kw["receive_own_messages"] = True
        bitrate = self.url.option("bitrate", int)
        if bitrate is not None:
            kw["bitrate"] = bitrate
        try:
            bus = can.Bus(interface=self.interface, channel=self.channel, **kw)
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            raise TransportError(f"cannot open CAN interface {self.interface!r} channel {self.channel!r}: "
                                 f"{explain_bus_error(self.interface, exc)}") from exc
        sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
        if sock is not None:
            # ~7 datagrams per ms at 6 axes: the default ~200 kB buffer holds only tens of ms,
            # too little to ride out a busy moment of the capture loop (an MCAP flush).
            try:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECV_BUFFER_BYTES)
            except OSError:
                pass
        return bus

    def _axes_and_scales(self, n: int) -> tuple[list[str], list[float]]:
        text = self.url.option("axes", str)
        names = [a.strip() for a in text.split(",") if a.strip()] if text else list(DEFAULT_AXES[:n])
        if len(names) != n:
            raise InputError.about("port", f"{self.url.raw}: {len(names)} axes for {n} nodes; give one axis name per node")
        if len(set(names)) != n:
            raise InputError.about("port", f"{self.url.raw}: axis names repeat in axes={text}")
        stext = self.url.option("scale", str)
        try:
            scales = [float(v) for v in stext.split(",")] if stext else [DEFAULT_SCALE]
        except ValueError:
            raise InputError.about("port", f"{self.url.raw}: scale={stext!r} is not a number or a comma-separated list") from None
        if len(scales) == 1:
            scales = scales * n
        if len(scales) != n or not all(s > 0 for s in scales):
            raise InputError.about("port", f"{self.url.raw}: scale needs one positive value or one per axis ({n})")
        return names, scales

    def _wanted(self, names: list[str]) -> list[int]:
        if not self.wanted_axes:
            return list(range(len(names)))
        missing = [a for a in self.wanted_axes if a not in names]
        if missing:
            raise InputError.about("axes", f"axis {missing[0]!r} is not on this bus (axes: {','.join(names)})")
        return [names.index(a) for a in self.wanted_axes]

    def _open(self) -> StreamInfo:
        self._bus = self._make_bus()
        try:
            info = self._open_dbc() if self.url.option("dbc", str) else self._open_canopen()
            if self.url.option("sync", bool, False):
                self._start_sync(info.sample_period)
            self._opened_at = time.monotonic()
            self._await_first_frame()
            self._last_rx = time.monotonic()
        except BaseException:
            self._close()
            raise
        return info

    def _relevant(self, msg: can.Message) -> bool:
        """Whether a frame carries ticks (the SYNC or counter frame, a position PDO or DBC frame): the
        frames whose absence is a silent bus (a status node alone makes no samples)."""
        cob = msg.arbitration_id
        return cob == self._sync_cob or self._dispatch.get(cob, ("status",))[0] != "status"

    def _await_first_frame(self) -> None:
        """Wait up to ``timeout`` for the first frame the capture reads, so that a silent bus is a
        one-line error before any log is written (docs/capture.md); frames read go to the backlog."""
        if any(self._relevant(m) for m in self._backlog):
            return
        others: set[int] = set()
        deadline = self._opened_at + self.timeout_s
        while (left := deadline - time.monotonic()) > 0:
            try:
                msg = self._bus.recv(min(left, 0.1))
            except can.CanOperationError:
                self.stats.corrupt += 1  # a datagram that is not a CAN frame
                continue
            if msg is None:
                continue
            self._backlog.append(msg)
            if self._relevant(msg):
                return
            others.add(msg.arbitration_id)
        where = f"{self.interface} {self.channel}"
        if others:
            ids = ", ".join(f"0x{i:X}" for i in sorted(others)[:8]) + (", ..." if len(others) > 8 else "")
            raise TransportTimeout(
                f"CAN frames arrive on {where} but in {self.timeout_s:g} s none the capture reads (ids seen: {ids}; "
                f"expected {self._expected_ids()}): check {'the DBC' if self._mode == 'dbc' else 'nodes= and 0x1005'}")
        raise TransportTimeout(
            f"no CAN frame in {self.timeout_s:g} s on {where}: nothing is sending on this bus (check the "
            "interface, channel and port, and that the drives run)")

    def _expected_ids(self) -> str:
        ids = sorted({self._sync_cob, *(cob for cob, entry in self._dispatch.items() if entry[0] != "status")})
        return ", ".join(f"0x{i:X}" for i in ids)

    def _open_canopen(self) -> StreamInfo:
        import canopen

        url = self.url
        nodes = _int_list(url, "nodes")
        single = url.option("node", int)
        if nodes is None and single is None:
            raise InputError.about("port", f"{url.raw}: give the drives' node ids, e.g. nodes=1,2,3 (or node=3)")
        if nodes is not None and single is not None:
            raise InputError.about("port", f"{url.raw}: give nodes= or node=, not both")
        nodes = nodes if nodes is not None else [single]
        if not nodes or not all(1 <= n <= 127 for n in nodes) or len(set(nodes)) != len(nodes):
            raise InputError.about("port", f"{url.raw}: node ids must be distinct, 1..127 (got {nodes})")
        names, scales = self._axes_and_scales(len(nodes))
        keep = self._wanted(names)
        status_id = url.option("status", int, 0)
        if status_id and (not 1 <= status_id <= 127 or status_id in nodes):
            raise InputError.about("port", f"{url.raw}: status node {status_id} must be 1..127 and not an axis node")
        eds = Path(url.option("eds", str, str(com.DEFAULT_AXIS_EDS)))
        use_sdo = url.option("sdo", bool, True)

        network = canopen.Network(self._bus)
        pump = _OpenPhasePump(self._bus, network, self._backlog) if use_sdo else None
        try:
            remote = {}
            for nid in [nodes[i] for i in keep] + ([status_id] if status_id else []):
                od = load_od(eds if nid != status_id else com.DEFAULT_STATUS_EDS, nid)
                node = canopen.RemoteNode(nid, od)
                node.sdo.RESPONSE_TIMEOUT = 1.0
                network.add_node(node)
                remote[nid] = node
            layouts = {nodes[i]: com.axis_pdo(remote[nodes[i]], from_od=not use_sdo) for i in keep}
            status = com.status_pdo(remote[status_id], from_od=not use_sdo) if status_id else None
            sync = com.sync_params(remote[nodes[keep[0]]], from_od=not use_sdo)
        finally:
            if pump is not None:
                pump.stop()  # from here on the driver reads the bus itself, backlog first
        period = url.option("period", float) or sync.period_s
        if not period or period <= 0:
            raise InputError.about("port", f"{url.raw}: the sample period is unknown (0x1006 is 0); give period= in s")

        self._sync_cob = sync.cob_id
        self._overflow = sync.overflow
        self._dispatch = {}
        for part, i in enumerate(keep):
            lay = layouts[nodes[i]]
            st = lay.compiled()
            self._dispatch[lay.cob_id] = ("pdo", part, st, lay.length, part,
                                          lay.position(com.POSITION_DEMAND), lay.position(com.POSITION_ACTUAL),
                                          scales[i])
        if status:
            self._dispatch[status.cob_id] = ("status", status.compiled(), status.length,
                                             status.position(com.PROGRAM_STATUS, 1),
                                             status.position(com.PROGRAM_STATUS, 2))
        # CiA 301: without 0x1019 (or with it 0) the SYNC carries no counter; ticks are then
        # numbered by arrival order and host receive time (modulus 1).  A counter byte sent
        # anyway cannot be unwrapped without its overflow value, so it is ignored.
        counted = sync.overflow > 1
        unwrap = CounterUnwrapper(sync.overflow if counted else 1, 1, period,
                                  f"SYNC counter (1..{sync.overflow})" if counted else "SYNC without counter")
        self._asm = TickAssembler(len(keep), len(keep), unwrap, period)
        # a drive or the status node that restarts says so with its NMT boot-up message
        self._bootup = {0x700 + nid: nid for nid in [nodes[i] for i in keep] + ([status_id] if status_id else [])}
        self._mode = "canopen"
        axes = tuple(names[i] for i in keep)
        return StreamInfo(
            axes=axes, sample_period=period,
            controller=f"CANopen CiA 402 drives, nodes {','.join(str(nodes[i]) for i in keep)} "
                       f"({eds.name}) on {self.interface} {self.channel}",
            units=("mm",) * len(axes),
            extra={"transport": "can", "protocol": "canopen", "interface": self.interface, "channel": self.channel,
                   "nodes": [nodes[i] for i in keep], "status_node": status_id or None,
                   "position_units_per_mm": [scales[i] for i in keep], "sync_counter_overflow": sync.overflow,
                   "sync_producer": "capture" if url.option("sync", bool, False) else "controller",
                   "mapping_from": "sdo" if use_sdo else "eds"},
        )

    def _open_dbc(self) -> StreamInfo:
        url = self.url
        for name in ("nodes", "node", "status", "eds", "scale", "sdo"):
            if url.option(name, str) is not None:
                raise InputError.about("port", f"{url.raw}: option {name}= is for CANopen; with dbc= the DBC gives the layout")
        from drivers.transports.dbc_map import load_dbc  # cantools only when a DBC is used

        text = url.option("axes", str)
        layout = load_dbc(url.option("dbc", str), [a.strip() for a in text.split(",") if a.strip()] if text else None)
        names = list(layout.axes)
        keep = self._wanted(names)
        cycle = getattr(layout.tick_message, "cycle_time", None)
        period = url.option("period", float) or ((cycle or 0) / 1000.0)
        if not period > 0:
            raise InputError.about("port", f"{url.raw}: the sample period is unknown; give period= in s")
        remap = {i: k for k, i in enumerate(keep)}
        parts = [(p, [(remap[i], c, a, f) for (i, c, a), f in zip(p.axes, p.per_mm) if i in remap])
                 for p in layout.parts]
        parts = [(p, ax) for p, ax in parts if ax]
        self._dispatch = {layout.tick_id: ("tick", layout.tick_message, layout.tick_length)}
        for k, (p, ax) in enumerate(parts):
            self._dispatch[p.frame_id] = ("dbc", k, p.message, p.length, tuple(ax))
        self._sync_cob = layout.tick_id
        self._overflow = layout.modulus
        unwrap = CounterUnwrapper(layout.modulus, 0, period, f"DBC counter ({layout.modulus.bit_length() - 1} bits)")
        self._asm = TickAssembler(len(keep), len(parts), unwrap, period)
        self._bootup = {}
        self._mode = "dbc"
        axes = tuple(names[i] for i in keep)
        return StreamInfo(
            axes=axes, sample_period=period,
            controller=f"CAN frames per {Path(url.option('dbc', str)).name} on {self.interface} {self.channel}",
            units=("mm",) * len(axes),
            extra={"transport": "can", "protocol": "dbc", "interface": self.interface, "channel": self.channel,
                   "dbc": str(url.option("dbc", str)), "counter_modulus": layout.modulus},
        )

    # -- SYNC production (sync=1 only) ---------------------------------------------------
    def _start_sync(self, period: float) -> None:
        if self._mode != "canopen":
            raise InputError.about("port", f"{self.url.raw}: sync=1 applies to CANopen (not with dbc=)")
        self._sync_thread = threading.Thread(target=self._sync_loop, args=(period,), name="can-sync", daemon=True)
        self._sync_thread.start()

    def _sync_loop(self, period: float) -> None:
        """Send SYNC (COB-ID 0x1005, counter 1..overflow) every ``period`` s until closed.

        The reader sees each SYNC come back from the bus (own messages received), so ticks
        open in bus order, exactly as if another SYNC producer had sent them.
        """
        count, next_t = 0, time.perf_counter()
        while not self._sync_stop.is_set():
            raw = count % self._overflow + 1 if self._overflow > 1 else None
            msg = can.Message(arbitration_id=self._sync_cob, is_extended_id=False,
                              data=[raw] if raw is not None else [])
            try:
                self._bus.send(msg)
            except can.CanError:
                pass  # a failed SYNC shows as a dropped tick
            count += 1
            next_t += period
            delay = next_t - time.perf_counter()
            if delay > 0:
                self._sync_stop.wait(delay)

    # -- reading --------------------------------------------------------------------------
    def _read(self, timeout: float) -> list[Sample]:
        if self._stop_error is not None:
            raise self._stop_error  # the samples read before it were returned by the last call
        out: list[Sample] = []
        try:
            self._drain(timeout, out)
        except CounterError as exc:
            self._stop_error = exc  # raised on the next call, after these samples are recorded
        asm = self._asm
        if self.ended:
            out += asm.release()  # the end of the program: no later frame can contradict them
        self.stats.received += len(out)
        self.stats.skipped = asm.skipped_ticks  # ticks that arrived but could not become samples
        # stats.dropped stays 0: every lost tick shows as a counter gap, which the capture
        # loop counts (drivers/capture.py); asm.lost_ticks holds the same number here.
        if not out and not self.ended and self._stop_error is None:
            now = time.monotonic()
            if now - self._last_rx > self.timeout_s:
                raise TransportTimeout(
                    f"no CAN frame for {now - self._last_rx:.1f} s on {self.interface} {self.channel}: the "
                    "controller stopped sending (bus disconnected or controller off)")
        return out

    def _drain(self, timeout: float, out: list[Sample]) -> None:
        """Handle the frames waiting (up to _DRAIN_MAX), appending completed samples to ``out``."""
        bus, asm, dispatch = self._bus, self._asm, self._dispatch
        wait = timeout
        for _ in range(_DRAIN_MAX):
            try:
                msg = self._backlog.popleft() if self._backlog else bus.recv(wait)
            except can.CanOperationError:
                self.stats.corrupt += 1  # a datagram that is not a CAN frame
                continue
            if msg is None:
                return
            wait = 0.0
            if msg.is_error_frame or msg.is_remote_frame:
                continue
            cob = msg.arbitration_id
            if cob in self._bootup and msg.dlc == 1 and msg.data[0] == 0 and asm.counter is not None:
                raise ControllerRestart(
                    f"node {self._bootup[cob]} sent its NMT boot-up message (0x{cob:X}): it restarted "
                    f"(after counter {asm.counter}); the log ends there")
            if cob != self._sync_cob and cob not in dispatch:
                continue
            if self._relevant(msg):
                self._last_rx = time.monotonic()
            # Silence measured on the receive timestamps (kernel time for udp_multicast), so a
            # capture loop that was busy for a while does not look like a silent bus.
            ts = msg.timestamp
            if self._last_ts is not None and ts - self._last_ts > self._silence_s and asm.counter is not None:
                self.stats.reconnects += 1  # the bus was silent, then frames resumed
            self._last_ts = ts
            if cob == self._sync_cob and self._mode == "canopen":
                n = len(msg.data)
                if self._overflow > 1 and n == 1 and 1 <= msg.data[0] <= self._overflow:
                    out += asm.open_tick(msg.data[0], ts)
                elif self._overflow <= 1 and n <= 1:
                    out += asm.open_tick(0, ts)  # no counter (a byte sent anyway is ignored)
                else:
                    self.stats.corrupt += 1  # wrong length, or a counter outside 1..0x1019
                continue
            entry = dispatch[cob]
            kind = entry[0]
            if kind == "pdo":
                _, part, st, length, axis, i_cmd, i_act, scale = entry
                if msg.dlc != length or len(msg.data) != length:
                    self.stats.corrupt += 1  # PDO length does not match the mapping: never decoded
                    continue
                vals = st.unpack(msg.data)
                sample = asm.part(part, [(axis, vals[i_cmd] / scale, vals[i_act] / scale)])
                if sample is not None:
                    out.append(sample)
            elif kind == "dbc":
                _, part, message, length, axes = entry
                if len(msg.data) != length:
                    self.stats.corrupt += 1
                    continue
                try:
                    raw = message.decode(bytes(msg.data), decode_choices=False, scaling=False)
                except Exception:  # noqa: BLE001 - cantools raises several kinds on bad data
                    self.stats.corrupt += 1
                    continue
                sample = asm.part(part, [(i, raw[c] / f, raw[a] / f) for i, c, a, f in axes])
                if sample is not None:
                    out.append(sample)
            elif kind == "tick":
                _, message, length = entry
                if len(msg.data) != length:
                    self.stats.corrupt += 1
                    continue
                sig = message.decode(bytes(msg.data), decode_choices=False)
                if sig.get("state") == com.STATE_ENDED:
                    self.ended = True
                    return
                out += asm.open_tick(int(sig["counter"]), ts)
                asm.segment = int(sig.get("segment", 0))
            elif kind == "status":
                _, st, length, i_seg, i_state = entry
                if len(msg.data) != length:
                    self.stats.corrupt += 1
                    continue
                vals = st.unpack(msg.data)
                asm.segment = int(vals[i_seg])
                if vals[i_state] == com.STATE_ENDED:
                    self.ended = True
                    return
    # -- closing --------------------------------------------------------------------------
    def _shutdown_bus(self) -> None:
        if self._bus is not None:
            try:
                self._bus.shutdown()
            finally:
                self._bus = None

    def unusable_reason(self) -> str:
        asm = self._asm
        if asm is None or not asm.skipped_ticks:
            return ""
        if asm.orphan_ticks > asm.incomplete_ticks:
            opener = "counter frame" if self._mode == "dbc" else f"SYNC (COB-ID 0x{self._sync_cob:X}, from 0x1005)"
            return (f"position frames that no {opener} came before; check that the controller sends it "
                    f"{'(the DBC frame with the counter signal)' if self._mode == 'dbc' else 'and 0x1005'}")
        return ("ticks that did not bring a position frame from every axis; check nodes= (or the DBC) "
                "against the ids the drives send with")

    def position_hint(self, axis: str) -> str:
        return f"the scale= of axis {axis} (position units per mm) or its DBC factor"

    def clock_hint(self) -> str:
        """Where the sample period is set, for the capture's clock check."""
        return "the period= option, else the drive's communication cycle period 0x1006 (or the DBC's cycle time)"

    def _close(self) -> None:
        self._sync_stop.set()
        if self._sync_thread is not None:
            self._sync_thread.join(1.0)
        self._shutdown_bus()


def explain_bus_error(interface: str, exc: BaseException) -> str:
    """The reason python-can gives, with its cause, and the usual fix for udp_multicast."""
    text = str(exc)
    cause = exc.__cause__
    if cause is not None and str(cause) not in text:
        text += f" ({cause})"
    if interface == "udp_multicast" and isinstance(cause, OSError) and cause.errno in (19, 101):
        text += "; the host has no route for multicast: add one, e.g. `ip route add 239.0.0.0/8 dev lo`"
    return text


class _OpenPhasePump:
    """While the driver reads SDOs: feed SDO answers to canopen, keep every other frame for later.

    canopen's own receive thread would swallow the first stream frames; this one hands
    only SDO server answers (COB-ID 0x581..0x5FF) to the canopen network and queues the
    rest in ``backlog`` so that the first read() sees them, whatever the interface.
    """

    def __init__(self, bus: can.BusABC, network, backlog: collections.deque) -> None:
        self.bus, self.network, self.backlog = bus, network, backlog
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="can-open-pump", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                msg = self.bus.recv(0.02)
            except can.CanOperationError:
                continue
            if msg is None:
                continue
            if 0x580 < msg.arbitration_id <= 0x5FF:
                self.network.notify(msg.arbitration_id, msg.data, msg.timestamp)
            else:
                self.backlog.append(msg)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()


def load_od(path: Path, node_id: int):
    """The object dictionary of node ``node_id`` from an EDS (see :func:`canopen_map.load_od`)."""
    return com.load_od(path, node_id)

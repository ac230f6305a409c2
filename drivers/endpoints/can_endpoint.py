"""Simulated CAN controller: CiA 402 drives (one CANopen node per axis) or DBC frames on a python-can bus.

CANopen (default, ``--opt protocol=canopen``): the simulated CNC is the SYNC producer at
the servo period; after every SYNC (COB-ID 0x80, CiA 301 counter byte 1..240) each
axis node n sends its TPDO1 (COB-ID 0x180+n, 8 bytes: 0x6062 position demand value
and 0x6064 position actual value, INTEGER32, ``scale`` increments per mm, default
10 000 = 0.1 um), in the layout
of fixtures/can/cia402_axis.eds.  The program status node (``status``, default 64,
fixtures/can/cnc_status.eds) sends TPDO1 (0x180+64, 3 bytes: 0x2100:01 segment,
0x2100:02 state) after the SYNC of the first tick of each segment, and state 2
("program ended") after the last tick, repeated every 0.25 s while lingering.

DBC (``--opt protocol=dbc [--opt dbc=FILE]``, default fixtures/can/positions.dbc):
each tick is the ``counter`` frame (counter mod 2**bits, segment, state 1) followed by
the frames carrying ``<AXIS>_commanded`` / ``<AXIS>_actual``; the end is a counter
frame with state 2.

Transport: python-can ``udp_multicast`` by default, on a group 239.74.163.x and UDP
port chosen per endpoint (so parallel endpoints do not hear each other) and hop limit
0, so frames never leave the host (SPEC §8: loopback only); ``--opt
interface=virtual`` for in-process tests.

Starting (``wait``, default true): a real CNC streams from power-on; the simulated one
waits for a capture so that a test sees every tick.  With CANopen it answers SDO
uploads for the axis and status nodes (canopen ``LocalNode``) and starts the program
once a capture has read 0x1006 (the CAN driver reads it last while opening); a
capture that sends no SDO (``sdo=0``) is noticed by its multicast group membership
(/proc/net/igmp) and the program starts 2 s later.  With DBC only the group membership
counts (start 0.2 s after the capture joins; on a bus without group membership, such as
``virtual``, it streams at once).  ``wait=0`` streams at once.

Faults: a dropped tick = one axis node's TPDO (DBC: one axis frame) missing after its
SYNC; a corrupted tick = that frame sent with 6 data bytes instead of 8 (a PDO whose
length does not match its mapping - CAN's own CRC means damage on a real bus shows
as malformed or missing frames, never as wrong bytes); a disconnect = the bus is
silent for ``outage`` s (default 1.0) from ``--disconnect-at``, its ticks are listed
as ``unsent_counters``, then frames resume.
"""

from __future__ import annotations

import random
import socket
import struct
import sys
import threading
import time
from pathlib import Path
from typing import Any

import can
import numpy as np

from core.errors import InputError, TransportError
from drivers.base import StreamInfo
from drivers.endpoints.base import Endpoint
from drivers.endpoints.source import RealTimeSource
from drivers.transports import canopen_map as com
from drivers.transports.can_bus import DEFAULT_SCALE, explain_bus_error
from drivers.transports.dbc_map import DEFAULT_DBC, load_dbc

__all__ = ["CanEndpoint", "multicast_members"]

SYNC_OVERFLOW = 240  # CiA 301 SYNC counter runs 1..240 (0x1019 in the EDS)
DEFAULT_STATUS_NODE = 64
_STATE = struct.Struct("<HB")  # 0x2100:01 segment, 0x2100:02 state
_POS = struct.Struct("<ii")  # 0x6062, 0x6064


def multicast_members(group: str) -> int | None:
    """Sockets on this host joined to IPv4 multicast ``group`` (from /proc/net/igmp); None if unknown."""
    try:
        text = Path("/proc/net/igmp").read_text()
    except OSError:
        return None
    key = "%08X" % struct.unpack("<I", socket.inet_aton(group))[0]
    total = 0
    for line in text.splitlines():
        parts = line.split()
        if len(parts) >= 2 and parts[0].upper() == key:
            total += int(parts[1])
    return total


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class CanEndpoint(Endpoint):
    """Serve a recording as CANopen CiA 402 drives (or DBC frames); see the module docstring."""

    name = "can"
    option_types = {"protocol": str, "interface": str, "channel": str, "port": int, "ttl": int, "nodes": str,
                    "status": int, "scale": float, "dbc": str, "wait": bool, "outage": float}

    def __init__(self, source: RealTimeSource, info: StreamInfo, options: dict[str, Any] | None = None) -> None:
        super().__init__(source, info, options)
        o = self.options
        self.protocol = str(o.get("protocol", "canopen")).lower()
        if self.protocol not in ("canopen", "dbc"):
            raise InputError(f"can endpoint: protocol={self.protocol!r} (use canopen or dbc)")
        self.interface = str(o.get("interface", "udp_multicast"))
        rnd = random.Random()
        default_channel = f"239.74.163.{rnd.randint(2, 254)}" if self.interface == "udp_multicast" else "channel0"
        self.channel = str(o.get("channel", default_channel))
        self.udp_port = o.get("port")
        self.ttl = int(o.get("ttl", 0))
        self.wait = bool(o.get("wait", True))
        self.outage_s = float(o.get("outage", 1.0))
        if self.outage_s < 0:
            raise InputError("can endpoint: outage must be >= 0 s")
        n = len(source.axes)
        if "nodes" in o:
            try:
                self.nodes = [int(v, 0) for v in str(o["nodes"]).split(",") if v.strip()]
            except ValueError:
                raise InputError(f"can endpoint: nodes={o['nodes']!r} is not a list of node ids") from None
        else:
            self.nodes = list(range(1, n + 1))
        if len(self.nodes) != n or not all(1 <= v <= 127 for v in self.nodes):
            raise InputError(f"can endpoint: need {n} node ids in 1..127 (one per axis), got {self.nodes}")
        self.status_node = int(o.get("status", DEFAULT_STATUS_NODE))
        if self.status_node in self.nodes or not 0 <= self.status_node <= 127:
            raise InputError(f"can endpoint: status node {self.status_node} must be 0..127 and not an axis node")
        self._rng = random.Random(source.faults.seed)
        self._counter = source.counter.tolist()
        self._segment = source.recording.segment.tolist()
        if self.protocol == "dbc":
            self.dbc_path = Path(o.get("dbc", DEFAULT_DBC))
            self._layout = load_dbc(self.dbc_path, list(source.axes))
            order = {i: f for p in self._layout.parts for (i, _c, _a), f in zip(p.axes, p.per_mm)}
            scales = [order[i] for i in range(n)]
        else:
            self.scale = float(o.get("scale", DEFAULT_SCALE))
            if not self.scale > 0:
                raise InputError("can endpoint: scale (increments per mm) must be > 0")
            scales = [self.scale] * n
        per_mm = np.asarray(scales)
        cmd = np.rint(source.commanded * per_mm)
        act = np.rint(source.actual * per_mm)
        big = max(np.abs(cmd).max(initial=0), np.abs(act).max(initial=0))
        if big >= 2**31:
            raise InputError(f"can endpoint: a position of {big / per_mm.max():g} mm does not fit INTEGER32 "
                             f"at {per_mm.max():g} increments per mm; lower the scale option")
        self._cmd = cmd.astype(np.int64).tolist()
        self._act = act.astype(np.int64).tolist()
        self._bus: can.BusABC | None = None
        self._network = None
        self._cue = threading.Event()
        self._sdo_seen = threading.Event()

    # -- set-up ---------------------------------------------------------------------------
    def _make_bus(self) -> can.BusABC:
        kw: dict[str, Any] = {}
        if self.interface == "udp_multicast":
            kw = {"port": self.udp_port, "hop_limit": self.ttl}
        try:
            return can.Bus(interface=self.interface, channel=self.channel, **kw)
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            raise TransportError(f"can endpoint: cannot open {self.interface} {self.channel}: "
                                 f"{explain_bus_error(self.interface, exc)}") from exc

    def start(self) -> None:
        if self.interface == "udp_multicast" and self.udp_port is None:
            self.udp_port = _free_udp_port()
        self._bus = self._make_bus()
        if self.wait and self.protocol == "canopen":
            self._start_sdo_server()
        self._members0 = multicast_members(self.channel) if self.interface == "udp_multicast" else None
        print(f"can endpoint: {self.protocol} on {self.interface} {self.channel}"
              + (f" port {self.udp_port}" if self.udp_port else "") + f", nodes {self.nodes}", file=sys.stderr,
              flush=True)

    def _start_sdo_server(self) -> None:
        """Answer SDO uploads (reads) of the axis and status nodes until the program starts."""
        import canopen

        net = canopen.Network(self._make_bus())
        net.NOTIFIER_CYCLE = 0.02  # its receive thread must stop within ms once the program starts
        period_us = int(round(self.info.sample_period * 1e6))

        def on_read(index: int, subindex: int, od) -> int | None:
            self._sdo_seen.set()
            if index == 0x1006:
                self._cue.set()
                return period_us
            return None

        for nid in self.nodes:
            node = canopen.LocalNode(nid, com.load_od(com.DEFAULT_AXIS_EDS, nid))
            node.add_read_callback(on_read)
            net.add_node(node)
        if self.status_node:
            node = canopen.LocalNode(self.status_node, com.load_od(com.DEFAULT_STATUS_EDS, self.status_node))
            node.add_read_callback(on_read)
            net.add_node(node)
        net.connect()
        self._network = net

    def _stop_sdo_server(self) -> None:
        if self._network is not None:
            net, self._network = self._network, None
            try:
                net.disconnect()
            except Exception:  # noqa: BLE001 - shutting down a listener must not stop serving
                pass

    def port_url(self) -> str:
        q: list[str] = []
        if self.interface == "udp_multicast":
            q.append(f"port={self.udp_port}")
            if self.ttl != 1:
                q.append(f"ttl={self.ttl}")
        axes = ",".join(self.info.axes)
        if self.protocol == "dbc":
            q += [f"dbc={self.dbc_path}", f"axes={axes}", f"period={self.info.sample_period!r}"]
        else:
            q += [f"nodes={','.join(map(str, self.nodes))}", f"axes={axes}"]
            if self.status_node:
                q.append(f"status={self.status_node}")
            if self.scale != DEFAULT_SCALE:
                q.append(f"scale={self.scale!r}")
            if abs(self.info.sample_period - 0.001) > 1e-12:
                # the EDS says 1000 us: a capture that reads nothing (sdo=0) needs the real period
                q.append(f"period={self.info.sample_period!r}")
        return f"can://{self.interface}/{self.channel}?{'&'.join(q)}"

    def _wait_for_capture(self) -> bool:
        """Block until a capture is listening (see the module docstring); False if told to stop."""
        if self._members0 is None and self.protocol == "dbc":
            return True  # no cue possible (interface without group membership): stream at once
        joined_at = None
        # A capture buffers frames from the moment it joined (socket buffer), so the grace only
        # has to tell a CANopen capture that reads nothing (sdo=0) from one about to send SDOs.
        grace = 2.0 if self.protocol == "canopen" else 0.2
        while not self._cue.is_set():
            if self.stop_event.wait(0.01):
                return False
            if self._members0 is None:
                continue
            members = multicast_members(self.channel)
            if joined_at is None and members is not None and members > self._members0:
                joined_at = time.monotonic()
            if joined_at is not None and not self._sdo_seen.is_set() and time.monotonic() - joined_at > grace:
                break  # a capture that reads nothing (sdo=0 / DBC)
        # let the SDO answer to the 0x1006 read leave before the listener closes
        return not self.stop_event.wait(0.05)

    # -- frames ---------------------------------------------------------------------------
    def _frames_canopen(self, k: int, seg_changed: bool) -> list[can.Message]:
        c = self._counter[k]
        msgs = [can.Message(arbitration_id=0x80, is_extended_id=False, data=bytes([c % SYNC_OVERFLOW + 1]))]
        if seg_changed and self.status_node:
            msgs.append(self._status_msg(self._segment[k], com.STATE_RUNNING))
        cmd, act = self._cmd[k], self._act[k]
        for i, nid in enumerate(self.nodes):
            msgs.append(can.Message(arbitration_id=0x180 + nid, is_extended_id=False,
                                    data=_POS.pack(cmd[i], act[i])))
        return msgs

    def _status_msg(self, segment: int, state: int) -> can.Message:
        return can.Message(arbitration_id=0x180 + self.status_node, is_extended_id=False,
                           data=_STATE.pack(segment & 0xFFFF, state))

    def _tick_msg(self, counter: int, segment: int, state: int) -> can.Message:
        lay = self._layout
        data = lay.tick_message.encode({"counter": counter % lay.modulus, "segment": segment, "state": state},
                                       scaling=False, strict=False)
        return can.Message(arbitration_id=lay.tick_id, is_extended_id=lay.tick_id > 0x7FF, data=data)

    def _frames_dbc(self, k: int, seg_changed: bool) -> list[can.Message]:
        msgs = [self._tick_msg(self._counter[k], self._segment[k], com.STATE_RUNNING)]
        cmd, act = self._cmd[k], self._act[k]
        for p in self._layout.parts:
            values = {}
            for i, c, a in p.axes:
                values[c], values[a] = cmd[i], act[i]
            msgs.append(can.Message(arbitration_id=p.frame_id, is_extended_id=p.frame_id > 0x7FF,
                                    data=p.message.encode(values, scaling=False, strict=False)))
        return msgs

    def _end_msg(self) -> can.Message | None:
        if self.protocol == "dbc":
            return self._tick_msg(self._counter[-1] + 1, self._segment[-1], com.STATE_ENDED)
        return self._status_msg(self._segment[-1], com.STATE_ENDED) if self.status_node else None

    def _send(self, msg: can.Message) -> None:
        try:
            self._bus.send(msg)
        except can.CanError as exc:
            raise TransportError(f"can endpoint: sending failed: {exc}") from exc

    # -- serving --------------------------------------------------------------------------
    def serve_ticks(self) -> None:
        src = self.source
        if self.wait and not self._wait_for_capture():
            return
        self._stop_sdo_server()
        dropped, corrupted = src.dropped.tolist(), src.corrupted.tolist()
        disconnect_k = -1
        if src.faults.disconnect_at_s is not None:
            later = np.flatnonzero(src.recording.t >= src.faults.disconnect_at_s)
            disconnect_k = int(later[0]) if later.size else -1
        frames = self._frames_dbc if self.protocol == "dbc" else self._frames_canopen
        n_parts = len(self._layout.parts) if self.protocol == "dbc" else len(self.nodes)
        down_until = None
        last_seg = None
        for ticks, _t in src.batches():
            if self.stop_event.is_set():
                return
            last_sent = None
            for k in ticks:
                if k == disconnect_k:
                    down_until = time.monotonic() + self.outage_s
                    print(f"can endpoint: bus silent at counter {self._counter[k]} for {self.outage_s:g} s",
                          file=sys.stderr, flush=True)
                if down_until is not None:
                    if time.monotonic() < down_until:
                        self.unsent_counters.append(self._counter[k])
                        continue
                    down_until = None
                    last_seg = None  # resend the program status after the outage
                seg_changed = self._segment[k] != last_seg
                last_seg = self._segment[k]
                msgs = frames(k, seg_changed)
                if dropped[k] or corrupted[k]:
                    victim = len(msgs) - n_parts + self._rng.randrange(n_parts)
                    if dropped[k]:
                        del msgs[victim]
                    else:
                        bad = msgs[victim]
                        msgs[victim] = can.Message(arbitration_id=bad.arbitration_id,
                                                   is_extended_id=bad.is_extended_id, data=bytes(bad.data[:6]))
                for m in msgs:
                    self._send(m)
                last_sent = self._counter[k]
            if last_sent is not None:
                self.note_sent(last_sent)
        end = self._end_msg()
        if end is not None:
            self._send(end)

    def linger(self) -> None:
        """Repeat the end-of-program frame every 0.25 s while lingering."""
        end_t = time.monotonic() + self.linger_s
        end = self._end_msg()
        while not self.stop_event.wait(min(0.25, max(end_t - time.monotonic(), 0.0))):
            if time.monotonic() >= end_t:
                break
            if end is not None:
                self._send(end)

    def _close(self) -> None:
        self._stop_sdo_server()
        if self._bus is not None:
            self._bus.shutdown()
            self._bus = None

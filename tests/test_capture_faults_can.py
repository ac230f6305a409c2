"""Fault injection for CAN capture (issue 40): odd controllers, silences and restarts.

The peers are written here from CiA 301/402, docs/can.md and the libraries, not from
drivers/endpoints: canopen ``LocalNode`` drives built from EDS files written below (they
answer the capture's SDO uploads), raw SYNC / TPDO / NMT frames sent with python-can, and
a DBC made with cantools.  Tick k carries commanded = k and actual = -k position units
(``scale=1``), so every recorded sample names its true tick and each check is exact:

* every recorded sample's counter minus its true tick is one constant (its time is
  within half a period of the true tick: it is exact), and
* ``dropped`` is exactly the number of ticks not received between the first and the last
  recorded one;

or the capture stops with one ``error:`` (``summary.error``, exit 1 on the command line)
and everything it recorded up to there is exact.

Most peers run on python-can's in-process ``virtual`` bus with ``preserve_timestamps``: the
receive time of each frame is the one the peer gives it, so a silence, a jitter or a burst
happens exactly as written and the result does not depend on this machine's load.  The
tests marked slow run ``agent capture`` as its own process against a peer sending in real
time on ``udp_multicast``.
"""

from __future__ import annotations

import random
import struct
import subprocess
import sys
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import can
import canopen
import cantools
import numpy as np
import pytest

from core.errors import TransportTimeout
from core.log_format import FAILED_ENDS
from core.reader import load_mcap, load_recording
from drivers.capture import capture
from test_can_driver import UDP_MULTICAST_NEEDS, udp_multicast_available

T0 = 1_700_000_000.0  # host receive time of tick 0 on the virtual bus, s
STATUS_EDS = Path(__file__).resolve().parents[1] / "fixtures" / "can" / "cnc_status.eds"  # docs/can.md 0x2100
STATUS_NODE = 64


# -- the peer's documents: an EDS and a DBC -------------------------------------------------
def axis_eds(path: Path, overflow: int | None, period_us: int) -> Path:
    """A CiA 402 drive's EDS (CiA 306): TPDO1 on SYNC (type 1) maps 0x6062 and 0x6064; 0x1019 only if given."""
    objects = {
        "1000": ("Device type", "0x0007", "ro", "0x00020192"),
        "1001": ("Error register", "0x0005", "ro", "0"),
        "1005": ("COB-ID SYNC", "0x0007", "rw", "0x00000080"),
        "1006": ("Communication cycle period", "0x0007", "rw", str(period_us)),
        "6062": ("Position demand value", "0x0004", "ro", "0"),
        "6064": ("Position actual value", "0x0004", "ro", "0"),
    }
    if overflow is not None:
        objects["1019"] = ("Synchronous counter overflow value", "0x0005", "rw", str(overflow))
    records = {
        "1800": ("TPDO1 communication parameter", [("Highest sub-index supported", "0x0005", "ro", "2"),
                                                   ("COB-ID used by TPDO", "0x0007", "rw", "$NODEID+0x40000180"),
                                                   ("Transmission type", "0x0005", "rw", "1")]),
        "1A00": ("TPDO1 mapping parameter", [("Number of mapped objects", "0x0005", "rw", "2"),
                                             ("Mapped object 1", "0x0007", "rw", "0x60620020"),
                                             ("Mapped object 2", "0x0007", "rw", "0x60640020")]),
    }
    out = ["[DeviceInfo]", "VendorName=test peer", "ProductName=CiA 402 drive", "NrOfRXPDO=0", "NrOfTXPDO=1", "",
           "[MandatoryObjects]", "SupportedObjects=2", "1=0x1000", "2=0x1001", ""]
    optional = sorted(k for k in list(objects) + list(records) if k not in ("1000", "1001"))
    out += ["[OptionalObjects]", f"SupportedObjects={len(optional)}"]
    out += [f"{i + 1}=0x{k}" for i, k in enumerate(optional)] + [""]
    for key, (name, dtype, access, value) in objects.items():
        pdo = 1 if key in ("6062", "6064") else 0
        out += [f"[{key}]", f"ParameterName={name}", "ObjectType=0x7", f"DataType={dtype}",
                f"AccessType={access}", f"DefaultValue={value}", f"PDOMapping={pdo}", ""]
    for key, (name, subs) in records.items():
        out += [f"[{key}]", f"ParameterName={name}", "ObjectType=0x9", f"SubNumber={len(subs)}", ""]
        for i, (sname, dtype, access, value) in enumerate(subs):
            out += [f"[{key}sub{i}]", f"ParameterName={sname}", "ObjectType=0x7", f"DataType={dtype}",
                    f"AccessType={access}", f"DefaultValue={value}", "PDOMapping=0", ""]
    path.write_text("\n".join(out))
    return path


def counter_dbc(path: Path, bits: int) -> cantools.database.Database:
    """A DBC (docs/can.md naming): frame 0x100 holds a ``bits``-bit counter and the state, 0x101 axis X."""
    from cantools.database import Database, Message, Signal

    tick = Message(0x100, "Tick", 1 if bits <= 6 else 3,
                   [Signal("counter", 0, bits), Signal("state", bits, 2)], cycle_time=1)
    axis = Message(0x101, "AxisX", 8, [Signal("X_commanded", 0, 32, is_signed=True),
                                        Signal("X_actual", 32, 32, is_signed=True)])
    db = Database([tick, axis])
    path.write_text(db.as_dbc_string())
    return db


# -- the peer -------------------------------------------------------------------------------
@dataclass
class Wire:
    """Frames in the order the bus carries them, each with the host receive time the capture sees."""

    frames: list[can.Message] = field(default_factory=list)

    def send(self, ts: float, cob: int, data: bytes | list[int]) -> None:
        self.frames.append(can.Message(arbitration_id=cob, is_extended_id=False, data=bytes(data), timestamp=ts))

    def ordered(self) -> list[can.Message]:
        return sorted(self.frames, key=lambda m: m.timestamp)  # stable: one tick's frames keep their order


@dataclass
class Ticks:
    """Which ticks go on the wire, when, and with what counter.

    ``late(k)`` is how much later than k x period (s) tick k's frames arrive; ``counter(k)``
    the SYNC counter byte (None: a SYNC without data) or the DBC counter.
    """

    n: int
    period: float
    counter: Callable[[int], int | None]
    late: Callable[[int], float] = lambda k: 0.0
    unsent: set[int] = field(default_factory=set)

    def ts(self, k: int) -> float:
        return T0 + k * self.period + self.late(k)

    def sent(self) -> list[int]:
        return [k for k in range(self.n) if k not in self.unsent]


def canopen_wire(ticks: Ticks, nodes=(1,), extra: Callable[[Wire, int], None] = lambda w, k: None) -> Wire:
    """SYNC (COB-ID 0x80, counter byte or none), then each node's TPDO1 (0x180 + node: 0x6062, 0x6064)."""
    w = Wire()
    for k in ticks.sent():
        ts, c = ticks.ts(k), ticks.counter(k)
        w.send(ts, 0x80, [] if c is None else [c])
        for i, node in enumerate(nodes):
            w.send(ts + 20e-6 * (i + 1), 0x180 + node, struct.pack("<ii", k, -k))
        extra(w, k)
    end = ticks.ts(ticks.n - 1) + 0.5 * ticks.period
    w.send(end, 0x180 + STATUS_NODE, struct.pack("<HB", 0, 2))  # 0x2100: segment 0, state 2 = program ended
    return w


def dbc_wire(ticks: Ticks, db: cantools.database.Database) -> Wire:
    tick, axis = db.get_message_by_frame_id(0x100), db.get_message_by_frame_id(0x101)
    w = Wire()
    for k in ticks.sent():
        ts = ticks.ts(k)
        w.send(ts, 0x100, tick.encode({"counter": ticks.counter(k), "state": 1}))
        w.send(ts + 20e-6, 0x101, axis.encode({"X_commanded": k, "X_actual": -k}))
    w.send(ticks.ts(ticks.n - 1) + 0.5 * ticks.period, 0x100, tick.encode({"counter": 0, "state": 2}))
    return w


class VirtualPeer:
    """The controller on a fresh python-can virtual channel: CANopen LocalNodes (from EDS files)
    answer SDO uploads, and the frames of a :class:`Wire` are sent, with their receive times,
    once the capture is listening."""

    def __init__(self, eds: Path | None = None, nodes=(1,)) -> None:
        self.channel = f"faults-{uuid.uuid4().hex[:8]}"
        self.tx = can.Bus(interface="virtual", channel=self.channel, preserve_timestamps=True)
        self.net = None
        if eds is not None:
            self.net = canopen.Network()
            for node in nodes:
                self.net.add_node(canopen.LocalNode(node, canopen.import_od(str(eds), node)))
            self.net.add_node(canopen.LocalNode(STATUS_NODE, canopen.import_od(str(STATUS_EDS), STATUS_NODE)))
            self.net.connect(interface="virtual", channel=self.channel)

    def record(self, query: str, wire: Wire, tmp_path: Path, duration: float | None = None):
        """Run ``drivers.capture.capture`` on ``can://virtual/<channel>?query`` while sending ``wire``;
        returns (summary, recording or None)."""
        peers = 1 + (self.net is not None)
        listening = threading.Event()

        def send() -> None:
            t0 = time.monotonic()
            # the capture has joined the channel once python-can's virtual bus lists its queue
            while len(can.interfaces.virtual.channels.get(self.channel, ())) <= peers:
                if time.monotonic() - t0 > 10:
                    return
                time.sleep(0.002)
            listening.set()
            for m in wire.ordered():
                self.tx.send(m)

        sender = threading.Thread(target=send, daemon=True)
        sender.start()
        out = tmp_path / "log.mcap"
        try:
            summary = capture(f"can://virtual/{self.channel}?{query}", out, duration=duration, progress=False)
        finally:
            sender.join(10)
            self.close()
        assert listening.is_set()
        return summary, load_recording(out) if summary.received else None

    def close(self) -> None:
        if self.net is not None:
            self.net.disconnect()
            self.net = None
        self.tx.shutdown()


# -- the checks -----------------------------------------------------------------------------
def true_ticks(log) -> tuple[np.ndarray, np.ndarray]:
    """(recorded counters, the true tick each sample carries), checking actual = -commanded."""
    counters = np.asarray(log.metadata["counter"], dtype=np.int64)
    k = log.axes["X"].commanded
    np.testing.assert_array_equal(log.axes["X"].actual, -k)
    assert np.array_equal(k, np.rint(k))
    return counters, k.astype(np.int64)


def assert_every_sample_exact(log, period: float) -> np.ndarray:
    """Every sample's time is its true tick's (one constant offset): returns the true ticks recorded."""
    counters, k = true_ticks(log)
    assert len(k) > 0
    offset = counters - k
    assert np.all(offset == offset[0]), f"counter - true tick takes values {sorted(set(offset.tolist()))[:6]}"
    np.testing.assert_allclose(log.t - k * period, log.t[0] - k[0] * period, rtol=0, atol=period / 2)
    return k


def assert_exact(summary, log, ticks: Ticks) -> None:
    """The capture ended normally, recorded every tick sent, each at its true time, and counted the others."""
    assert summary.error == "" and summary.end == "program ended", summary.error
    k = assert_every_sample_exact(log, ticks.period)
    sent = set(ticks.sent())
    assert list(k) == [j for j in range(k[0], k[-1] + 1) if j in sent]
    assert k[0] == 0 and k[-1] == ticks.n - 1
    assert summary.dropped == (k[-1] - k[0] + 1) - len(k) == len(ticks.unsent)
    assert summary.received == len(k)


def assert_stopped(summary, log, ticks: Ticks, says: str) -> np.ndarray:
    """The capture stopped with an error naming the problem; what it recorded is exact. Returns the true ticks."""
    assert summary.end in FAILED_ENDS and says in summary.error, summary.error
    assert "\n" not in summary.error
    k = assert_every_sample_exact(log, ticks.period)
    sent = set(ticks.sent())
    assert list(k) == [j for j in range(k[0], k[-1] + 1) if j in sent]  # nothing skipped before the stop
    assert summary.dropped == (k[-1] - k[0] + 1) - len(k)
    return k


def small_jitter(seed: int, max_s: float) -> Callable[[int], float]:
    rng = random.Random(seed)
    table: dict[int, float] = {}
    return lambda k: table.setdefault(k, rng.uniform(0.0, max_s))


def canopen_query(eds: Path | None = None, **opts) -> str:
    q = f"node=1&status={STATUS_NODE}&scale=1&timeout=2"
    if eds is not None:
        q += f"&eds={eds}"
    return q + "".join(f"&{k}={v}" for k, v in opts.items())


# -- 1: a drive without 0x1019 -----------------------------------------------------------------
@pytest.mark.parametrize("sync_bytes", [0, 1])
def test_a_drive_without_0x1019_numbers_syncs_by_arrival_and_host_time(tmp_path, sync_bytes):
    """CiA 301: without 0x1019 the SYNC carries no counter.  The capture reads the mapping from the
    drive (which aborts the upload of 0x1019), then numbers ticks by SYNC arrival and receive time;
    a producer that sends a counter byte anyway does not make it a modulo-2^32 counter."""
    eds = axis_eds(tmp_path / "drive.eds", overflow=None, period_us=1000)
    lost = {17, 300, 301, 302, 640}  # whole ticks (SYNC and TPDO) never sent
    ticks = Ticks(1000, 0.001, counter=lambda k: (k * 7 + 3) % 256 if sync_bytes else None,
                  late=small_jitter(1, 0.0001), unsent=lost)
    summary, log = VirtualPeer(eds).record(canopen_query(), canopen_wire(ticks), tmp_path)
    assert_exact(summary, log, ticks)
    assert log.metadata["stream"]["sync_counter_overflow"] == 0
    assert log.t[-1] - log.t[0] == pytest.approx(0.999)


# -- 2: one repeated SYNC ----------------------------------------------------------------------
def test_one_repeated_sync_frame_is_ignored_not_read_as_a_wrap(tmp_path):
    eds = axis_eds(tmp_path / "drive.eds", overflow=240, period_us=1000)
    ticks = Ticks(1200, 0.001, counter=lambda k: k % 240 + 1, late=small_jitter(2, 0.0001))

    def repeat(w: Wire, k: int) -> None:
        if k in (40, 500):  # the same SYNC again, after its TPDO (once while the rate is still unknown)
            w.send(ticks.ts(k) + 0.0002, 0x80, [ticks.counter(k)])

    summary, log = VirtualPeer(eds).record(canopen_query(), canopen_wire(ticks, extra=repeat), tmp_path)
    assert_exact(summary, log, ticks)
    assert summary.dropped == 0 and summary.received == 1200


# -- 3: silences longer than a counter wrap ------------------------------------------------------
def test_sync_counter_overflow_16_at_500_hz_bridges_silences_of_50_and_80_ms(tmp_path):
    eds = axis_eds(tmp_path / "drive.eds", overflow=16, period_us=2000)
    silent = set(range(400, 425)) | set(range(900, 940))  # 50 ms and 80 ms: 25 and 40 ticks, wraps of 32 ms
    ticks = Ticks(1500, 0.002, counter=lambda k: k % 16 + 1, late=small_jitter(3, 0.0003), unsent=silent)
    summary, log = VirtualPeer(eds).record(canopen_query(), canopen_wire(ticks), tmp_path)
    assert_exact(summary, log, ticks)
    assert summary.dropped == 65


def test_a_counterless_sync_bridges_a_300_ms_silence(tmp_path):
    eds = axis_eds(tmp_path / "drive.eds", overflow=None, period_us=2000)
    ticks = Ticks(1500, 0.002, counter=lambda k: None, late=small_jitter(4, 0.0003), unsent=set(range(600, 750)))
    summary, log = VirtualPeer(eds).record(canopen_query(), canopen_wire(ticks), tmp_path)
    assert_exact(summary, log, ticks)
    assert summary.dropped == 150


def test_a_dbc_4_bit_counter_at_1_khz_bridges_a_50_ms_pause(tmp_path):
    db = counter_dbc(tmp_path / "ctrl.dbc", bits=4)
    ticks = Ticks(1200, 0.001, counter=lambda k: k % 16, late=small_jitter(5, 0.0002), unsent=set(range(500, 550)))
    summary, log = VirtualPeer().record(f"dbc={tmp_path / 'ctrl.dbc'}&period=0.001&timeout=2",
                                        dbc_wire(ticks, db), tmp_path)
    assert_exact(summary, log, ticks)
    assert summary.dropped == 50


def stalls(every: int, length: int, first: int = 150) -> Callable[[int], float]:
    """The 1 kHz sender stalls ``length`` ticks every ``every`` ticks (from ``first``), then sends what it
    held in a burst, 40 us a tick, just before the tick that ends the stall."""
    def late(k: int) -> float:
        j = (k - first) % every
        return (length - j) * (1e-3 - 40e-6) if k >= first and j < length else 0.0
    return late


def test_jitter_too_large_for_a_4_bit_counter_stops_at_the_pause_with_one_error(tmp_path):
    """Frames held back up to 9 ms by a 1 kHz sender whose counter wraps every 16 ms: after a
    50 ms pause, 51 and 35 ticks from the last one are both plausible; the capture says so and stops there."""
    db = counter_dbc(tmp_path / "ctrl.dbc", bits=4)
    ticks = Ticks(1200, 0.001, counter=lambda k: k % 16, late=stalls(every=100, length=9, first=120),
                  unsent=set(range(500, 550)))
    summary, log = VirtualPeer().record(f"dbc={tmp_path / 'ctrl.dbc'}&period=0.001&timeout=2",
                                        dbc_wire(ticks, db), tmp_path)
    k = assert_stopped(summary, log, ticks, "the host clock cannot tell how many ticks passed (51 or 35)")
    assert k[-1] == 499


@pytest.mark.parametrize("stall", [17, 24])
def test_a_sender_stall_longer_than_a_wrap_is_never_read_as_a_silence(tmp_path, stall):
    """A sender that holds back more than a wrap of a 4-bit counter and then bursts: the first late frame
    looks like the end of a silence; the capture stops without recording it under a wrong tick."""
    db = counter_dbc(tmp_path / "ctrl.dbc", bits=4)
    ticks = Ticks(800, 0.001, counter=lambda k: k % 16, late=stalls(every=10_000, length=stall, first=400))
    summary, log = VirtualPeer().record(f"dbc={tmp_path / 'ctrl.dbc'}&period=0.001&timeout=2",
                                        dbc_wire(ticks, db), tmp_path)
    k = assert_stopped(summary, log, ticks, "the log ends there")
    assert k[-1] == 399


def test_a_counterless_sync_with_jitter_over_half_a_period_stops_with_one_error(tmp_path):
    eds = axis_eds(tmp_path / "drive.eds", overflow=None, period_us=2000)
    ticks = Ticks(1000, 0.002, counter=lambda k: None, late=lambda k: 0.0013 if k == 300 else 0.0)
    summary, log = VirtualPeer(eds).record(canopen_query(), canopen_wire(ticks), tmp_path)
    k = assert_stopped(summary, log, ticks, "the host clock cannot tell how many ticks passed (2 or 1)")
    assert k[-1] == 299


# -- 4: a controller that restarts ---------------------------------------------------------------
def test_a_sync_counter_that_restarts_stops_the_capture_at_the_restart(tmp_path):
    eds = axis_eds(tmp_path / "drive.eds", overflow=240, period_us=1000)
    ticks = Ticks(1500, 0.001, counter=lambda k: k % 240 + 1 if k < 700 else (k - 700) % 240 + 1,
                  late=small_jitter(6, 0.0001))
    summary, log = VirtualPeer(eds).record(canopen_query(), canopen_wire(ticks), tmp_path)
    k = assert_stopped(summary, log, ticks, "jumped by 21 (220 -> 1)")
    assert "the controller restarted or its counter was reset" in summary.error
    assert "(after counter 699); the log ends there" in summary.error
    assert k[-1] == 699


def test_a_restart_early_in_the_capture_is_caught_too(tmp_path):
    eds = axis_eds(tmp_path / "drive.eds", overflow=240, period_us=1000)
    ticks = Ticks(600, 0.001, counter=lambda k: k % 240 + 1 if k < 50 else (k - 50) % 240 + 1)
    summary, log = VirtualPeer(eds).record(canopen_query(), canopen_wire(ticks), tmp_path)
    k = assert_stopped(summary, log, ticks, "jumped by 191 (50 -> 1)")
    assert "(after counter 49); the log ends there" in summary.error
    assert k[-1] == 49


def test_a_drive_boot_up_message_stops_the_capture(tmp_path):
    eds = axis_eds(tmp_path / "drive.eds", overflow=240, period_us=1000)
    ticks = Ticks(1000, 0.001, counter=lambda k: k % 240 + 1)

    def bootup(w: Wire, k: int) -> None:
        if k == 600:  # node 1 restarts: CiA 301 boot-up (0x701, one byte 0), its counter runs on
            w.send(ticks.ts(k) + 0.0005, 0x701, [0])

    summary, log = VirtualPeer(eds).record(canopen_query(), canopen_wire(ticks, extra=bootup), tmp_path)
    k = assert_stopped(summary, log, ticks, "node 1 sent its NMT boot-up message (0x701): it restarted")
    assert k[-1] == 600


def test_a_dbc_counter_jumping_back_stops_the_capture(tmp_path):
    db = counter_dbc(tmp_path / "ctrl.dbc", bits=16)
    ticks = Ticks(1200, 0.001, counter=lambda k: k if k < 800 else k - 800)
    summary, log = VirtualPeer().record(f"dbc={tmp_path / 'ctrl.dbc'}&period=0.001&timeout=2",
                                        dbc_wire(ticks, db), tmp_path)
    k = assert_stopped(summary, log, ticks, "the DBC counter (16 bits) jumped by 64737 (799 -> 0)")
    assert k[-1] == 799


# -- 11: a silent bus, and frames that make no sample -------------------------------------------
def test_a_silent_can_bus_is_one_error_and_writes_no_log(tmp_path):
    chan = f"silent-{uuid.uuid4().hex[:6]}"
    out = tmp_path / "log.mcap"
    with pytest.raises(TransportTimeout, match=r"^no CAN frame in 0\.3 s on virtual silent-\w+: nothing is sending"):
        capture(f"can://virtual/{chan}?node=1&sdo=0&timeout=0.3", out, progress=False)
    assert not out.exists()


@pytest.mark.parametrize("case, says", [
    ("syncs without tpdos", "ticks that did not bring a position frame from every axis"),
    ("tpdos without syncs", "position frames that no SYNC (COB-ID 0x80, from 0x1005) came before"),
])
def test_frames_that_make_no_sample_end_the_capture_unusable(tmp_path, case, says):
    ticks = Ticks(300, 0.001, counter=lambda k: k % 240 + 1)
    w = canopen_wire(ticks, nodes=(2,))  # node 2's TPDOs: the capture reads node 1
    if case == "tpdos without syncs":
        w = canopen_wire(ticks)
        w.frames = [m for m in w.frames if m.arbitration_id != 0x80]
    w.frames = [m for m in w.frames if m.arbitration_id != 0x180 + STATUS_NODE]  # no end of program
    summary, log = VirtualPeer().record("node=1&sdo=0&scale=1&timeout=5", w, tmp_path, duration=0.2)
    assert summary.received == 0 and summary.end == "unusable data"
    assert "sample records arrived but none could be recorded" in summary.error and says in summary.error


# -- the same over udp_multicast, `agent capture` as its own process, the peer in real time ----------
class RealTimePeer:
    """A CiA 402 drive (LocalNode from an EDS, answering SDO uploads) and SYNC producer on
    udp_multicast, sending each tick when it is due once the capture has read 0x1006."""

    def __init__(self, eds: Path, ticks: Ticks) -> None:
        self.ticks = ticks
        self.group, self.port = f"239.74.163.{random.randint(2, 254)}", random.randint(20000, 60000)
        self.net = canopen.Network()
        self.started = threading.Event()
        for nid, path in ((1, eds), (STATUS_NODE, STATUS_EDS)):
            node = canopen.LocalNode(nid, canopen.import_od(str(path), nid))
            node.add_read_callback(self._on_read)
            self.net.add_node(node)
        self.net.connect(interface="udp_multicast", channel=self.group, port=self.port, hop_limit=0)
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def url(self, **opts) -> str:
        q = f"port={self.port}&ttl=0&node=1&status={STATUS_NODE}&scale=1"
        return f"can://udp_multicast/{self.group}?{q}" + "".join(f"&{k}={v}" for k, v in opts.items())

    def _on_read(self, index: int, subindex: int, od) -> None:
        if index == 0x1006:
            self.started.set()

    def _run(self) -> None:
        if not self.started.wait(30):
            return
        time.sleep(0.05)
        bus, T = self.net.bus, self.ticks.period
        t0 = time.monotonic()
        for k in self.ticks.sent():
            time.sleep(max(0.0, t0 + k * T - time.monotonic()))
            c = self.ticks.counter(k)
            bus.send(can.Message(arbitration_id=0x80, is_extended_id=False, data=[] if c is None else [c]))
            bus.send(can.Message(arbitration_id=0x181, is_extended_id=False, data=struct.pack("<ii", k, -k)))
        for _ in range(3):
            bus.send(can.Message(arbitration_id=0x180 + STATUS_NODE, is_extended_id=False,
                                 data=struct.pack("<HB", 0, 2)))
            time.sleep(0.1)

    def close(self) -> None:
        self.thread.join(30)
        self.net.disconnect()


def agent_capture(url: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "agent.cli", "capture", "--port", url, "-o", "log.mcap"],
                          cwd=cwd, capture_output=True, text=True, timeout=120)


def one_error_line(res: subprocess.CompletedProcess) -> str:
    assert res.returncode == 1 and "Traceback" not in res.stderr, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, res.stderr
    return lines[0]


multicast = pytest.mark.skipif(not udp_multicast_available(), reason=UDP_MULTICAST_NEEDS)


@pytest.mark.slow
@multicast
@pytest.mark.parametrize("overflow", [16, None])
def test_agent_capture_bridges_real_silences_or_says_it_cannot(tmp_path, overflow):
    """In real time the receive times jitter with this machine's load: the capture numbers every
    tick exactly, or stops with one error line that the host clock could not tell (never exit 0
    with wrong times).  SYNC counter 16 at 500 Hz with 50 and 80 ms silences; a drive without
    0x1019 (SYNC without counter) with the same silences."""
    eds = axis_eds(tmp_path / "drive.eds", overflow=overflow, period_us=2000)
    ticks = Ticks(1500, 0.002, counter=(lambda k: k % 16 + 1) if overflow else (lambda k: None),
                  unsent=set(range(400, 425)) | set(range(900, 940)))
    peer = RealTimePeer(eds, ticks)
    try:
        res = agent_capture(peer.url(), tmp_path)  # the capture's EDS is the fixture's: 0x1019 read by SDO
    finally:
        peer.close()
    log = load_mcap(tmp_path / "log.mcap")  # (it may hold a single sample, which load_recording refuses)
    summary = log.metadata["summary"]
    if res.returncode == 0:
        k = assert_every_sample_exact(log, ticks.period)
        assert summary["dropped"] == (k[-1] - k[0] + 1) - len(k) == 65 and k[-1] == ticks.n - 1
    else:
        line = one_error_line(res)
        assert "the host clock cannot tell" in line or "jitter too much to number ticks by arrival" in line, line
        assert log.metadata["summary"]["end"] == "unusable data"
        assert_every_sample_exact(log, ticks.period)


@pytest.mark.slow
@multicast
def test_agent_capture_of_a_restarting_controller_exits_1_with_one_line(tmp_path):
    eds = axis_eds(tmp_path / "drive.eds", overflow=240, period_us=1000)
    ticks = Ticks(1200, 0.001, counter=lambda k: k % 240 + 1 if k < 700 else (k - 700) % 240 + 1)
    peer = RealTimePeer(eds, ticks)
    try:
        res = agent_capture(peer.url(eds=eds), tmp_path)
    finally:
        peer.close()
    line = one_error_line(res)
    assert "jumped by 21 (220 -> 1)" in line and "restarted or its counter was reset" in line, line
    assert "(after counter 699)" in line
    log = load_recording(tmp_path / "log.mcap")
    k = assert_every_sample_exact(log, ticks.period)
    assert k[-1] == 699 and log.metadata["summary"]["end"] == "controller restarted"


@pytest.mark.slow
@multicast
def test_agent_capture_on_a_silent_bus_exits_1_with_one_line_and_no_file(tmp_path):
    res = agent_capture(f"can://udp_multicast/239.74.163.{random.randint(2, 254)}?port={random.randint(20000, 60000)}"
                        "&ttl=0&node=1&sdo=0&timeout=0.5", tmp_path)
    assert "nothing is sending on this bus" in one_error_line(res)
    assert not (tmp_path / "log.mcap").exists()


def test_a_bus_with_only_the_status_node_talking_is_a_silent_bus(tmp_path):
    """A program-status node reporting "idle" makes no samples: no SYNC or TPDO within the timeout is
    one error before anything is written, naming the frames seen and the ones expected."""
    w = Wire()
    for i in range(40):
        w.send(T0 + 0.01 * i, 0x180 + STATUS_NODE, struct.pack("<HB", 0, 0))
    peer = VirtualPeer()
    with pytest.raises(TransportTimeout, match=r"none the capture reads \(ids seen: 0x1C0; expected 0x80, 0x181\)"):
        peer.record(f"node=1&sdo=0&status={STATUS_NODE}&timeout=0.3", w, tmp_path)
    assert not (tmp_path / "log.mcap").exists()

"""CAN driver + simulated CAN controller in one process, on python-can's real in-process `virtual` bus.

The endpoint runs in a thread, the driver reads in the test; values must come out as
the served samples rounded to the wire's 0.1 um increments, exactly.
"""

from __future__ import annotations

import socket
import struct
import threading
import time
import uuid

import can
import numpy as np
import pytest

from core.errors import InputError, TransportError, TransportTimeout
from drivers.endpoints.can_endpoint import CanEndpoint
from drivers.endpoints.source import FaultPlan, RealTimeSource, stream_info_for
from drivers.registry import open_driver
from core.recording import AxisTrace, Recording


UDP_MULTICAST_NEEDS = "python-can udp_multicast needs a multicast route (e.g. `ip route add 239.0.0.0/8 dev lo`)"


def udp_multicast_available() -> bool:
    """Whether this host can join a multicast group (it cannot in a namespace with only loopback and no route)."""
    try:
        bus = can.Bus(interface="udp_multicast", channel="239.74.163.250", port=43999, hop_limit=0)
    except can.CanError:
        return False
    bus.shutdown()
    return True


def random_walk(n: int = 2000, axes: str = "XY", Ts: float = 0.001, seed: int = 1) -> Recording:
    rng = np.random.default_rng(seed)
    tr = {}
    for a in axes:
        c = np.cumsum(rng.normal(0, 0.01, n))
        tr[a] = AxisTrace(c, c + rng.normal(0, 1e-3, n))
    seg = (np.arange(n) >= n // 2).astype(int)  # two programs: segments 0 and 1
    return Recording(np.arange(n) * Ts, tr, Ts, segment=seg)


def on_wire(values: np.ndarray, per_mm: float = 10_000.0) -> np.ndarray:
    return np.rint(values * per_mm) / per_mm


class Served:
    """An endpoint serving ``rec`` on a fresh virtual channel from a thread."""

    def __init__(self, rec: Recording, faults: FaultPlan | None = None, speed: float = float("inf"), **options):
        self.source = RealTimeSource(rec, speed=speed, faults=faults or FaultPlan())
        options = {"interface": "virtual", "channel": f"test-{uuid.uuid4().hex[:8]}", "linger": 0.2, **options}
        self.ep = CanEndpoint(self.source, stream_info_for(rec), options)
        self.ep.start()
        self.url = self.ep.port_url()
        self.thread = threading.Thread(target=self.ep.run, daemon=True)

    def open(self, drv):
        """Open ``drv`` while the endpoint starts serving: the driver's open waits for the first
        frame, and a DBC endpoint on `virtual` streams at once, so it starts once the driver's bus exists."""
        result = {}

        def opening() -> None:
            try:
                result["info"] = drv.open()
            except BaseException as exc:  # noqa: BLE001 - re-raised in the test's thread
                result["error"] = exc

        opener = threading.Thread(target=opening, daemon=True)
        opener.start()
        t0 = time.monotonic()
        while drv._bus is None and opener.is_alive() and time.monotonic() - t0 < 5:
            time.sleep(0.001)
        self.thread.start()
        opener.join(10)
        if "error" in result:
            raise result["error"]
        return result["info"]

    def __enter__(self) -> "Served":
        return self

    def __exit__(self, *exc) -> None:
        self.ep.stop_event.set()
        self.thread.join(5)
        self.ep.close()


def read_all(drv, limit_s: float = 10.0) -> list:
    out, t0 = [], time.monotonic()
    while not drv.ended and time.monotonic() - t0 < limit_s:
        out += drv.read(0.05)
    return out


def test_canopen_capture_equals_the_served_samples_exactly():
    rec = random_walk()
    with Served(rec) as srv:
        drv = open_driver(srv.url)
        info = srv.open(drv)  # reads the mapping by SDO; the endpoint starts on the 0x1006 read
        out = read_all(drv)
        drv.close()
    assert info.axes == ("X", "Y") and info.sample_period == pytest.approx(0.001)
    assert info.extra["mapping_from"] == "sdo" and info.extra["nodes"] == [1, 2]
    assert drv.ended
    assert [s.counter for s in out] == list(range(rec.n_samples))
    for i, a in enumerate("XY"):
        assert np.array_equal([s.commanded[i] for s in out], on_wire(rec.axes[a].commanded))
        assert np.array_equal([s.actual[i] for s in out], on_wire(rec.axes[a].actual))
    assert np.array_equal([s.segment for s in out], rec.segment)
    assert np.allclose([s.t_s for s in out], rec.t)
    assert drv.stats.corrupt == 0


def test_dropped_and_corrupted_frames_are_counted_exactly_and_never_decoded():
    rec = random_walk(3000, "XYZ")
    with Served(rec, FaultPlan(drop_rate=0.02, corrupt_rate=0.02, seed=7)) as srv:
        drv = open_driver(srv.url)
        srv.open(drv)
        out = read_all(drv)
        drv.close()
        report = srv.source.fault_report()
    assert report["dropped"] > 20 and report["corrupted"] > 20
    got = [s.counter for s in out]
    missing = sorted(set(range(rec.n_samples)) - set(got))
    assert missing == sorted(report["dropped_counters"] + report["corrupted_counters"])
    assert drv.stats.corrupt == report["corrupted"]  # each a TPDO with 6 bytes instead of 8
    assert drv._asm.lost_ticks == report["dropped"] + report["corrupted"]
    cmd = np.array([s.commanded for s in out])
    act = np.array([s.actual for s in out])
    for i, a in enumerate("XYZ"):
        assert np.array_equal(cmd[:, i], on_wire(rec.axes[a].commanded)[got])
        assert np.array_equal(act[:, i], on_wire(rec.axes[a].actual)[got])


def test_dbc_frames_decode_exactly_with_segments_and_end():
    rec = random_walk(1500, "XYZABC")
    with Served(rec, FaultPlan(corrupt_rate=0.01, seed=2), protocol="dbc", wait=False) as srv:
        assert "dbc=" in srv.url and "period=0.001" in srv.url
        drv = open_driver(srv.url)
        srv.open(drv)  # DBC: nothing to read from the controller; the bus exists before it streams
        out = read_all(drv)
        drv.close()
        report = srv.source.fault_report()
    got = [s.counter for s in out]
    assert drv.ended and drv.stats.corrupt == report["corrupted"] > 0
    assert sorted(set(range(rec.n_samples)) - set(got)) == report["corrupted_counters"]
    cmd = np.array([s.commanded for s in out])
    for i, a in enumerate("XYZABC"):
        assert np.array_equal(cmd[:, i], on_wire(rec.axes[a].commanded)[got])
    assert np.array_equal([s.segment for s in out], rec.segment[got])


def test_axes_subset_reads_only_those_nodes():
    rec = random_walk(500, "XYZ")
    with Served(rec) as srv:
        drv = open_driver(srv.url, ["Z", "X"])
        info = srv.open(drv)
        out = read_all(drv)
        drv.close()
    assert info.axes == ("Z", "X") and info.extra["nodes"] == [3, 1]
    assert len(out) == 500
    assert np.array_equal([s.commanded[0] for s in out], on_wire(rec.axes["Z"].commanded))


def test_the_driver_only_sends_sdo_upload_requests():
    """SPEC §8: capture is passive - no NMT, no RPDO, no SDO download, no SYNC unless sync=1."""
    rec = random_walk(300)
    with Served(rec) as srv:
        chan = srv.url.split("/")[3].split("?")[0]
        monitor = can.Bus(interface="virtual", channel=chan)
        drv = open_driver(srv.url)
        srv.open(drv)
        read_all(drv)
        drv.close()
    frames = []
    while (m := monitor.recv(0.05)) is not None:
        frames.append(m)
    monitor.shutdown()
    requests = [m for m in frames if 0x600 < m.arbitration_id <= 0x67F]
    assert requests, "expected the mapping to be read by SDO"
    assert all(m.data[0] in (0x40, 0x60, 0x70) for m in requests)  # upload initiate / upload segment
    others = {m.arbitration_id for m in frames} - {m.arbitration_id for m in requests}
    # everything else on the bus came from the simulated controller
    assert others <= {0x80, 0x181, 0x182, 0x1C0} | {0x580 + n for n in (1, 2, 64)}


def test_to_an_absent_node_the_driver_sends_upload_requests_then_one_sdo_abort():
    """The only frame beyond reads: canopen ends the unanswered upload with an SDO abort
    (0x80, code 0x05040000 "SDO protocol timed out"), which changes nothing in a drive."""
    chan = f"absent-{uuid.uuid4().hex[:6]}"
    monitor = can.Bus(interface="virtual", channel=chan)
    drv = open_driver(f"can://virtual/{chan}?nodes=7")
    with pytest.raises(TransportError, match=r"node 7 did not answer"):
        drv.open()
    drv.close()
    frames = []
    while (m := monitor.recv(0.05)) is not None:
        frames.append(m)
    monitor.shutdown()
    assert {m.arbitration_id for m in frames} == {0x607}
    assert [m.data[0] for m in frames][-1] == 0x80
    assert all(m.data[0] == 0x40 for m in frames[:-1])
    assert int.from_bytes(frames[-1].data[4:8], "little") == 0x05040000


def test_sync_1_makes_the_capture_the_sync_producer():
    """With sync=1 the driver sends SYNC (with counter) at `period`; drives answer each SYNC."""
    chan = f"test-{uuid.uuid4().hex[:8]}"
    drive = can.Bus(interface="virtual", channel=chan)
    stop = threading.Event()
    seen_ids = set()

    def drives() -> None:  # two CiA 402 nodes answering SYNC with TPDO1 = (demand, actual)
        while not stop.is_set():
            m = drive.recv(0.05)
            if m is None:
                continue
            seen_ids.add(m.arbitration_id)
            if m.arbitration_id == 0x80:
                c = m.data[0]
                for node in (1, 2):
                    drive.send(can.Message(arbitration_id=0x180 + node, is_extended_id=False,
                                           data=struct.pack("<ii", 1000 * node + c, -c)))

    th = threading.Thread(target=drives, daemon=True)
    th.start()
    drv = open_driver(f"can://virtual/{chan}?nodes=1,2&sync=1&period=0.05&sdo=0")
    info = drv.open()
    out = []
    t0 = time.monotonic()
    while len(out) < 30 and time.monotonic() - t0 < 5:
        out += drv.read(0.05)
    drv.close()
    stop.set()
    th.join(2)
    drive.shutdown()
    assert info.extra["sync_producer"] == "capture"
    assert seen_ids == {0x80}  # the only frame the capture sent
    assert len(out) >= 30 and info.sample_period == 0.05
    counters = [s.counter for s in out]
    # TPDOs carry no counter: a drive must answer before the next SYNC (a real one answers within
    # microseconds; this Python thread gets a 50 ms period to be sure to, even on a loaded machine).
    assert counters == list(range(counters[0], counters[0] + len(out)))
    for s in out:
        c = s.counter % 240 + 1
        assert s.commanded == ((1000 + c) / 10000, (2000 + c) / 10000) and s.actual == (-c / 10000, -c / 10000)


@pytest.mark.parametrize("query, message", [
    ("axes=X", r"give the drives' node ids"),
    ("nodes=1,2&axes=X", r"1 axes for 2 nodes"),
    ("nodes=1,1", r"node ids must be distinct"),
    ("nodes=1&bogus=3", r"unknown option 'bogus'"),
    ("nodes=1,2&scale=1,2,3", r"scale needs one positive value or one per axis \(2\)"),
    ("nodes=1&status=1", r"status node 1 must be 1..127 and not an axis node"),
    ("nodes=1&sdo=0&eds=/nonexistent.eds", r"EDS file /nonexistent.eds not found"),
    ("dbc=/nonexistent.dbc", r"DBC file /nonexistent.dbc not found"),
    ("nodes=1&dbc=x.dbc", r"option nodes= is for CANopen"),
])
def test_bad_urls_are_one_line_errors(query, message):
    with pytest.raises(InputError, match=message):
        drv = open_driver(f"can://virtual/bad-{uuid.uuid4().hex[:6]}?{query}")
        try:
            drv.open()
        finally:
            drv.close()


def test_a_drive_that_does_not_answer_sdo_is_a_clear_error():
    drv = open_driver(f"can://virtual/none-{uuid.uuid4().hex[:6]}?nodes=1")
    with pytest.raises(TransportError, match=r"node 1 did not answer the SDO upload of its TPDO mapping"):
        drv.open()
    drv.close()


@pytest.mark.skipif(not udp_multicast_available(), reason=UDP_MULTICAST_NEEDS)
def test_garbage_datagrams_on_udp_multicast_count_as_corrupt_and_a_silent_bus_times_out():
    group, port = "239.74.163.251", None
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    drv = open_driver(f"can://udp_multicast/{group}?port={port}&nodes=1&sdo=0&timeout=0.3")
    tx = can.Bus(interface="udp_multicast", channel=group, port=port, hop_limit=0)
    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    raw.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)

    def send() -> None:  # once the driver has joined the group (its open waits for the first frame)
        time.sleep(0.1)
        raw.sendto(b"\x00not a CAN frame", (group, port))
        for k in range(3):
            tx.send(can.Message(arbitration_id=0x80, is_extended_id=False, data=[k + 1]))
            tx.send(can.Message(arbitration_id=0x181, is_extended_id=False, data=struct.pack("<ii", k, -k)))

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    try:
        drv.open()
        sender.join(5)
        out = []
        with pytest.raises(TransportTimeout, match=r"no CAN frame for 0\.\d s"):
            for _ in range(40):
                out += drv.read(0.05)
        assert [s.counter for s in out] == [0, 1, 2]
        assert drv.stats.corrupt == 1
    finally:
        raw.close()
        tx.shutdown()
        drv.close()


def test_slcan_adapter_over_a_pseudo_terminal():
    """The same driver on python-can's serial-line (slcan) interface: frames as ASCII lines on a pty."""
    import os
    import tty

    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    drv = open_driver(f"can://slcan/{path}?nodes=1,2&axes=X,Y&sdo=0&status=64")
    ticks = []  # the adapter's lines of each 1 ms tick
    for k in range(300):
        lines = ["t0801%02X" % (k % 240 + 1)]  # SYNC with counter
        if k == 100:
            lines.append("t1C03010001")  # program status: segment 1, running
        for node in (1, 2):
            payload = struct.pack("<ii", node * 10_000 + k, -k)
            if (k, node) == (120, 1):
                payload = payload[:7]  # node 1's TPDO with 7 bytes: malformed, never decoded
            lines.append("t%03X%d%s" % (0x180 + node, len(payload), payload.hex().upper()))
        ticks.append("".join(ln + "\r" for ln in lines).encode())
    ticks.append(b"t1C03010002\r")  # program ended

    def adapter() -> None:
        got = b""
        while b"O\r" not in got:  # python-can opens the channel: the adapter starts forwarding frames
            got += os.read(master, 64)
        t0 = time.monotonic()
        for k in range(0, len(ticks), 5):  # as they appear on the bus: 1 ms apart, forwarded every 5 ms
            time.sleep(max(0.0, t0 + (k + 4) * 0.001 - time.monotonic()))  # when its last tick is due
            os.write(master, b"".join(ticks[k:k + 5]))

    writer = threading.Thread(target=adapter, daemon=True)
    writer.start()
    info = drv.open()  # python-can writes "O\r" (open channel); the "adapter" here ignores commands
    out = []
    t0 = time.monotonic()
    while not drv.ended and time.monotonic() - t0 < 10:
        out += drv.read(0.05)
    drv.close()
    writer.join(5)
    os.close(master)
    os.close(slave)
    assert info.axes == ("X", "Y") and drv.ended
    assert [s.counter for s in out] == [k for k in range(300) if k != 120]
    assert drv.stats.corrupt == 1
    assert out[0].commanded == (1.0, 2.0) and out[-1].actual == (-299 / 10_000, -299 / 10_000)
    assert [s.segment for s in out].index(1) == 100


@pytest.mark.parametrize("options, message", [
    ({"protocol": "j1939"}, r"protocol='j1939' \(use canopen or dbc\)"),
    ({"nodes": "1,2,3"}, r"need 2 node ids in 1..127 \(one per axis\), got \[1, 2, 3\]"),
    ({"status": 2}, r"status node 2 must be 0..127 and not an axis node"),
    ({"scale": 1e12}, r"does not fit INTEGER32 at 1e\+12 increments per mm; lower the scale option"),
    ({"bogus": 1}, r"unknown option 'bogus'"),
])
def test_bad_endpoint_options_are_one_line_errors(options, message):
    rec = random_walk(10)
    with pytest.raises(InputError, match=message):
        CanEndpoint(RealTimeSource(rec), stream_info_for(rec), {"interface": "virtual", **options})


def test_the_endpoint_url_names_everything_a_capture_needs():
    rec = random_walk(10, "XYZ", Ts=0.0005)
    ep = CanEndpoint(RealTimeSource(rec), stream_info_for(rec), {"nodes": "5,6,7", "status": 9, "scale": 1000})
    ep.start()
    try:
        url = ep.port_url()
    finally:
        ep.close()
    assert url.startswith(f"can://udp_multicast/{ep.channel}?port={ep.udp_port}&ttl=0&")
    assert url.endswith("&nodes=5,6,7&axes=X,Y,Z&status=9&scale=1000.0&period=0.0005")


def test_a_bus_where_nothing_is_sent_is_a_clear_timeout_while_opening():
    drv = open_driver(f"can://virtual/empty-{uuid.uuid4().hex[:6]}?nodes=1&sdo=0&timeout=0.2")
    try:
        with pytest.raises(TransportTimeout, match=r"no CAN frame in 0\.2 s on virtual empty-\w+: nothing is sending"):
            drv.open()
    finally:
        drv.close()


def test_a_bus_carrying_only_other_frames_names_them_while_opening():
    chan = f"others-{uuid.uuid4().hex[:6]}"
    other = can.Bus(interface="virtual", channel=chan)
    drv = open_driver(f"can://virtual/{chan}?nodes=1&sdo=0&timeout=0.3")
    stop = threading.Event()

    def chatter() -> None:
        while not stop.is_set():
            other.send(can.Message(arbitration_id=0x123, is_extended_id=False, data=[1, 2]))
            time.sleep(0.01)

    th = threading.Thread(target=chatter, daemon=True)
    th.start()
    try:
        with pytest.raises(TransportTimeout, match=r"CAN frames arrive on virtual others-\w+ but in 0\.3 s none the "
                                                   r"capture reads \(ids seen: 0x123; expected 0x80, 0x181\)"):
            drv.open()
    finally:
        stop.set()
        th.join(2)
        drv.close()
        other.shutdown()

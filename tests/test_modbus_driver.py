"""The Modbus driver against the simulated controller on a real TCP socket and a real pseudo-terminal.

The endpoint runs in this process (its pymodbus server on its own event-loop thread);
the driver talks to it through the kernel exactly as across processes.  Positions are
compared exactly after the wire scaling ``count = rint(mm / scale_mm)``.
"""

from __future__ import annotations

import socket
import threading
import time
from contextlib import contextmanager

import numpy as np
import pytest
from pymodbus.client import ModbusTcpClient
from pymodbus.pdu import DecodePDU

from core.errors import InputError, TransportError
from drivers.endpoints.modbus_endpoint import ModbusEndpoint
from drivers.endpoints.source import FaultPlan, RealTimeSource, stream_info_for
from drivers.modbus_map import default_map
from drivers.registry import open_driver
from drivers.transports.modbus import ALLOWED_FUNCTION_CODES, ModbusDriver, ReadOnlyViolation, _read_only_guard
from core.recording import AxisTrace, Recording

SCALE = 1e-6  # mm per count of the default map


def random_walk(n: int, axes: str = "XYZ", seed: int = 0) -> Recording:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.001
    traces = {a: AxisTrace(np.cumsum(rng.normal(0, 0.01, n)) + 5.0, np.cumsum(rng.normal(0, 0.01, n)) - 5.0)
              for a in axes}
    seg = (np.arange(n) >= n // 2).astype(np.int32)  # two programs
    return Recording(t, traces, 0.001, segment=seg,
                     metadata={"controller": "test CNC", "programs": [{"name": "p1.nc", "sha256": "ab" * 32},
                                                                      {"name": "p2.nc", "sha256": "cd" * 32}]})


@contextmanager
def serving(rec: Recording, speed: float = 1.0, faults: FaultPlan | None = None, **options):
    src = RealTimeSource(rec, speed=speed, faults=faults or FaultPlan())
    ep = ModbusEndpoint(src, stream_info_for(rec), dict({"linger": 0.5}, **options))
    ep.start()
    th = threading.Thread(target=ep.run, daemon=True)
    th.start()
    try:
        yield ep, src
    finally:
        ep.stop_event.set()
        th.join(5)
        ep.close()


def capture_all(url: str, limit_s: float = 10.0):
    drv = open_driver(url)
    info = drv.open()
    samples = []
    t_end = time.monotonic() + limit_s
    try:
        while not drv.ended and time.monotonic() < t_end:
            samples += drv.read(0.2)
    finally:
        drv.close()
    return drv, info, samples


def wire(values: np.ndarray, scale: float = SCALE) -> np.ndarray:
    """What survives the register encoding: whole counts, as the exact decimal count x 10^-k
    (count / 10^k, never count * 1e-6, which misses the decimal in a third of the cases)."""
    return np.rint(values / scale) / round(1 / scale)


def assert_exact(samples, src: RealTimeSource, cols=None, scale: float = SCALE) -> np.ndarray:
    k = np.array([s.counter for s in samples])
    cols = list(range(len(src.axes))) if cols is None else cols
    cmd = np.array([s.commanded for s in samples])
    act = np.array([s.actual for s in samples])
    assert np.array_equal(cmd, wire(src.commanded[k][:, cols], scale))
    assert np.array_equal(act, wire(src.actual[k][:, cols], scale))
    assert [s.segment for s in samples] == src.recording.segment[k].tolist()
    assert np.allclose([s.t_s for s in samples], k * 0.001)
    return k


# -- trace-buffer upload -------------------------------------------------------------------

def test_trace_upload_over_tcp_gets_every_sample_exactly():
    rec = random_walk(1500)
    with serving(rec, speed=2.0) as (ep, src):
        url = ep.port_url()
        assert url.startswith("modbus-tcp://127.0.0.1:") and "mode=trace" in url
        drv, info, samples = capture_all(url)
        codes = ep.function_codes
    assert info.axes == ("X", "Y", "Z") and info.sample_period == 0.001
    assert info.controller == "test CNC"
    assert [p["name"] for p in info.programs] == ["p1.nc", "p2.nc"] and info.programs[0]["sha256"] == "ab" * 32
    assert drv.ended
    k = assert_exact(samples, src)
    assert k.tolist() == list(range(1500))
    assert drv.stats.as_dict() == {"received": 1500, "dropped": 0, "corrupt": 0, "reconnects": 0, "skipped": 0}
    assert drv.gaps == 0
    assert set(codes) == {3}  # reads of holding registers only


def test_positions_are_the_exact_decimal_of_the_nanometre_counts():
    """-2486899 counts at 1e-6 mm are -2.486899 mm, as CAN and serial give it: count / 10^6,
    never count * 1e-6 = -2.4868989999999997 (which a third of all counts would become)."""
    rec = random_walk(600, axes="X")
    rec.axes["X"].commanded[:3] = [-2.486899, -2.486902, 1.2345]
    with serving(rec, speed=4.0) as (ep, src):
        drv, info, samples = capture_all(ep.port_url())
    values = [v for s in samples for v in (*s.commanded, *s.actual)]
    assert len(values) == 1200
    assert [s.commanded[0] for s in samples[:3]] == [-2.486899, -2.486902, 1.2345]
    assert all(len(repr(v).partition(".")[2]) <= 6 for v in values)  # the shortest repr is the decimal


def test_trace_upload_over_an_rtu_pseudo_terminal_gets_every_sample_exactly():
    rec = random_walk(1200, axes="XY")
    with serving(rec, link="rtu", baud=115200) as (ep, src):
        url = ep.port_url()
        assert url.startswith("modbus-rtu:///dev/pts/") and "baud=115200" in url
        drv, info, samples = capture_all(url)
        codes = ep.function_codes
    k = assert_exact(samples, src)
    assert k.tolist() == list(range(1200))
    assert drv.stats.corrupt == 0 and drv.gaps == 0
    assert set(codes) == {3}


@pytest.mark.parametrize("link", ["tcp", "rtu"])
def test_injected_drops_and_corruptions_are_counted_exactly_and_no_damaged_value_is_kept(link):
    rec = random_walk(1500, axes="XY", seed=2)
    faults = FaultPlan(drop_rate=0.02, corrupt_rate=0.02, seed=7)
    with serving(rec, link=link, faults=faults) as (ep, src):
        drv, info, samples = capture_all(ep.port_url())
        served_corrupt = ep.image.corrupted_responses
    k = assert_exact(samples, src)
    report = src.fault_report()
    assert report["dropped"] > 10 and report["corrupted"] > 10
    # the missing counters are exactly the dropped ticks; corrupted ticks arrive intact after a retry
    assert sorted(set(range(1500)) - set(k.tolist())) == report["dropped_counters"]
    assert drv.gaps == report["dropped"]
    assert drv.stats.corrupt == report["corrupted"] == served_corrupt
    assert drv.stats.dropped == 0  # gaps are the capture loop's to count


def test_tcp_disconnect_reconnects_and_recovers_the_samples_still_in_the_ring():
    rec = random_walk(1500, axes="XY")
    with serving(rec, speed=1.0, faults=FaultPlan(disconnect_at_s=0.6)) as (ep, src):
        drv, info, samples = capture_all(ep.port_url())
        disconnects = ep.disconnects
    assert disconnects == 1
    assert drv.stats.reconnects == 1
    k = assert_exact(samples, src)
    assert k.tolist() == list(range(1500))  # nothing lost: the ring kept the ticks of the outage


def test_rtu_line_outage_is_survived_and_the_ring_fills_the_hole():
    rec = random_walk(2000, axes="X")
    # An RTU link counts as lost after two timeouts in a row; a host that stalls the line for
    # that long counts a second loss (a 0.2 s timeout under the CI's load did once).  With
    # 0.4 s only the 1.5 s cut is that long.
    with serving(rec, link="rtu", outage=1.5, faults=FaultPlan(disconnect_at_s=0.3)) as (ep, src):
        drv, info, samples = capture_all(ep.port_url() + "&timeout=0.4")
    assert drv.timeouts >= 2 and drv.stats.reconnects == 1
    assert [s.counter for s in samples] == list(range(2000))
    assert_exact(samples, src)


def test_capture_started_late_uploads_what_the_ring_still_holds():
    rec = random_walk(1500, axes="XY")
    with serving(rec, speed=2.0, wait=0) as (ep, src):
        time.sleep(0.3)  # the controller runs without a client; ~600 ticks are in the ring already
        drv, info, samples = capture_all(ep.port_url())
    assert [s.counter for s in samples] == list(range(1500))


# -- live polling -------------------------------------------------------------------------

def test_a_record_a_later_lap_overwrote_is_lost_not_unusable():
    # Read slot by slot, a ring of 100: counter 0's record, then in counter 1's slot the record
    # of counter 101 (the controller overtook the reader), then in counter 2's slot one that
    # belongs in no slot of this ring (a map that does not fit reads like that).
    rec = random_walk(300)
    with serving(rec, capacity=100) as (ep, src):
        drv = open_driver(ep.port_url())
        drv.open()
        try:
            got = drv.decode_records(0, np.stack([ep.records[0], ep.records[101], ep.records[57]]))
        finally:
            drv.close()
    assert [s.counter for s in got] == [0]
    assert drv.gaps == 2 and drv.stats.skipped == 1  # the lapped record is a loss, the foreign one unusable


def test_live_polling_returns_exact_values_and_counts_unseen_ticks_as_gaps():
    rec = random_walk(1000, axes="XY")
    with serving(rec, mode="live") as (ep, src):
        url = ep.port_url()
        assert "mode=live" in url
        drv, info, samples = capture_all(url)
    assert drv.ended and samples
    k = assert_exact(samples, src)
    assert np.all(np.diff(k) > 0)
    assert drv.gaps == (k[-1] - k[0] + 1) - len(samples)
    assert k[-1] == 999  # the last tick stays in the live registers


# -- passive: only read function codes ----------------------------------------------------------

def test_guard_refuses_every_function_code_except_the_reads():
    checked = 0
    for fc, (request_cls, _response_cls) in DecodePDU.pdu_table.items():  # every PDU pymodbus knows
        pdu = request_cls()
        if fc in ALLOWED_FUNCTION_CODES:
            assert _read_only_guard(True, pdu) is pdu
        else:
            with pytest.raises(ReadOnlyViolation, match=f"function code {fc}"):
                _read_only_guard(True, pdu)
        checked += 1
    assert checked > 10
    assert ALLOWED_FUNCTION_CODES == {1, 2, 3, 4}


def test_a_write_through_the_driver_never_reaches_the_wire():
    rec = random_walk(300, axes="X")
    with serving(rec) as (ep, src):
        drv = open_driver(ep.port_url())
        drv.open()
        with pytest.raises(ReadOnlyViolation):
            drv._client.write_register(256, 0, device_id=1)
        with pytest.raises(ReadOnlyViolation):
            drv._client.write_registers(264, [1, 2], device_id=1)
        with pytest.raises(ReadOnlyViolation):
            drv._client.write_coil(0, True, device_id=1)
        assert drv.read(0.5) is not None  # the driver still works afterwards
        drv.close()
        codes = ep.function_codes
    assert set(codes) == {3}


def test_the_simulated_controller_is_read_only():
    rec = random_walk(300, axes="X")
    with serving(rec) as (ep, src):
        port = int(ep.port_url().split(":")[2].split("?")[0])
        client = ModbusTcpClient("127.0.0.1", port=port, timeout=1)
        assert client.connect()
        before = client.read_holding_registers(256, count=10, device_id=1).registers
        rr = client.write_register(256, 0xFFFF, device_id=1)
        assert rr.isError() and rr.exception_code == 1  # illegal function
        rr = client.read_input_registers(256, count=1, device_id=1)  # the default map serves holding registers
        assert rr.isError() and rr.exception_code == 1
        after = client.read_holding_registers(256, count=1, device_id=1).registers
        client.close()
    assert after[0] != 0xFFFF and before[0] != 0xFFFF  # the write did not land


# -- maps, errors ---------------------------------------------------------------------------------

def test_custom_map_input_registers_little_word_order_and_coarser_scale(tmp_path):
    rmap = default_map(["Y", "X"], scale_mm=1e-5, word_order="little")
    text = rmap.to_toml().replace('table = "holding"', 'table = "input"')
    path = tmp_path / "ctrl.toml"
    path.write_text(text)
    rec = random_walk(800, axes="XY")
    with serving(rec, map=str(path)) as (ep, src):
        url = ep.port_url()
        assert f"map={path}" in url
        drv, info, samples = capture_all(url)
        codes = ep.function_codes
    assert info.axes == ("Y", "X")
    assert_exact(samples, src, cols=[1, 0], scale=1e-5)
    assert set(codes) == {4}


def test_a_map_that_does_not_fit_the_controller_is_a_one_line_error(tmp_path):
    text = default_map(["X"]).to_toml().replace('table = "holding"', 'table = "input"')
    path = tmp_path / "wrong.toml"
    path.write_text(text)
    rec = random_walk(300, axes="X")
    with serving(rec) as (ep, src):
        drv = open_driver(ep.port_url() + f"&map={path}")
        with pytest.raises(TransportError, match=r"exception 1 \(illegal function\).*check the register map") as info:
            drv.open()
        drv.close()
    assert "\n" not in str(info.value)


def test_losing_the_controller_for_good_ends_with_a_clear_error():
    rec = random_walk(5000, axes="X")
    with serving(rec) as (ep, src):
        drv = open_driver(ep.port_url() + "&reconnect_s=1&timeout=0.2")
        drv.open()
        assert drv.read(0.5)
        ep.close()  # the controller goes away: the listener is closed too
        t0 = time.monotonic()
        with pytest.raises(TransportError, match=r"connection lost .* not re-established within 1 s"):
            for _ in range(100):
                drv.read(0.2)
        assert time.monotonic() - t0 < 5
        drv.close()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_nothing_listening_is_a_transport_error():
    drv = open_driver(f"modbus-tcp://127.0.0.1:{_free_port()}?timeout=0.2")
    with pytest.raises(TransportError, match="cannot connect"):
        drv.open()


@pytest.mark.parametrize(
    "url, message",
    [
        ("modbus-tcp://127.0.0.1:5020?mode=fast", "mode='fast'"),
        ("modbus-tcp://127.0.0.1:5020?speed=2", "unknown option 'speed'"),
        ("modbus-tcp://127.0.0.1:5020?unit=one", "unit='one' is not a valid int"),
        ("modbus-tcp://127.0.0.1:5020?unit=300", "unit=300; a Modbus unit id is 0..247"),
        ("modbus-tcp://127.0.0.1:5020?timeout=0", "timeout=0.0 must be > 0 s"),
        ("modbus-rtu:///dev/ttyUSB0?parity=X", "parity='X'"),
    ],
)
def test_bad_port_options_are_one_line_input_errors(url, message):
    with pytest.raises(InputError, match=message):
        open_driver(url)


def test_registry_picks_this_driver_for_both_schemes():
    assert isinstance(open_driver("modbus-tcp://127.0.0.1:5020"), ModbusDriver)
    assert isinstance(open_driver("modbus-rtu:///dev/ttyUSB0?baud=115200&unit=1"), ModbusDriver)


def test_a_wrong_unit_id_is_a_one_line_error_naming_the_exception():
    rec = random_walk(300, axes="X")
    with serving(rec) as (ep, src):
        drv = open_driver(ep.port_url().replace("unit=1", "unit=7"))
        with pytest.raises(TransportError, match=r"exception 11 \(gateway target failed to respond\).*unit 7"):
            drv.open()
        drv.close()

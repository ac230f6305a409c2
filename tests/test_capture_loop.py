"""The shared capture loop (drivers.capture): axis selection, duration, gap counting, stopping, errors.

Most tests capture from a real serial endpoint running in a thread of the test process
(a real pseudo-terminal); the counting rules use a small in-memory driver registered
under its own URL scheme, like python-can's virtual bus.
"""

from __future__ import annotations

import signal
import subprocess
import threading
import time
import warnings
from contextlib import contextmanager

import numpy as np
import pytest

from _capture_procs import AGENT
from core.errors import InputError, TransportError, TransportTimeout
from drivers import registry
from drivers.base import Driver, Sample, StreamInfo
from drivers.capture import capture
from drivers.endpoints.serial_endpoint import SerialEndpoint
from drivers.endpoints.source import FaultPlan, RealTimeSource, stream_info_for
from core.reader import load_mcap, load_recording
from core.recording import AxisTrace, Recording


def random_walk(n: int = 1500, axes: str = "XYZ", t0_counter: int = 0, seed: int = 0) -> Recording:
    rng = np.random.default_rng(seed)
    tr = {}
    for a in axes:
        c = np.cumsum(rng.normal(0, 0.01, n))
        tr[a] = AxisTrace(c, c + rng.normal(0, 1e-3, n))
    t = (t0_counter + np.arange(n)) * 0.001
    return Recording(t, tr, 0.001, metadata={"controller": "random walk", "programs": []})


@contextmanager
def served(rec: Recording, speed: float = 4.0, faults: FaultPlan | None = None, **options):
    ep = SerialEndpoint(RealTimeSource(rec, speed=speed, faults=faults or FaultPlan()), stream_info_for(rec),
                        options)
    ep.start()
    th = threading.Thread(target=ep.run, daemon=True)
    th.start()
    try:
        yield ep
    finally:
        ep.stop_event.set()
        th.join(5)
        ep.close()


def scaled(x):
    return np.rint(x * 10_000) / 10_000


def test_selected_axes_are_recorded_in_the_order_asked(tmp_path):
    rec = random_walk()
    with served(rec) as ep:
        s = capture(ep.port_url(), tmp_path / "a.mcap", axes=["Z", "X"], progress=False)
    log = load_recording(tmp_path / "a.mcap")
    assert log.axis_names == ["Z", "X"] and s.axes == ["Z", "X"]
    for a in "ZX":
        np.testing.assert_array_equal(log.axes[a].actual, scaled(rec.axes[a].actual))
    assert log.metadata["stream_axes"] == ["X", "Y", "Z"]


def test_an_unknown_axis_is_a_one_line_error_naming_the_available_ones(tmp_path):
    with served(random_walk()) as ep:
        with pytest.raises(InputError, match=r"no axis 'Q' \(available: X, Y, Z\)"):
            capture(ep.port_url(), tmp_path / "a.mcap", axes=["X", "Q"], progress=False)
    assert not (tmp_path / "a.mcap").exists()


def test_a_mistyped_axis_keeps_the_earlier_log_and_the_next_capture_replaces_it(tmp_path):
    out = tmp_path / "a.mcap"
    with served(random_walk()) as ep:
        capture(ep.port_url(), out, axes=["X"], progress=False)
    earlier = out.read_bytes()
    with served(random_walk()) as ep:
        with pytest.raises(InputError, match=r"no axis 'Q'"):
            capture(ep.port_url(), out, axes=["Q"], progress=False)
    assert out.read_bytes() == earlier  # nothing was recorded, nothing is lost
    with served(random_walk()) as ep:
        capture(ep.port_url(), out, axes=["Y"], progress=False)
    assert load_recording(out).axis_names == ["Y"]


def test_duration_records_exactly_that_much_controller_time(tmp_path):
    with served(random_walk(3000)) as ep:
        s = capture(ep.port_url(), tmp_path / "a.mcap", duration=0.25, progress=False)
    log = load_recording(tmp_path / "a.mcap")
    assert s.end == "duration" and log.n_samples == 250 == s.received
    assert log.metadata["summary"]["end"] == "duration"


def test_a_late_capture_learns_the_stream_from_the_repeated_info_frame(tmp_path):
    rec = random_walk(4000)
    with served(rec, speed=2.0, wait=False, info_every=0.3) as ep:
        time.sleep(0.6)  # the controller has been streaming; open() discards what was queued
        s = capture(ep.port_url(), tmp_path / "a.mcap", duration=0.5, progress=False)
    log = load_recording(tmp_path / "a.mcap")
    first = int(log.metadata["counter"][0])
    assert first > 500 and s.dropped == 0 and s.corrupt == 0
    np.testing.assert_array_equal(log.axes["Y"].commanded, scaled(rec.axes["Y"].commanded[first:first + 500]))


def test_the_32_bit_wire_counter_is_unwrapped(tmp_path):
    rec = random_walk(400, axes="X", t0_counter=2**32 - 150)
    with served(rec) as ep:
        capture(ep.port_url(), tmp_path / "a.mcap", progress=False)
    counters = load_recording(tmp_path / "a.mcap").metadata["counter"]
    np.testing.assert_array_equal(counters, 2**32 - 150 + np.arange(400))


def test_a_silent_port_times_out_with_a_hint(tmp_path):
    rec = random_walk(100)
    ep = SerialEndpoint(RealTimeSource(rec), stream_info_for(rec), {})
    ep.start()  # the pty exists but nothing is served
    try:
        with pytest.raises(TransportTimeout, match="no info frame .* within 0.3 s; nothing arrived"):
            capture(ep.port_url() + "&open_timeout=0.3", tmp_path / "a.mcap", progress=False)
    finally:
        ep.close()


def test_a_missing_device_and_a_bad_output_name_are_one_line_errors(tmp_path):
    with pytest.raises(TransportError, match="cannot open serial port /nonexistent/tty"):
        capture("serial:///nonexistent/tty", tmp_path / "a.mcap", progress=False)
    with pytest.raises(InputError, match="use a .mcap file name"):
        capture("serial:///dev/null", tmp_path / "a.csv", progress=False)
    with pytest.raises(InputError, match="unknown option 'bogus'"):
        capture("serial:///dev/null?bogus=1", tmp_path / "a.mcap", progress=False)


# -- counting rules, with an in-memory driver ------------------------------------------------

class ListDriver(Driver):
    """Plays back a fixed list of samples (URL ``listtest://``); counts given corrupt frames."""

    schemes = ("listtest",)
    options = {}
    script: list = []  # items: Sample, ("corrupt", n), ("end",)

    def _open(self) -> StreamInfo:
        self._items = list(self.script)
        return StreamInfo(axes=("X", "Y"), sample_period=0.001)

    def _read(self, timeout: float) -> list[Sample]:
        out = []
        while self._items:
            item = self._items.pop(0)
            if isinstance(item, Sample):
                out.append(item)
            elif item[0] == "corrupt":
                self.stats.corrupt += item[1]
            elif item[0] == "end":
                self.ended = True
                break
        return out

    def _close(self) -> None:
        pass


@pytest.fixture
def list_driver(monkeypatch):
    monkeypatch.setitem(registry.DRIVERS, "listtest", (__name__, "ListDriver"))
    return ListDriver


def _s(c: int, seg: int = 0) -> Sample:
    return Sample(c, c * 0.001, (c * 1.0, -c * 1.0), (c * 0.5, 0.0), seg)


def test_counter_gaps_are_counted_once_as_dropped_and_corrupt_frames_come_from_the_driver(tmp_path, list_driver):
    list_driver.script = [_s(10), _s(11), ("corrupt", 1), _s(13), _s(14), _s(14), _s(12), _s(20, 1),
                          ("corrupt", 2), _s(21, 1), ("end",), _s(22, 1)]
    s = capture("listtest://x", tmp_path / "a.mcap", progress=False)
    assert (s.received, s.dropped, s.corrupt, s.duplicates, s.end) == (6, 1 + 5, 3, 2, "program ended")
    log = load_recording(tmp_path / "a.mcap")
    np.testing.assert_array_equal(log.metadata["counter"], [10, 11, 13, 14, 20, 21])
    ev = log.metadata["events"]
    assert [(e["counter"], e["count"]) for e in ev if e["kind"] == "dropped"] == [(12, 1), (15, 5)]
    assert [e["count"] for e in ev if e["kind"] == "segment"] == [0, 1]
    assert sum(e["count"] for e in ev if e["kind"] == "corrupt") == 3
    assert log.metadata["summary"]["dropped"] == 6 and log.metadata["dropped"] == 6


def test_a_stream_whose_frames_are_nearly_all_rejected_ends_as_unusable_data(tmp_path):
    """Every frame but the first and the last fails its CRC: the log must not pass as a
    recording of 2 samples; it ends "unusable data" and says how many were rejected."""
    rec = random_walk(400, axes="X")
    with served(rec, faults=FaultPlan(corrupt_rate=1.0, seed=1)) as ep:
        s = capture(ep.port_url(), tmp_path / "a.mcap", progress=False)
    assert (s.received, s.corrupt, s.end) == (2, 398, "unusable data")
    assert s.error == ("400 sample records arrived but only 2 could be recorded (stopped by: program ended): "
                       "398 rejected by the integrity check (checksum, length or format)")
    log = load_mcap(tmp_path / "a.mcap")
    assert log.metadata["summary"]["end"] == "unusable data"
    assert log.metadata["events"][-1] == {"kind": "end", "counter": 399, "count": 2,
                                          "message": f"unusable data: {s.error}"}


# -- stopping with signals, in a real capture process --------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_or_sigterm_stops_cleanly_even_when_repeated(tmp_path, sig):
    with served(random_walk(20000), speed=1.0) as ep:
        proc = subprocess.Popen(AGENT + ["capture", "--port", ep.port_url(), "-o", "a.mcap"], cwd=tmp_path,
                                stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 20
        while not ((tmp_path / "a.mcap").exists() and (tmp_path / "a.mcap").stat().st_size > 5000):
            assert time.monotonic() < deadline
            time.sleep(0.05)
        proc.send_signal(sig)
        time.sleep(0.005)
        proc.send_signal(sig)  # impatient second Ctrl-C: must not cut the file short
        _, err = proc.communicate(timeout=15)
    assert proc.returncode == 0, err
    assert "Traceback" not in err
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        log = load_recording(tmp_path / "a.mcap")
    assert log.metadata["summary"]["end"] == ("interrupted" if sig == signal.SIGINT else "terminated")
    assert log.n_samples == log.metadata["summary"]["received"] > 100

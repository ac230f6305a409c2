"""Serial capture against a controller written from docs/serial-protocol.md, with its faults.

The peer (tests/_serial_tick_sender.py) builds its frames from the document, not with the
project's codec, and sends tick k with commanded = k, actual = -k counts.  Every capture
here either records each sample on its true tick with drops counted exactly and exits 0,
or stops with one ``error:`` line and a non-zero exit: never exit 0 with wrong times
(issue 40, items 4, 6, 7, 10, 11 and 13 on serial).
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

from core.reader import load_recording
from _serial_tick_sender import COUNTS_PER_MM, TickSender, ascii_line
from _tick_checks import (assert_every_sample_on_its_tick, assert_one_error_line, clock_ratio, load, run_capture,
                          summary)


@pytest.mark.parametrize("fmt", ["binary", "ascii"])
def test_a_stream_with_missing_ticks_is_stamped_on_its_ticks_with_every_drop_counted(tmp_path, fmt):
    skip = frozenset({3, 4, 5, 400, 999})
    with TickSender(ticks=1200, fmt=fmt, skip=skip) as peer:
        res = run_capture(peer.url, tmp_path)
    assert res.returncode == 0, res.stderr
    log = load(tmp_path)
    k = assert_every_sample_on_its_tick(log, 0.001, COUNTS_PER_MM)
    np.testing.assert_array_equal(k, [j for j in range(1200) if j not in skip])
    assert log.metadata["summary"]["dropped"] == len(skip)


@pytest.mark.parametrize("restart_at", [50, 1000], ids=["early", "late"])
def test_a_controller_that_restarts_stops_the_capture_with_one_line_and_keeps_the_run_before(tmp_path,
                                                                                            restart_at):
    with TickSender(ticks=1500, restart_at=restart_at) as peer:
        res = run_capture(peer.url, tmp_path)
    assert_one_error_line(res, "the controller restarted", f"went back from {restart_at - 1} to 0")
    log = load(tmp_path)
    assert log.metadata["summary"]["end"] == "controller restarted"
    k = assert_every_sample_on_its_tick(log, 0.001, COUNTS_PER_MM)
    np.testing.assert_array_equal(k, np.arange(restart_at))  # nothing of the new run, nothing mislabelled
    assert log.metadata["summary"]["duplicates"] == 0


@pytest.mark.parametrize("true_period, announced", [(0.002, 0.001), (0.0005, 0.001)],
                         ids=["slower-than-announced", "faster-than-announced"])
def test_a_sample_period_announced_wrong_is_caught_by_the_host_clock(tmp_path, true_period, announced):
    with TickSender(ticks=int(3.0 / true_period), period_s=true_period, announced_period_s=announced) as peer:
        res = run_capture(peer.url, tmp_path)
    line = assert_one_error_line(res, "period_ns the controller announces")
    assert clock_ratio(line) == pytest.approx(announced / true_period, rel=0.1)
    log = load(tmp_path)
    assert log.metadata["summary"]["end"] == "clock mismatch"


@pytest.mark.parametrize("fmt", ["binary", "ascii"])
def test_valid_samples_without_an_info_message_are_named_as_such_not_as_a_framing_error(tmp_path, fmt):
    with TickSender(ticks=5000, fmt=fmt, info=False) as peer:
        res = run_capture(peer.url + "&open_timeout=1", tmp_path)
    line = assert_one_error_line(res, "no info frame", f"valid {fmt} sample frames arrived but no info frame")
    assert "wrong format" not in line
    assert not (tmp_path / "log.mcap").exists()


def test_an_info_message_with_no_axis_is_named_as_rejected(tmp_path):
    class NoAxes(TickSender):
        def info_msg(self, next_counter: int) -> bytes:
            return ascii_line(f"I,{next_counter},1000000,{COUNTS_PER_MM},,mm,fault peer,")

    with NoAxes(ticks=5000, fmt="ascii") as peer:
        res = run_capture(peer.url + "&open_timeout=1", tmp_path)
    assert_one_error_line(res, "info frame(s) arrived intact but were rejected", "at least one axis name")


def test_a_stream_that_never_sends_a_sample_fails_even_when_the_duration_ends_it(tmp_path):
    with TickSender(ticks=3000, samples=False) as peer:
        res = run_capture(peer.url, tmp_path, "--duration", "1")
    assert_one_error_line(res, "no sample recorded (stopped by: duration (host clock))")
    assert summary(tmp_path)["end"] == "transport error" and summary(tmp_path)["received"] == 0


def test_a_capture_that_fails_before_the_stream_starts_keeps_the_earlier_log_at_o(tmp_path):
    old = tmp_path / "log.mcap"
    old.write_bytes(b"an older capture")
    with TickSender(ticks=3000, info=False, samples=False) as peer:
        bad = run_capture(peer.url + "&bogus=1", tmp_path)  # bad input: nothing has started
        assert_one_error_line(bad, "unknown option 'bogus'")
        assert old.read_bytes() == b"an older capture"
        res = run_capture(peer.url + "&open_timeout=0.5", tmp_path)
    assert_one_error_line(res, "no info frame")
    assert old.read_bytes() == b"an older capture"  # nothing was recorded, nothing is lost


def test_a_served_program_is_captured_with_as_many_samples_and_the_same_duration_as_simulated(tmp_path):
    """Item 13: the capture of an ``agent serve`` d program and ``agent simulate`` agree to the sample."""
    from drivers.capture import capture
    from drivers.endpoints.serial_endpoint import SerialEndpoint
    from drivers.endpoints.source import RealTimeSource, stream_info_for
    from virtual_cnc.machine_run import simulate

    prog = tmp_path / "p.nc"
    prog.write_text("G21 G90 G94\nF3000\nG1 X5 Y3\nG1 X0 Y-2\nG1 X2 Y0\nM2\n")
    rec = simulate([prog])
    ep = SerialEndpoint(RealTimeSource(rec, speed=1.0), stream_info_for(rec), {})
    ep.start()
    th = threading.Thread(target=ep.run, daemon=True)
    th.start()
    try:
        s = capture(ep.port_url(), tmp_path / "c.mcap", progress=False)
    finally:
        ep.stop_event.set()
        th.join(5)
        ep.close()
    log = load_recording(tmp_path / "c.mcap")
    assert (s.received, s.end) == (rec.n_samples, "program ended")
    assert log.n_samples == rec.n_samples
    assert s.duration_s == pytest.approx(rec.duration, abs=1e-12)
    assert log.duration == pytest.approx(rec.duration, abs=1e-12)

"""Modbus TCP capture against a controller written from docs/modbus.md, with its faults.

The peer (tests/_modbus_tick_server.py) is a raw-socket Modbus TCP server with its own
registers, trace ring and live registers; tick k carries commanded = k, actual = -k nm.
Every capture here either records each sample on its true tick with drops counted
exactly and exits 0, or stops with one ``error:`` line and a non-zero exit: never exit 0
with wrong times (issue 40, items 4-9 and 11 on Modbus).
"""

from __future__ import annotations

import signal
import socket
import subprocess
import time

import numpy as np
import pytest

from _modbus_tick_server import SCALE_MM, TickServer
from _tick_checks import (AGENT, assert_every_sample_on_its_tick, assert_one_error_line, clock_ratio, load,
                          run_capture, summary)

COUNTS_PER_MM = 1 / SCALE_MM

MAP = """\
[device]
unit = 1
table = "holding"
word_order = "big"
max_registers = 125
sample_period_s = 0.001

[info]
address = 0
length = 256

[status]
address = 256

[counter]
address = 257
segment = 259

[trace]
head = 260
capacity = 262
base = 1024

[[axis]]
name = "X"
commanded = 264
actual = 266
scale_mm = 1e-6
"""

MAP_WITHOUT_TRACE = MAP.split("[trace]")[0] + MAP.split("base = 1024\n")[1]


@pytest.fixture
def ctrl_map(tmp_path):
    (tmp_path / "ctrl.toml").write_text(MAP)
    return "ctrl.toml"


def free_port() -> int:
    """A loopback port nobody listens on."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("mode", ["trace", "live"])
def test_trace_and_live_captures_stamp_every_sample_on_its_tick(tmp_path, mode):
    with TickServer(ticks=1500) as peer:
        res = run_capture(f"{peer.url}?mode={mode}", tmp_path)
    assert res.returncode == 0, res.stderr
    log = load(tmp_path)
    k = assert_every_sample_on_its_tick(log, 0.001, COUNTS_PER_MM)
    assert k[-1] == 1499
    if mode == "trace":  # the ring holds every tick
        np.testing.assert_array_equal(k, np.arange(1500))


def test_a_controller_that_restarts_in_live_mode_stops_with_one_line_and_keeps_the_run_before(tmp_path):
    with TickServer(ticks=2500, restart_at=1200) as peer:
        res = run_capture(f"{peer.url}?mode=live", tmp_path)
    assert_one_error_line(res, "the controller restarted: its sample counter went back from")
    log = load(tmp_path)
    assert log.metadata["summary"]["end"] == "controller restarted"
    k = assert_every_sample_on_its_tick(log, 0.001, COUNTS_PER_MM)
    assert k[-1] < 1200  # nothing of the new run, nothing mislabelled


def test_a_controller_that_restarts_its_trace_stops_with_one_line(tmp_path):
    with TickServer(ticks=2500, restart_at=1200) as peer:
        res = run_capture(f"{peer.url}?mode=trace", tmp_path)
    assert_one_error_line(res, "the trace head went back", "restarted its trace")
    assert_every_sample_on_its_tick(load(tmp_path), 0.001, COUNTS_PER_MM)


def test_live_counters_in_the_other_word_order_stop_the_capture_naming_the_word_order(tmp_path):
    with TickServer(ticks=3000, word_order="little") as peer:
        res = run_capture(f"{peer.url}?mode=live", tmp_path)
    assert_one_error_line(res, "the live sample counter steps by", 'set word_order = "little"')
    assert summary(tmp_path)["end"] == "unusable data"


@pytest.mark.parametrize("mode", ["trace", "live"])
def test_a_map_period_that_is_not_the_controllers_is_caught_by_the_host_clock(tmp_path, ctrl_map, mode):
    """The server samples at 500 Hz; the map (and no info-block period) says 1 ms."""
    with TickServer(ticks=2000, period_s=0.002, info_period=False) as peer:
        res = run_capture(f"{peer.url}?mode={mode}&map={ctrl_map}", tmp_path)
    line = assert_one_error_line(res, "device.sample_period_s of register map ctrl.toml")
    assert clock_ratio(line) == pytest.approx(0.5, rel=0.1)
    assert summary(tmp_path)["end"] == "clock mismatch"


def test_a_status_that_never_says_running_fails_when_the_duration_ends_it(tmp_path):
    with TickServer(ticks=5000, running=False) as peer:
        res = run_capture(f"{peer.url}?mode=live", tmp_path, "--duration", "1")
    assert_one_error_line(res, "no sample recorded (stopped by: duration (host clock))",
                          "the status register (address 256 of register map default) never said running")
    assert summary(tmp_path)["end"] == "unusable data"


def test_a_status_that_never_says_running_fails_when_ctrl_c_ends_it(tmp_path):
    with TickServer(ticks=5000, running=False) as peer:
        proc = subprocess.Popen(AGENT + ["capture", "--port", f"{peer.url}?mode=live", "-o", "log.mcap", "-q"],
                                cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(2.0)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=20)
    res = subprocess.CompletedProcess(proc.args, proc.returncode, out, err)
    assert_one_error_line(res, "no sample recorded (stopped by: interrupted)", "never said running")


@pytest.mark.parametrize("map_text, expected", [
    (None, "ctrl.toml"),
    (MAP.replace("scale_mm = 1e-6", "scale_mm = 1e-6\nbogus = 1"), "bogus"),
])
def test_a_bad_map_is_reported_before_any_connection_is_tried(tmp_path, map_text, expected):
    if map_text is not None:
        (tmp_path / "ctrl.toml").write_text(map_text)
    res = run_capture(f"modbus-tcp://127.0.0.1:{free_port()}?map=ctrl.toml", tmp_path)
    line = assert_one_error_line(res, expected)
    assert "cannot connect" not in line


@pytest.mark.parametrize("extra, expected", [
    ("&mode=trace", "mode=trace but register map ctrl.toml has no [trace] block"),
    ("", "--axes: the controller has no axis 'Q' (axes: X)"),
])
def test_options_that_contradict_the_map_are_reported_before_any_connection_is_tried(tmp_path, extra, expected):
    (tmp_path / "ctrl.toml").write_text(MAP_WITHOUT_TRACE if extra else MAP)
    res = run_capture(f"modbus-tcp://127.0.0.1:{free_port()}?map=ctrl.toml{extra}", tmp_path,
                      *([] if extra else ["--axes", "Q"]))
    assert_one_error_line(res, expected)
    assert res.returncode == 2


def test_a_program_name_with_a_space_is_kept_whole(tmp_path):
    sha = "ab" * 32
    with TickServer(ticks=300, programs=(f"low speed.nc {sha}",)) as peer:
        res = run_capture(peer.url, tmp_path)
    assert res.returncode == 0, res.stderr
    assert load(tmp_path).metadata["programs"] == [{"name": "low speed.nc", "sha256": sha}]


def test_a_capture_that_cannot_connect_keeps_the_earlier_log_at_o(tmp_path):
    old = tmp_path / "log.mcap"
    old.write_bytes(b"an older capture")
    res = run_capture(f"modbus-tcp://127.0.0.1:{free_port()}", tmp_path)
    assert_one_error_line(res, "cannot connect")
    assert old.read_bytes() == b"an older capture"  # nothing was recorded, nothing is lost

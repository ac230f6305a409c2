"""End to end over python-can's udp_multicast (loopback, hop limit 0): `agent serve --transport can`
(simulated CiA 402 drives, or DBC frames) and `agent capture` in separate processes record exactly
what the virtual CNC computed, count every injected fault, and handle a silent bus."""

from __future__ import annotations

import os
import signal
import time
import warnings

import numpy as np
import pytest

from test_can_driver import UDP_MULTICAST_NEEDS, udp_multicast_available
from _capture_procs import Server, capture, expected_counts, read_fault_log, start_capture, write_program
from drivers.recorder import write_recording_mcap
from drivers.sim.virtual_cnc import run_programs
from ident.loading import load_recording

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not udp_multicast_available(), reason=UDP_MULTICAST_NEEDS)]

MOVES = ["X5 Y3", "X0 Y-2", "X2 Y0"]  # about 1.8 s on the default machine


@pytest.fixture(scope="module")
def program(tmp_path_factory):
    return write_program(tmp_path_factory.mktemp("prog") / "moves.nc", MOVES)


@pytest.fixture(scope="module")
def simulated(program):
    return run_programs([program])


def _assert_values_exact(log, sim, counters):
    for axis in sim.axis_names:
        np.testing.assert_array_equal(log.axes[axis].commanded, expected_counts(sim.axes[axis].commanded[counters]))
        np.testing.assert_array_equal(log.axes[axis].actual, expected_counts(sim.axes[axis].actual[counters]))


@pytest.mark.parametrize("protocol, source", [("canopen", "program"), ("dbc", "recording")])
def test_capture_equals_the_simulation_exactly_with_zero_drops(tmp_path, program, simulated, protocol, source):
    if source == "program":
        what = ["-p", str(program)]
    else:  # replay of a simulated log (`agent simulate` writes the same layout)
        write_recording_mcap(simulated, tmp_path / "sim.mcap")
        what = ["--recording", str(tmp_path / "sim.mcap")]
    with Server(["-t", "can", *what, "--speed", "2", "--opt", f"protocol={protocol}"], tmp_path) as srv:
        assert srv.port.startswith("can://udp_multicast/239.74.163.")
        res = capture(["--port", srv.port, "-o", "log.mcap"], tmp_path)
    assert res.returncode == 0, res.stderr
    log = load_recording(tmp_path / "log.mcap")
    np.testing.assert_array_equal(log.metadata["counter"], np.arange(simulated.n_samples))
    _assert_values_exact(log, simulated, slice(None))
    np.testing.assert_array_equal(log.segment, simulated.segment)
    np.testing.assert_allclose(log.t, simulated.t, rtol=0, atol=1e-12)
    s = log.metadata["summary"]
    assert (s["received"], s["dropped"], s["corrupt"], s["end"]) == (simulated.n_samples, 0, 0, "program ended")
    assert log.metadata["transport"] == "can"


def test_injected_drops_and_corruptions_are_counted_exactly_and_never_recorded(tmp_path, program):
    simulated = run_programs([program], seed=4)
    with Server(["-t", "can", "-p", str(program), "--speed", "2", "--seed", "4", "--drop-rate", "0.03",
                 "--corrupt-rate", "0.03", "--fault-log", "faults.json"], tmp_path) as srv:
        res = capture(["--port", srv.port, "-o", "log.mcap"], tmp_path)
        srv.wait()
    assert res.returncode == 0, res.stderr
    faults = read_fault_log(tmp_path / "faults.json")
    assert faults["dropped"] > 10 and faults["corrupted"] > 10
    log = load_recording(tmp_path / "log.mcap")
    s = log.metadata["summary"]
    assert s["corrupt"] == faults["corrupted"]  # TPDOs of 6 bytes where the mapping says 8
    assert s["dropped"] == faults["dropped"] + faults["corrupted"]
    missing = set(faults["dropped_counters"]) | set(faults["corrupted_counters"])
    kept = np.array([c for c in range(simulated.n_samples) if c not in missing])
    np.testing.assert_array_equal(log.metadata["counter"], kept)
    _assert_values_exact(log, simulated, kept)


def test_a_silent_bus_longer_than_a_sync_counter_wrap_is_bridged_and_counted(tmp_path, program, simulated):
    # 0.5 s of silence at 1 kHz = 500 ticks: more than the 240 values of the SYNC counter
    with Server(["-t", "can", "-p", str(program), "--disconnect-at", "0.6", "--opt", "outage=0.5",
                 "--fault-log", "faults.json"], tmp_path) as srv:
        res = capture(["--port", srv.port, "-o", "log.mcap"], tmp_path)
        srv.wait()
    assert res.returncode == 0, res.stderr
    faults = read_fault_log(tmp_path / "faults.json")
    unsent = faults["unsent_counters"]
    assert unsent[0] == 600 and len(unsent) > 240
    log = load_recording(tmp_path / "log.mcap")
    s = log.metadata["summary"]
    assert s["reconnects"] == 1 and s["end"] == "program ended"
    assert s["dropped"] == len(unsent)
    kept = np.array([c for c in range(simulated.n_samples) if c not in set(unsent)])
    np.testing.assert_array_equal(log.metadata["counter"], kept)
    _assert_values_exact(log, simulated, kept)


def test_a_bus_that_stays_silent_ends_the_capture_with_one_line_and_a_complete_log(tmp_path, program):
    with Server(["-t", "can", "-p", str(program), "--disconnect-at", "0.5", "--opt", "outage=5"], tmp_path) as srv:
        res = capture(["--port", srv.port + "&timeout=0.5", "-o", "log.mcap"], tmp_path)
    assert res.returncode == 1
    err = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    assert len(err) == 1 and "no CAN frame for 0." in err[0], res.stderr
    assert "Traceback" not in res.stderr
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a complete log: no "cut off" warning
        log = load_recording(tmp_path / "log.mcap")
    assert log.metadata["summary"]["end"] == "transport error"
    np.testing.assert_array_equal(log.metadata["counter"], np.arange(500))


def test_a_sigkilled_capture_leaves_a_log_missing_at_most_one_second(tmp_path):
    prog = write_program(tmp_path / "long.nc", ["X20", "X0", "X10"], feed_mm_min=900)  # ~3.4 s
    sim = run_programs([prog])
    with Server(["-t", "can", "-p", str(prog), "--fault-log", "faults.json", "--linger", "0"], tmp_path) as srv:
        cap = start_capture(["--port", srv.port, "-o", "log.mcap"], tmp_path)
        out = tmp_path / "log.mcap"
        deadline = time.monotonic() + 20
        while (not out.exists() or out.stat().st_size < 20_000) and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(1.2)
        os.kill(cap.pid, signal.SIGKILL)
        t_kill = time.time()
        cap.wait(10)
        srv.wait()
    timeline = read_fault_log(tmp_path / "faults.json")["sent_timeline"]
    sent_by_kill = max(c for t, c in timeline if t <= t_kill)
    with pytest.warns(Warning, match="cut off|did not close cleanly"):
        log = load_recording(out)
    counters = log.metadata["counter"]
    np.testing.assert_array_equal(counters, np.arange(counters[0], counters[-1] + 1))
    assert counters[0] == 0
    lost_s = (sent_by_kill - counters[-1]) * sim.sample_period
    assert lost_s <= 1.0, f"lost {lost_s:.3f} s"
    _assert_values_exact(log, sim, counters)

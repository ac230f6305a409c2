"""End to end over a real pseudo-terminal: `agent serve --transport serial` and `agent capture` in
separate processes record exactly what the virtual CNC computed, count every injected fault,
survive a disconnect, and lose at most a second when the capture is killed."""

from __future__ import annotations

import os
import signal
import time
import warnings

import numpy as np
import pytest

from _capture_procs import Server, capture, expected_counts, read_fault_log, start_capture, write_program
from drivers.recorder import write_recording_mcap
from drivers.sim.virtual_cnc import run_programs
from ident.loading import load_recording

pytestmark = pytest.mark.slow

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


@pytest.mark.parametrize("fmt, source", [("binary", "program"), ("ascii", "recording")])
def test_capture_equals_the_simulation_exactly_with_zero_drops(tmp_path, program, simulated, fmt, source):
    if source == "program":
        what = ["-p", str(program)]
    else:  # replay of a simulated log (`agent simulate` writes the same layout)
        write_recording_mcap(simulated, tmp_path / "sim.mcap")
        what = ["--recording", str(tmp_path / "sim.mcap")]
    with Server(["-t", "serial", *what, "--speed", "2", "--opt", f"format={fmt}"], tmp_path) as srv:
        assert f"format={fmt}" in srv.port
        res = capture(["--port", srv.port, "-o", "log.mcap"], tmp_path)
    assert res.returncode == 0, res.stderr
    log = load_recording(tmp_path / "log.mcap")
    np.testing.assert_array_equal(log.metadata["counter"], np.arange(simulated.n_samples))
    _assert_values_exact(log, simulated, slice(None))
    np.testing.assert_array_equal(log.segment, simulated.segment)
    np.testing.assert_allclose(log.t, simulated.t, rtol=0, atol=1e-12)
    s = log.metadata["summary"]
    assert (s["received"], s["dropped"], s["corrupt"], s["end"]) == (simulated.n_samples, 0, 0, "program ended")
    assert log.metadata["transport"] == "serial"
    assert log.metadata["programs"] == simulated.metadata["programs"]
    assert log.metadata["controller"] == simulated.metadata["controller"]


@pytest.mark.parametrize("fmt", ["binary", "ascii"])
def test_injected_drops_and_corruptions_are_counted_exactly_and_never_recorded(tmp_path, program, fmt):
    simulated = run_programs([program], seed=4)  # --seed seeds the encoder noise and the fault plan
    with Server(["-t", "serial", "-p", str(program), "--speed", "2", "--opt", f"format={fmt}", "--seed", "4",
                 "--drop-rate", "0.03", "--corrupt-rate", "0.03", "--fault-log", "faults.json"], tmp_path) as srv:
        res = capture(["--port", srv.port, "-o", "log.mcap"], tmp_path)
        srv.wait()
    assert res.returncode == 0, res.stderr
    faults = read_fault_log(tmp_path / "faults.json")
    assert faults["dropped"] > 10 and faults["corrupted"] > 10
    log = load_recording(tmp_path / "log.mcap")
    s = log.metadata["summary"]
    assert s["corrupt"] == faults["corrupted"]
    assert s["dropped"] == faults["dropped"] + faults["corrupted"]
    missing = set(faults["dropped_counters"]) | set(faults["corrupted_counters"])
    kept = np.array([c for c in range(simulated.n_samples) if c not in missing])
    np.testing.assert_array_equal(log.metadata["counter"], kept)
    _assert_values_exact(log, simulated, kept)
    gaps = sum(e["count"] for e in log.metadata["events"] if e["kind"] == "dropped")
    assert gaps == s["dropped"]


def test_a_disconnect_is_survived_by_reconnecting_and_the_gap_is_counted(tmp_path, program, simulated):
    with Server(["-t", "serial", "-p", str(program), "--disconnect-at", "0.6", "--drop-rate", "0.01",
                 "--fault-log", "faults.json"], tmp_path) as srv:
        res = capture(["--port", srv.port, "-o", "log.mcap"], tmp_path)
        srv.wait()
    assert res.returncode == 0, res.stderr
    faults = read_fault_log(tmp_path / "faults.json")
    unsent = faults["unsent_counters"]
    assert unsent and unsent[0] == 600  # the link went down at 0.6 s
    log = load_recording(tmp_path / "log.mcap")
    s = log.metadata["summary"]
    assert s["reconnects"] == 1 and s["end"] == "program ended"
    missing = set(faults["dropped_counters"]) | set(unsent)
    assert s["dropped"] == len(missing)
    kept = np.array([c for c in range(simulated.n_samples) if c not in missing])
    np.testing.assert_array_equal(log.metadata["counter"], kept)
    _assert_values_exact(log, simulated, kept)
    assert any(e["kind"] == "reconnect" for e in log.metadata["events"])


def test_a_disconnect_without_reconnection_ends_with_one_line_and_a_complete_log(tmp_path, program):
    with Server(["-t", "serial", "-p", str(program), "--disconnect-at", "0.5", "--opt", "outage=3"],
                tmp_path) as srv:
        res = capture(["--port", srv.port + "&reconnect=0.5", "-o", "log.mcap"], tmp_path)
    assert res.returncode == 1
    err = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    assert len(err) == 1 and "disconnected" in err[0] and "did not come back within 0.5 s" in err[0], res.stderr
    assert "Traceback" not in res.stderr
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a complete log: no "cut off" warning
        log = load_recording(tmp_path / "log.mcap")
    assert log.metadata["summary"]["end"] == "transport error"
    np.testing.assert_array_equal(log.metadata["counter"], np.arange(500))


def test_a_sigkilled_capture_leaves_a_log_missing_at_most_one_second(tmp_path):
    prog = write_program(tmp_path / "long.nc", ["X20", "X0", "X10"], feed_mm_min=900)  # ~3.4 s
    sim = run_programs([prog])
    with Server(["-t", "serial", "-p", str(prog), "--fault-log", "faults.json", "--linger", "0"], tmp_path) as srv:
        cap = start_capture(["--port", srv.port, "-o", "log.mcap"], tmp_path)
        out = tmp_path / "log.mcap"
        deadline = time.monotonic() + 20
        while (not out.exists() or out.stat().st_size < 20_000) and time.monotonic() < deadline:
            time.sleep(0.05)  # until well over half a second of samples is on disk
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

"""End to end over Modbus: `agent serve --transport modbus` and `agent capture` in separate processes.

TCP on 127.0.0.1 and RTU over a pseudo-terminal; the trace-buffer upload records exactly
what the virtual CNC computed (positions at the map's 1 nm scale), counts every injected
fault (a corrupted response is rejected, counted and read again, so it costs no sample),
recovers the samples of a disconnect from the controller's ring, and never sends
anything but a read request.
"""

from __future__ import annotations

import os
import signal
import time
import warnings

import numpy as np
import pytest

from _capture_procs import Server, capture, read_fault_log, start_capture, write_program
from drivers.sim.virtual_cnc import run_programs
from ident.loading import load_recording

pytestmark = pytest.mark.slow

MOVES = ["X5 Y3", "X0 Y-2", "X2 Y0"]  # about 1.8 s on the default machine
SCALE = 1e-6  # mm per count of the default register map


@pytest.fixture(scope="module")
def program(tmp_path_factory):
    return write_program(tmp_path_factory.mktemp("prog") / "moves.nc", MOVES)


@pytest.fixture(scope="module")
def simulated(program):
    return run_programs([program])


def wire(values: np.ndarray) -> np.ndarray:
    return np.rint(values / SCALE).astype(np.int64) * SCALE


def _assert_values_exact(log, sim, counters):
    for axis in sim.axis_names:
        np.testing.assert_array_equal(log.axes[axis].commanded, wire(sim.axes[axis].commanded[counters]))
        np.testing.assert_array_equal(log.axes[axis].actual, wire(sim.axes[axis].actual[counters]))


@pytest.mark.parametrize("link", ["tcp", "rtu"])
def test_trace_capture_equals_the_simulation_exactly_with_zero_drops(tmp_path, program, simulated, link):
    with Server(["-t", "modbus", "-p", str(program), "--speed", "2", "--opt", f"link={link}",
                 "--fault-log", "faults.json"], tmp_path) as srv:
        assert srv.port.startswith(f"modbus-{link}://") and "mode=trace" in srv.port
        res = capture(["--port", srv.port, "-o", "log.mcap"], tmp_path)
        srv.wait()
    assert res.returncode == 0, res.stderr
    log = load_recording(tmp_path / "log.mcap")
    np.testing.assert_array_equal(log.metadata["counter"], np.arange(simulated.n_samples))
    _assert_values_exact(log, simulated, slice(None))
    np.testing.assert_array_equal(log.segment, simulated.segment)
    s = log.metadata["summary"]
    assert (s["received"], s["dropped"], s["corrupt"], s["end"]) == (simulated.n_samples, 0, 0, "program ended")
    assert log.metadata["transport"] == f"modbus-{link}"
    assert log.metadata["programs"] == simulated.metadata["programs"]
    assert log.metadata["controller"] == simulated.metadata["controller"]
    # passive: the controller received read-holding-registers requests and nothing else
    assert set(read_fault_log(tmp_path / "faults.json")["function_codes"]) == {"3"}


@pytest.mark.parametrize("link", ["tcp", "rtu"])
def test_injected_drops_and_corruptions_are_counted_exactly_and_never_recorded(tmp_path, program, link):
    simulated = run_programs([program], seed=4)  # --seed seeds the encoder noise and the fault plan
    with Server(["-t", "modbus", "-p", str(program), "--speed", "2", "--opt", f"link={link}", "--seed", "4",
                 "--drop-rate", "0.03", "--corrupt-rate", "0.03", "--fault-log", "faults.json"], tmp_path) as srv:
        res = capture(["--port", srv.port, "-o", "log.mcap"], tmp_path)
        srv.wait()
    assert res.returncode == 0, res.stderr
    faults = read_fault_log(tmp_path / "faults.json")
    assert faults["dropped"] > 10 and faults["corrupted"] > 10
    log = load_recording(tmp_path / "log.mcap")
    s = log.metadata["summary"]
    # a damaged response (bad CRC / exception 4) is rejected, counted, and the read repeated:
    # corrupted ticks arrive intact, only the dropped ones are missing
    assert s["corrupt"] == faults["corrupted"] == faults["corrupted_responses"]
    assert s["dropped"] == faults["dropped"]
    kept = np.array([c for c in range(simulated.n_samples) if c not in set(faults["dropped_counters"])])
    np.testing.assert_array_equal(log.metadata["counter"], kept)
    _assert_values_exact(log, simulated, kept)
    assert sum(e["count"] for e in log.metadata["events"] if e["kind"] == "dropped") == faults["dropped"]
    assert sum(e["count"] for e in log.metadata["events"] if e["kind"] == "corrupt") == faults["corrupted"]
    assert set(faults["function_codes"]) == {"3"}


def test_a_tcp_disconnect_is_survived_and_the_ring_refills_the_gap(tmp_path, program, simulated):
    with Server(["-t", "modbus", "-p", str(program), "--speed", "2", "--disconnect-at", "0.8",
                 "--fault-log", "faults.json"], tmp_path) as srv:
        res = capture(["--port", srv.port, "-o", "log.mcap"], tmp_path)
        srv.wait()
    assert res.returncode == 0, res.stderr
    assert read_fault_log(tmp_path / "faults.json")["disconnects"] == 1
    log = load_recording(tmp_path / "log.mcap")
    s = log.metadata["summary"]
    assert (s["reconnects"], s["dropped"], s["end"]) == (1, 0, "program ended")
    np.testing.assert_array_equal(log.metadata["counter"], np.arange(simulated.n_samples))
    _assert_values_exact(log, simulated, slice(None))
    assert [e["kind"] for e in log.metadata["events"]].count("reconnect") == 1


def test_live_polling_records_exact_values_and_counts_the_ticks_it_did_not_see(tmp_path, program, simulated):
    with Server(["-t", "modbus", "-p", str(program), "--opt", "mode=live"], tmp_path) as srv:
        assert "mode=live" in srv.port
        res = capture(["--port", srv.port, "-o", "log.mcap"], tmp_path)
    assert res.returncode == 0, res.stderr
    log = load_recording(tmp_path / "log.mcap")
    k = log.metadata["counter"]
    assert len(k) > simulated.n_samples // 10  # polling sees most ticks (its rate is a benchmark figure)
    _assert_values_exact(log, simulated, k)
    s = log.metadata["summary"]
    assert s["dropped"] == (k[-1] - k[0] + 1) - len(k)


def test_a_controller_gone_for_good_ends_with_one_line_and_a_complete_log(tmp_path, program, simulated):
    with Server(["-t", "modbus", "-p", str(program)], tmp_path) as srv:
        cap = start_capture(["--port", srv.port + "&reconnect_s=0.5", "-o", "log.mcap"], tmp_path)
        out = tmp_path / "log.mcap"
        deadline = time.monotonic() + 20
        while (not out.exists() or out.stat().st_size < 5_000) and time.monotonic() < deadline:
            time.sleep(0.05)
        srv.proc.kill()  # the controller is switched off: no listener to reconnect to
        _, err = cap.communicate(timeout=20)
    assert cap.returncode == 1
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and "connection lost" in lines[0] and "within 0.5 s" in lines[0], err
    assert "Traceback" not in err
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a complete log, closed normally
        log = load_recording(out)
    assert log.metadata["summary"]["end"] == "transport error"
    k = log.metadata["counter"]
    assert 0 < len(k) < simulated.n_samples
    np.testing.assert_array_equal(k, np.arange(len(k)))
    _assert_values_exact(log, simulated, k)


def test_a_sigkilled_capture_leaves_a_log_missing_at_most_one_second(tmp_path):
    prog = write_program(tmp_path / "long.nc", ["X20", "X0", "X10"], feed_mm_min=900)  # ~3.4 s
    sim = run_programs([prog])
    with Server(["-t", "modbus", "-p", str(prog), "--fault-log", "faults.json", "--linger", "0"], tmp_path) as srv:
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
    k = log.metadata["counter"]
    assert k[0] == 0
    np.testing.assert_array_equal(k, np.arange(k[-1] + 1))
    lost_s = (sent_by_kill - k[-1]) * sim.sample_period
    assert lost_s <= 1.0, f"lost {lost_s:.3f} s"
    _assert_values_exact(log, sim, k)

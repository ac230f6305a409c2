"""End to end over a real pseudo-terminal: `agent serve --transport serial` and `agent capture` in
separate processes record exactly what the virtual CNC computed, count every injected fault,
survive a disconnect, and lose at most a second when the capture is killed.

The process handling and the checks every transport shares are in tests/_capture_procs.py."""

from __future__ import annotations

import numpy as np
import pytest

from _capture_procs import (FAULT_SEED, INJECTED_FAULTS, assert_complete_and_exact, assert_failed_with_one_line,
                            assert_recorded_all_but, assert_rejected_frames_are_dropped,
                            assert_sigkill_loses_at_most_one_second, reconnected_log, serve_and_capture, served_source)
from _capture_procs import program, simulated  # noqa: F401  (module-scoped fixtures, requested by name)
from virtual_cnc.machine_run import simulate as run_programs

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("fmt, source", [("binary", "program"), ("ascii", "recording")])
def test_capture_equals_the_simulation_exactly_with_zero_drops(tmp_path, program, simulated, fmt, source):
    what = served_source(source, program, simulated, tmp_path)
    port, res = serve_and_capture(["-t", "serial", *what, "--speed", "2", "--opt", f"format={fmt}"], tmp_path)
    assert f"format={fmt}" in port
    log = assert_complete_and_exact(res, tmp_path, simulated)
    np.testing.assert_allclose(log.t, simulated.t, rtol=0, atol=1e-12)
    assert log.metadata["transport"] == "serial"
    assert log.metadata["programs"] == simulated.metadata["programs"]
    assert log.metadata["controller"] == simulated.metadata["controller"]


@pytest.mark.parametrize("fmt", ["binary", "ascii"])
def test_injected_drops_and_corruptions_are_counted_exactly_and_never_recorded(tmp_path, program, fmt):
    simulated = run_programs([program], seed=FAULT_SEED)
    _, res = serve_and_capture(["-t", "serial", str(program), "--speed", "2", "--opt", f"format={fmt}",
                                *INJECTED_FAULTS], tmp_path, wait=True)
    log = assert_rejected_frames_are_dropped(res, tmp_path, simulated)
    gaps = sum(e["count"] for e in log.metadata["events"] if e["kind"] == "dropped")
    assert gaps == log.metadata["summary"]["dropped"]


def test_a_disconnect_is_survived_by_reconnecting_and_the_gap_is_counted(tmp_path, program, simulated):
    _, res = serve_and_capture(["-t", "serial", str(program), "--disconnect-at", "0.6", "--drop-rate", "0.01",
                                "--fault-log", "faults.json"], tmp_path, wait=True)
    log, faults = reconnected_log(res, tmp_path)
    unsent = faults["unsent_counters"]
    assert unsent and unsent[0] == 600  # the link went down at 0.6 s
    missing = set(faults["dropped_counters"]) | set(unsent)
    assert log.metadata["summary"]["dropped"] == len(missing)
    assert_recorded_all_but(log, simulated, missing)
    assert any(e["kind"] == "reconnect" for e in log.metadata["events"])


def test_a_disconnect_without_reconnection_ends_with_one_line_and_a_complete_log(tmp_path, program):
    _, res = serve_and_capture(["-t", "serial", str(program), "--disconnect-at", "0.5", "--opt", "outage=3"],
                               tmp_path, port_query="&reconnect=0.5")
    err, log = assert_failed_with_one_line(res.returncode, res.stderr, tmp_path)
    assert "disconnected" in err and "did not come back within 0.5 s" in err, res.stderr
    np.testing.assert_array_equal(log.metadata["counter"], np.arange(500))


def test_a_sigkilled_capture_leaves_a_log_missing_at_most_one_second(tmp_path):
    assert_sigkill_loses_at_most_one_second("serial", tmp_path)

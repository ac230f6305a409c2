"""End to end over python-can's udp_multicast (loopback, hop limit 0): `agent serve --transport can`
(simulated CiA 402 drives, or DBC frames) and `agent capture` in separate processes record exactly
what the virtual CNC computed, count every injected fault, and handle a silent bus.

The process handling and the checks every transport shares are in tests/_capture_procs.py."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from test_can_driver import UDP_MULTICAST_NEEDS, udp_multicast_available
from _capture_procs import (FAULT_SEED, INJECTED_FAULTS, LOG, Server, assert_complete_and_exact, capture, assert_failed_with_one_line,
                            assert_recorded_all_but, assert_rejected_frames_are_dropped,
                            assert_sigkill_loses_at_most_one_second, reconnected_log, serve_and_capture, served_source)
from _capture_procs import program, simulated  # noqa: F401  (module-scoped fixtures, requested by name)
from virtual_cnc.machine_run import simulate as run_programs

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not udp_multicast_available(), reason=UDP_MULTICAST_NEEDS)]


@pytest.mark.parametrize("protocol, source", [("canopen", "program"), ("dbc", "recording")])
def test_capture_equals_the_simulation_exactly_with_zero_drops(tmp_path, program, simulated, protocol, source):
    what = served_source(source, program, simulated, tmp_path)
    port, res = serve_and_capture(["-t", "can", *what, "--speed", "2", "--opt", f"protocol={protocol}"], tmp_path)
    assert port.startswith("can://udp_multicast/239.74.163.")
    log = assert_complete_and_exact(res, tmp_path, simulated)
    np.testing.assert_allclose(log.t, simulated.t, rtol=0, atol=1e-12)
    assert log.metadata["transport"] == "can"


def test_injected_drops_and_corruptions_are_counted_exactly_and_never_recorded(tmp_path, program):
    simulated = run_programs([program], seed=FAULT_SEED)
    _, res = serve_and_capture(["-t", "can", str(program), "--speed", "2", *INJECTED_FAULTS], tmp_path,
                               wait=True)
    # a corrupted tick is a TPDO of 6 bytes where the mapping says 8: rejected, so also dropped
    assert_rejected_frames_are_dropped(res, tmp_path, simulated)


def test_a_silent_bus_longer_than_a_sync_counter_wrap_is_bridged_and_counted(tmp_path, program, simulated):
    # 0.5 s of silence at 1 kHz = 500 ticks: more than the 240 values of the SYNC counter
    _, res = serve_and_capture(["-t", "can", str(program), "--disconnect-at", "0.6", "--opt", "outage=0.5",
                                "--fault-log", "faults.json"], tmp_path, wait=True)
    log, faults = reconnected_log(res, tmp_path)
    unsent = faults["unsent_counters"]
    assert unsent[0] == 600 and len(unsent) > 240
    assert log.metadata["summary"]["dropped"] == len(unsent)
    assert_recorded_all_but(log, simulated, unsent)


def test_a_bus_that_stays_silent_ends_the_capture_with_one_line_and_a_complete_log(tmp_path, program):
    _, res = serve_and_capture(["-t", "can", str(program), "--disconnect-at", "0.5", "--opt", "outage=5"],
                               tmp_path, port_query="&timeout=0.5")
    err, log = assert_failed_with_one_line(res.returncode, res.stderr, tmp_path)
    assert "no CAN frame for 0." in err, res.stderr
    np.testing.assert_array_equal(log.metadata["counter"], np.arange(500))


def test_a_sigkilled_capture_leaves_a_log_missing_at_most_one_second(tmp_path):
    assert_sigkill_loses_at_most_one_second("can", tmp_path)


LIBRARY_CAPTURE = """
import sys
from core.errors import TransportError
from drivers.capture import capture
try:
    capture(sys.argv[1], "lib.mcap", progress=False)
except TransportError as exc:
    print(f"error: {exc}", file=sys.stderr)
"""


@pytest.mark.parametrize("caller", ["agent capture", "drivers.capture.capture"])
def test_an_absent_canopen_node_is_exactly_one_line(tmp_path, program, caller):
    """Node 1 answers its SDO uploads, node 9 is not on the bus: the one line says so, and
    canopen's own log line about the transfer it aborted stays off the terminal."""
    with Server(["-t", "can", str(program)], tmp_path) as srv:
        port = srv.port.replace("nodes=1,2", "nodes=1,9")
        assert "nodes=1,9" in port
        if caller == "agent capture":
            res = capture(["--port", port, "-o", LOG], tmp_path)
        else:
            res = subprocess.run([sys.executable, "-c", LIBRARY_CAPTURE, port], cwd=tmp_path,
                                 capture_output=True, text=True, timeout=60)
    assert res.stderr.splitlines() == [
        "error: node 9 did not answer the SDO upload of its TPDO mapping (No SDO response received); "
        "is it on the bus? (sdo=0 takes the mapping from the EDS instead)"], res.stderr
    assert res.stdout == ""
    assert res.returncode == (1 if caller == "agent capture" else 0)
    assert not (tmp_path / LOG).exists() and not (tmp_path / "lib.mcap").exists()  # nothing was recorded

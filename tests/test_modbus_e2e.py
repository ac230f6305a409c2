"""End to end over Modbus: `agent serve --transport modbus` and `agent capture` in separate processes.

TCP on 127.0.0.1 and RTU over a pseudo-terminal; the trace-buffer upload records exactly
what the virtual CNC computed (positions at the map's 1 nm scale), counts every injected
fault (a corrupted response is rejected, counted and read again, so it costs no sample),
recovers the samples of a disconnect from the controller's ring, and never sends
anything but a read request.

The process handling and the checks every transport shares are in tests/_capture_procs.py.
"""

from __future__ import annotations

import os
import signal
import time
import warnings
from dataclasses import replace

import numpy as np
import pytest

from _capture_procs import (FAULT_SEED, INJECTED_FAULTS, LOG, Server, assert_complete_and_exact, capture,
                            assert_failed_with_one_line, assert_recorded_all_but,
                            assert_sigkill_loses_at_most_one_second, assert_values_exact, injected_faults,
                            read_fault_log, serve_and_capture, start_capture, wait_for_size, write_program, MOVES)
from _capture_procs import program, simulated  # noqa: F401  (module-scoped fixtures, requested by name)
from virtual_cnc.machine_run import simulate as run_programs
from core.reader import load_mcap, load_recording
from drivers.modbus_map import default_map

pytestmark = pytest.mark.slow

SCALE = 1e-6  # mm per count of the default register map


def wire(values: np.ndarray) -> np.ndarray:
    """Whole nanometre counts as the exact decimal: count / 10^6 mm."""
    return np.rint(values / SCALE) / 10**6


@pytest.mark.parametrize("link", ["tcp", "rtu"])
def test_trace_capture_equals_the_simulation_exactly_with_zero_drops(tmp_path, program, simulated, link):
    port, res = serve_and_capture(["-t", "modbus", str(program), "--speed", "2", "--opt", f"link={link}",
                                   "--fault-log", "faults.json"], tmp_path, wait=True)
    assert port.startswith(f"modbus-{link}://") and "mode=trace" in port
    log = assert_complete_and_exact(res, tmp_path, simulated, wire)
    assert log.metadata["transport"] == f"modbus-{link}"
    assert log.metadata["programs"] == simulated.metadata["programs"]
    assert log.metadata["controller"] == simulated.metadata["controller"]
    # passive: the controller received read-holding-registers requests and nothing else
    assert set(read_fault_log(tmp_path / "faults.json")["function_codes"]) == {"3"}


@pytest.mark.parametrize("link", ["tcp", "rtu"])
def test_injected_drops_and_corruptions_are_counted_exactly_and_never_recorded(tmp_path, program, link):
    simulated = run_programs([program], seed=FAULT_SEED)
    _, res = serve_and_capture(["-t", "modbus", str(program), "--speed", "2", "--opt", f"link={link}",
                                *INJECTED_FAULTS], tmp_path, wait=True)
    assert res.returncode == 0, res.stderr
    faults = injected_faults(tmp_path)
    log = load_recording(tmp_path / LOG)
    s = log.metadata["summary"]
    # a damaged response (bad CRC / exception 4) is rejected, counted, and the read repeated:
    # corrupted ticks arrive intact, only the dropped ones are missing
    assert s["corrupt"] == faults["corrupted"] == faults["corrupted_responses"]
    assert s["dropped"] == faults["dropped"]
    assert_recorded_all_but(log, simulated, faults["dropped_counters"], wire)
    assert sum(e["count"] for e in log.metadata["events"] if e["kind"] == "dropped") == faults["dropped"]
    assert sum(e["count"] for e in log.metadata["events"] if e["kind"] == "corrupt") == faults["corrupted"]
    assert set(faults["function_codes"]) == {"3"}


def test_a_reader_slower_than_the_controller_catches_up_from_the_ring_and_no_wrong_clock_is_read(
        tmp_path, program, simulated):
    # A 230400-baud line (paced: 10 bits a byte) carries about 900 records/s of this map while the
    # controller replays at 2 kHz: the reader falls behind the ring, which holds the whole run, and
    # catches up after the program.  The records arrive at the line's pace, the head at the clock's.
    _, res = serve_and_capture(["-t", "modbus", str(program), "--speed", "2", "--opt", "link=rtu",
                                "--opt", "pace=true", "--opt", "baud=230400"], tmp_path, wait=True)
    assert_complete_and_exact(res, tmp_path, simulated, wire)


def test_a_ring_that_overruns_behind_a_slow_line_is_said_once_and_its_losses_counted(tmp_path, program, simulated):
    # 500 records hold 0.5 s; the paced line carries about 900 a second of the 2000 written.
    _, res = serve_and_capture(["-t", "modbus", str(program), "--speed", "2", "--opt", "link=rtu", "--opt",
                                "pace=true", "--opt", "baud=230400", "--opt", "capacity=500"], tmp_path, wait=True)
    assert res.returncode == 0, res.stderr
    assert res.stderr.count("trace ring (500 records) overran") == 1
    log = load_recording(tmp_path / LOG)
    s = log.metadata["summary"]
    k = log.metadata["counter"]
    missing = sorted(set(range(simulated.n_samples)) - set(k.tolist()))
    assert s["end"] == "program ended" and 0 < s["dropped"] == len(missing)
    assert_recorded_all_but(log, simulated, missing, wire)  # what was read is exact
    assert [e["kind"] for e in log.metadata["events"]].count("warning") == 1


def test_a_tcp_disconnect_is_survived_and_the_ring_refills_the_gap(tmp_path, program, simulated):
    _, res = serve_and_capture(["-t", "modbus", str(program), "--speed", "2", "--disconnect-at", "0.8",
                                "--fault-log", "faults.json"], tmp_path, wait=True)
    assert res.returncode == 0, res.stderr
    assert read_fault_log(tmp_path / "faults.json")["disconnects"] == 1
    log = load_recording(tmp_path / LOG)
    s = log.metadata["summary"]
    assert (s["reconnects"], s["dropped"], s["end"]) == (1, 0, "program ended")
    assert_recorded_all_but(log, simulated, [], wire)  # every tick, the outage's from the ring
    assert [e["kind"] for e in log.metadata["events"]].count("reconnect") == 1


def test_live_polling_records_exact_values_and_counts_the_ticks_it_did_not_see(tmp_path, program, simulated):
    port, res = serve_and_capture(["-t", "modbus", str(program), "--opt", "mode=live"], tmp_path)
    assert "mode=live" in port
    assert res.returncode == 0, res.stderr
    log = load_recording(tmp_path / LOG)
    k = log.metadata["counter"]
    assert len(k) > simulated.n_samples // 10  # polling sees most ticks (its rate is a benchmark figure)
    assert_values_exact(log, simulated, k, wire)
    s = log.metadata["summary"]
    assert s["dropped"] == (k[-1] - k[0] + 1) - len(k)


def test_a_controller_that_pauses_is_recorded_whole_not_refused_as_a_wrong_clock(tmp_path):
    # The controller process stops for 0.7 s one second in: its samples arrive late, then it
    # catches up.  A late batch is no wrong sample period; the capture goes on to the end.
    prog = write_program(tmp_path / "long.nc", MOVES * 3)  # about 4.7 s
    with Server(["-t", "modbus", str(prog)], tmp_path) as srv:
        cap = start_capture(["--port", srv.port, "-o", LOG], tmp_path)
        wait_for_size(tmp_path / LOG, 1)
        time.sleep(1.0)
        os.kill(srv.proc.pid, signal.SIGSTOP)
        time.sleep(0.7)
        os.kill(srv.proc.pid, signal.SIGCONT)
        _, err = cap.communicate(timeout=60)
    assert cap.returncode == 0, err
    log = load_recording(tmp_path / LOG)
    assert log.metadata["summary"]["end"] == "program ended"
    k = log.metadata["counter"]
    np.testing.assert_array_equal(k, np.arange(len(k)))


def test_a_controller_gone_for_good_ends_with_one_line_and_a_complete_log(tmp_path, program, simulated):
    with Server(["-t", "modbus", str(program)], tmp_path) as srv:
        cap = start_capture(["--port", srv.port + "&reconnect_s=0.5", "-o", LOG], tmp_path)
        wait_for_size(tmp_path / LOG, 5_000)
        srv.proc.kill()  # the controller is switched off: no listener to reconnect to
        _, err = cap.communicate(timeout=20)
    line, log = assert_failed_with_one_line(cap.returncode, err, tmp_path)
    assert "connection lost" in line and "within 0.5 s" in line, err
    k = log.metadata["counter"]
    assert 0 < len(k) < simulated.n_samples
    np.testing.assert_array_equal(k, np.arange(len(k)))
    assert_values_exact(log, simulated, k, wire)


def test_a_sigkilled_capture_leaves_a_log_missing_at_most_one_second(tmp_path):
    assert_sigkill_loses_at_most_one_second("modbus", tmp_path, wire)


# -- a map that does not fit the controller ------------------------------------------------------

def _write_map(path, axes, word_order="big", axis_word_order=None):
    """A register map TOML of the default layout: 32-bit values in ``word_order``, the axis
    positions in ``axis_word_order`` (default: the same)."""
    rmap = default_map(axes, word_order=word_order)
    if axis_word_order:
        rmap = replace(rmap, axes=tuple(replace(a, word_order=axis_word_order) for a in rmap.axes))
    path.write_text(rmap.to_toml())
    return path


@pytest.mark.parametrize("capture_map", ["map file", "default layout"])
def test_a_controller_writing_the_other_word_order_ends_with_one_line_naming_it(tmp_path, program, capture_map):
    """The peer writes every 32-bit value low word first; the capture reads high word first.
    No trace record holds its counter: the capture must not end as an empty success."""
    served = _write_map(tmp_path / "served.toml", ["X", "Y"], word_order="little")
    with Server(["-t", "modbus", str(program), "--opt", f"map={served}"], tmp_path) as srv:
        if capture_map == "map file":
            port = srv.port.replace(f"map={served}", f"map={_write_map(tmp_path / 'mine.toml', ['X', 'Y'])}")
        else:
            port = srv.port.replace(f"&map={served}", "")
        res = capture(["--port", port, "-o", LOG], tmp_path, timeout=60)
    assert res.returncode == 1, res.stderr
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and "Traceback" not in res.stderr, res.stderr
    assert "none holding its counter" in errors[0]
    assert 'the controller writes 32-bit values low word first; set word_order = "little"' in errors[0]
    assert ("mine.toml" in errors[0]) == (capture_map == "map file")
    # the log is complete (closed normally), empty, and says why
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        log = load_mcap(tmp_path / LOG)
    s = log.metadata["summary"]
    assert (s["received"], s["end"]) == (0, "unusable data")
    assert 'set word_order = "little"' in s["error"]
    end = log.metadata["events"][-1]
    assert end["kind"] == "end" and end["message"] == f"unusable data: {s['error']}"


def test_axis_positions_in_the_other_word_order_are_warned_about_once_per_axis(tmp_path, program, simulated):
    """Counters fit (so every sample is recorded) but the axis positions are written low word
    first: the values are garbage that jumps by tens of mm per sample, which is named."""
    served = _write_map(tmp_path / "served.toml", ["X", "Y"], axis_word_order="little")
    mine = _write_map(tmp_path / "mine.toml", ["X", "Y"])
    with Server(["-t", "modbus", str(program), "--opt", f"map={served}"], tmp_path) as srv:
        res = capture(["--port", srv.port.replace(f"map={served}", f"map={mine}"), "-o", LOG], tmp_path)
    assert res.returncode == 0, res.stderr
    warned = [ln for ln in res.stderr.splitlines() if ln.startswith("warning:")]
    assert [w.split()[2] for w in warned] == ["X", "Y"], res.stderr
    assert all("faster than any feed drive" in w and f"word_order and scale_mm of axis {w.split()[2]}" in w
               for w in warned)
    log = load_recording(tmp_path / LOG)
    assert log.n_samples == simulated.n_samples
    assert [e["kind"] for e in log.metadata["events"]].count("warning") == 2
    assert len(log.metadata["summary"]["warnings"]) == 2


def test_the_right_map_gives_no_plausibility_warning(tmp_path, program, simulated):
    """The same run with maps that agree: not a single warning (the check must not cry wolf on rapids)."""
    served = _write_map(tmp_path / "served.toml", ["X", "Y"], word_order="little")
    with Server(["-t", "modbus", str(program), "--opt", f"map={served}"], tmp_path) as srv:
        res = capture(["--port", srv.port, "-o", LOG], tmp_path)
    assert res.returncode == 0 and "warning" not in res.stderr, res.stderr
    assert_complete_and_exact(res, tmp_path, simulated, wire)

"""Run `agent serve` and `agent capture` as separate processes for the end-to-end capture tests.

Shared by the transport tests (serial, Modbus, CAN), so that each test file keeps only what
is specific to its transport:

* processes: :class:`Server` starts a simulated controller and returns once it has printed
  its ``port: <url>`` line; :func:`capture` runs a capture to completion;
  :func:`serve_and_capture` does both into ``log.mcap``;
* fixtures ``program`` (a ~1.8 s two-axis ISO program) and ``simulated`` (what the virtual
  CNC computes for it), module-scoped; a test module imports them by name;
* checks every transport makes of a capture: :func:`assert_complete_and_exact` (zero drops),
  :func:`assert_recorded_all_but` (exactly the ticks not lost), :func:`reconnected_log`,
  :func:`assert_failed_with_one_line`, and the whole SIGKILL check
  :func:`assert_sigkill_loses_at_most_one_second`.

Values are compared exactly after rounding to the wire's scale (:func:`expected_counts`,
or a transport's own ``wire`` function).
"""

from __future__ import annotations

import json
import os
import select
import signal
import shlex
import subprocess
import sys
import time
import warnings
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from core.writer import write_recording_mcap
from virtual_cnc.machine_run import simulate as run_programs
from core.reader import load_recording
from core.recording import Recording

AGENT = [sys.executable, "-m", "agent.cli"]
LOG = "log.mcap"  # where the helpers capture to, in the test's working directory
MOVES = ["X5 Y3", "X0 Y-2", "X2 Y0"]  # about 1.8 s on the default machine
FAULT_SEED = 4  # --seed seeds the encoder noise and the fault plan
INJECTED_FAULTS = ["--seed", str(FAULT_SEED), "--drop-rate", "0.03", "--corrupt-rate", "0.03",
                   "--fault-log", "faults.json"]

Wire = Callable[[np.ndarray], np.ndarray]  # positions (mm) -> as they come off the wire (mm)


class Server:
    """A running `agent serve` process; use as a context manager (killed on exit)."""

    def __init__(self, args: list[str], cwd: Path, timeout: float = 30.0) -> None:
        self.stderr_path = Path(cwd) / f"serve-{time.monotonic_ns()}.err"
        self._err = open(self.stderr_path, "wb")
        self.proc = subprocess.Popen(AGENT + ["serve", *args], cwd=cwd, stdout=subprocess.PIPE,
                                     stderr=self._err)
        line = _readline(self.proc, timeout)
        if not line.startswith("port: "):
            self.kill()
            raise AssertionError(f"serve printed {line!r} first; stderr: {self.stderr()}")
        self.port = shlex.split(line[len("port: "):])[0]  # printed shell-quoted

    def stderr(self) -> str:
        self._err.flush()
        return self.stderr_path.read_text(errors="replace")

    def wait(self, timeout: float = 30.0) -> int:
        return self.proc.wait(timeout)

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self._err.close()

    def __enter__(self) -> "Server":
        return self

    def __exit__(self, *exc: object) -> None:
        self.kill()


def _readline(proc: subprocess.Popen, timeout: float) -> str:
    fd = proc.stdout.fileno()
    end = time.monotonic() + timeout
    buf = b""
    while b"\n" not in buf:
        left = end - time.monotonic()
        if left <= 0 or proc.poll() is not None and not select.select([fd], [], [], 0)[0]:
            break
        if select.select([fd], [], [], min(left, 0.2))[0]:
            chunk = os.read(fd, 4096)
            if not chunk:
                break
            buf += chunk
    return buf.decode(errors="replace").split("\n")[0]


def start_capture(args: list[str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(AGENT + ["capture", "--quiet", *args], cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def capture(args: list[str], cwd: Path, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run(AGENT + ["capture", "--quiet", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)


def write_program(path: Path, moves: list[str], feed_mm_min: float = 600) -> Path:
    """A small hand-written ISO program (G21 G90 G61, G01 moves, M2)."""
    lines = ["G21 G90 G61"] + [f"G01 {m} F{feed_mm_min:g}" for m in moves] + ["M2"]
    path.write_text("\n".join(lines) + "\n")
    return path


def expected_counts(values: np.ndarray, counts_per_mm: int = 10_000) -> np.ndarray:
    """Positions as they come off a wire that carries integers of 1/counts_per_mm mm."""
    return np.rint(values * counts_per_mm) / counts_per_mm


def read_fault_log(path: Path) -> dict:
    return json.loads(Path(path).read_text())


# --- fixtures -------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def program(tmp_path_factory) -> Path:
    """The ISO program of :data:`MOVES`, written once per test module."""
    return write_program(tmp_path_factory.mktemp("prog") / "moves.nc", MOVES)


@pytest.fixture(scope="module")
def simulated(program: Path) -> Recording:
    """What the virtual CNC computes for ``program`` (default machine, seed 0)."""
    return run_programs([program])


# --- processes ------------------------------------------------------------------------------

def served_source(source: str, program: Path, simulated: Recording, cwd: Path) -> list[str]:
    """`agent serve` arguments for "program" (run live) or "recording" (replay of its simulated log,
    written as `agent simulate` writes it)."""
    if source == "program":
        return [str(program)]
    write_recording_mcap(simulated, cwd / "sim.mcap")
    return ["--recording", str(cwd / "sim.mcap")]


def serve_and_capture(serve_args: list[str], cwd: Path, port_query: str = "",
                      wait: bool = False) -> tuple[str, subprocess.CompletedProcess]:
    """Serve, capture into ``cwd/log.mcap`` until the capture exits; the port URL and the capture's result.

    ``port_query`` is appended to the served URL (e.g. ``"&timeout=0.5"``). ``wait`` waits for
    the serve to exit (it writes its ``--fault-log`` then); otherwise it is stopped with SIGTERM.
    """
    with Server(serve_args, cwd) as srv:
        res = capture(["--port", srv.port + port_query, "-o", LOG], cwd)
        if wait:
            srv.wait()
    return srv.port, res


def wait_for_size(path: Path, n_bytes: int, timeout: float = 20.0) -> None:
    """Until ``path`` holds at least ``n_bytes`` (a capture has that much on disk), or ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while (not path.exists() or path.stat().st_size < n_bytes) and time.monotonic() < deadline:
        time.sleep(0.05)


# --- checks ---------------------------------------------------------------------------------

def assert_values_exact(log: Recording, sim: Recording, counters, wire: Wire = expected_counts) -> None:
    """Commanded and actual positions of every axis equal the simulation's at ``counters``, as on the wire."""
    for axis in sim.axis_names:
        np.testing.assert_array_equal(log.axes[axis].commanded, wire(sim.axes[axis].commanded[counters]))
        np.testing.assert_array_equal(log.axes[axis].actual, wire(sim.axes[axis].actual[counters]))


def assert_recorded_all_but(log: Recording, sim: Recording, missing, wire: Wire = expected_counts) -> None:
    """The log holds exactly the ticks of ``sim`` whose counters are not in ``missing``, values exact."""
    missing = set(missing)
    kept = np.array([c for c in range(sim.n_samples) if c not in missing])
    np.testing.assert_array_equal(log.metadata["counter"], kept)
    assert_values_exact(log, sim, kept, wire)


def assert_complete_and_exact(res: subprocess.CompletedProcess, cwd: Path, sim: Recording,
                              wire: Wire = expected_counts) -> Recording:
    """A clean capture of the whole run: exit 0, every tick once with exact values and segments,
    nothing dropped or corrupt, ended by the program. Returns the log."""
    assert res.returncode == 0, res.stderr
    log = load_recording(cwd / LOG)
    np.testing.assert_array_equal(log.metadata["counter"], np.arange(sim.n_samples))
    assert_values_exact(log, sim, slice(None), wire)
    np.testing.assert_array_equal(log.segment, sim.segment)
    s = log.metadata["summary"]
    assert (s["received"], s["dropped"], s["corrupt"], s["end"]) == (sim.n_samples, 0, 0, "program ended")
    return log


def injected_faults(cwd: Path) -> dict:
    """The serve's fault log after a run with :data:`INJECTED_FAULTS` (over 10 drops and corruptions)."""
    faults = read_fault_log(cwd / "faults.json")
    assert faults["dropped"] > 10 and faults["corrupted"] > 10
    return faults


def assert_rejected_frames_are_dropped(res: subprocess.CompletedProcess, cwd: Path, sim: Recording) -> Recording:
    """For links where a corrupt frame is lost (serial, CAN): every corruption counted as corrupt and
    as dropped, and the log holds exactly the ticks neither dropped nor corrupted. Returns the log."""
    assert res.returncode == 0, res.stderr
    faults = injected_faults(cwd)
    log = load_recording(cwd / LOG)
    s = log.metadata["summary"]
    assert s["corrupt"] == faults["corrupted"]
    assert s["dropped"] == faults["dropped"] + faults["corrupted"]
    assert_recorded_all_but(log, sim, set(faults["dropped_counters"]) | set(faults["corrupted_counters"]))
    return log


def reconnected_log(res: subprocess.CompletedProcess, cwd: Path) -> tuple[Recording, dict]:
    """After a served ``--disconnect-at``: the capture exited 0, reconnected once and ran to the
    program's end. Returns the log and the serve's fault log."""
    assert res.returncode == 0, res.stderr
    faults = read_fault_log(cwd / "faults.json")
    log = load_recording(cwd / LOG)
    s = log.metadata["summary"]
    assert s["reconnects"] == 1 and s["end"] == "program ended"
    return log, faults


def assert_failed_with_one_line(returncode: int, stderr: str, cwd: Path) -> tuple[str, Recording]:
    """A capture whose link did not come back: exit 1, one ``error:`` line and no traceback, and a
    complete log (closed normally: no "cut off" warning) ending in "transport error".
    Returns the error line and the log."""
    assert returncode == 1
    lines = [ln for ln in stderr.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, stderr
    assert "Traceback" not in stderr
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        log = load_recording(cwd / LOG)
    assert log.metadata["summary"]["end"] == "transport error"
    return lines[0], log


def assert_sigkill_loses_at_most_one_second(transport: str, cwd: Path, wire: Wire = expected_counts) -> None:
    """SIGKILL a capture well into a ~3.4 s run: its log is readable (with a warning), starts at
    tick 0, has no gap, and ends at most 1 s (of controller time) before what had been sent."""
    prog = write_program(cwd / "long.nc", ["X20", "X0", "X10"], feed_mm_min=900)  # ~3.4 s
    sim = run_programs([prog])
    out = cwd / LOG
    with Server(["-t", transport, str(prog), "--fault-log", "faults.json", "--linger", "0"], cwd) as srv:
        cap = start_capture(["--port", srv.port, "-o", LOG], cwd)
        wait_for_size(out, 20_000)  # until well over half a second of samples is on disk
        time.sleep(1.2)
        os.kill(cap.pid, signal.SIGKILL)
        t_kill = time.time()
        cap.wait(10)
        srv.wait()
    timeline = read_fault_log(cwd / "faults.json")["sent_timeline"]
    sent_by_kill = max(c for t, c in timeline if t <= t_kill)
    with pytest.warns(Warning, match="cut off|did not close cleanly"):
        log = load_recording(out)
    k = log.metadata["counter"]
    assert k[0] == 0
    np.testing.assert_array_equal(k, np.arange(k[-1] + 1))
    lost_s = (sent_by_kill - k[-1]) * sim.sample_period
    assert lost_s <= 1.0, f"lost {lost_s:.3f} s"
    assert_values_exact(log, sim, k, wire)

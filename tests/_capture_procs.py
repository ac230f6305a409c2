"""Run `agent serve` and `agent capture` as separate processes for the end-to-end capture tests.

Shared by the transport tests (serial, Modbus, CAN): :func:`start_serve` starts a
simulated controller and returns once it has printed its ``port: <url>`` line;
:func:`capture` runs a capture to completion; :func:`expected_counts` gives what a
capture must record for a served recording (positions rounded to the wire scale).
"""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

AGENT = [sys.executable, "-m", "agent.cli"]


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
        self.port = line[len("port: "):].strip()

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

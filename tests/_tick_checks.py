"""Checks shared by the capture fault-injection suites (tests/test_capture_faults_*.py).

Their peers send tick k with commanded = k and actual = -k counts, so each recorded
sample names the tick it belongs to.  A capture passes when either

* it exits 0 and every sample is stamped within half a period of its true tick, the
  positions are the tick's, and ``dropped`` is exactly the ticks missing between the first
  and the last sample (:func:`assert_every_sample_on_its_tick`), or
* it exits non-zero with exactly one ``error:`` line and no traceback
  (:func:`assert_one_error_line`).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from core.reader import load_mcap, load_recording
from core.recording import Recording

AGENT = [sys.executable, "-m", "agent.cli"]


def run_capture(port: str, cwd: Path, *extra: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    """``agent capture --port PORT -o log.mcap -q EXTRA...`` in ``cwd``, run to its end."""
    return subprocess.run(AGENT + ["capture", "--port", port, "-o", "log.mcap", "-q", *extra], cwd=cwd,
                          capture_output=True, text=True, timeout=timeout)


def error_lines(res: subprocess.CompletedProcess) -> list[str]:
    return [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]


def assert_one_error_line(res: subprocess.CompletedProcess, *fragments: str) -> str:
    """Non-zero exit, one ``error:`` line holding every fragment, no traceback; returns the line."""
    lines = error_lines(res)
    assert res.returncode != 0, res.stderr
    assert len(lines) == 1, res.stderr
    assert "Traceback" not in res.stderr, res.stderr
    for f in fragments:
        assert f in lines[0], lines[0]
    return lines[0]


def clock_ratio(line: str) -> float:
    """The ratio a ``clock mismatch`` error line states ("... clock runs R times as fast ...")."""
    m = re.search(r"clock runs ([0-9.e+-]+) times as fast as the host's", line)
    assert m, line
    return float(m.group(1))


def ticks_of(log: Recording, counts_per_mm: float) -> np.ndarray:
    """The true tick of every recorded sample, from its commanded position (= tick counts)."""
    return np.rint(log.axes["X"].commanded * counts_per_mm).astype(np.int64)


def assert_every_sample_on_its_tick(log: Recording, true_period_s: float, counts_per_mm: float) -> np.ndarray:
    """Every sample within half a period of its tick, positions of that tick, drops exact; the ticks."""
    k = ticks_of(log, counts_per_mm)
    np.testing.assert_array_equal(log.axes["X"].actual, -log.axes["X"].commanded)
    assert np.all(np.abs(log.t - k * true_period_s) <= true_period_s / 2), "a sample is stamped off its tick"
    s = log.metadata["summary"]
    counter = np.asarray(log.metadata["counter"])
    assert s["dropped"] == counter[-1] - counter[0] + 1 - len(counter)
    assert s["received"] == len(counter)
    return k


def load(cwd: Path) -> Recording:
    return load_recording(Path(cwd) / "log.mcap")


def summary(cwd: Path) -> dict:
    """The summary of ``cwd/log.mcap``, also of a log without samples."""
    return load_mcap(Path(cwd) / "log.mcap").metadata["summary"]

"""`agent identify` from the command line: outputs, and one-line errors on bad recordings."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from core.writer import write_recording_csv
from core.recording import AxisTrace, Recording

from typer.testing import CliRunner

from agent import cli

AGENT = [sys.executable, "-m", "agent.cli"]
cli._register()


def run_agent(*args: str) -> subprocess.CompletedProcess:
    """A real process, as a user runs it."""
    return subprocess.run([*AGENT, *map(str, args)], capture_output=True, text=True, timeout=300)


def run_in_process(*args: str):
    """The same command line in this process (fast; used for the many error cases)."""
    return CliRunner().invoke(cli.app, [str(a) for a in args])


def _random_moves(n: int = 6000, seed: int = 0, scale: float = 1.0) -> Recording:
    """A quick first-order-lag 'drive' following random point-to-point moves (enough for the CLI)."""
    rng = np.random.default_rng(seed)
    Ts = 1e-3
    targets = np.repeat(rng.uniform(-5, 5, n // 300 + 1), 300)[:n]
    x_r = np.convolve(targets, np.ones(100) / 100, mode="same")
    x = np.empty(n)
    x[0] = x_r[0]
    for k in range(1, n):
        x[k] = x[k - 1] + Ts * 30.0 * (x_r[k - 1] - x[k - 1])
    return Recording(np.arange(n) * Ts, {"X": AxisTrace(x_r * scale, x * scale)}, Ts)


@pytest.fixture(scope="module")
def good_csv(tmp_path_factory) -> Path:
    return write_recording_csv(_random_moves(), tmp_path_factory.mktemp("rec") / "good.csv")


def test_identify_writes_spec_json(tmp_path, good_csv):
    out = tmp_path / "r.json"
    proc = run_agent("identify", good_csv, "--no-diagnose", "--json", out)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(out.read_text())
    x = doc["axes"]["X"]
    assert set(x["model"]) == {"a1", "a2", "a3", "b0", "b1", "b2", "d0", "d1"}
    assert set(x["search_variables"]) == {"wn_hz", "zeta", "p_hz"}
    assert x["solver"] == "exact" and isinstance(x["active_constraints"], list)
    assert {"freq_hz", "damping"} <= set(x["poles"][0])
    assert x["fit"]["identification"]["tracking_error_fit_pct"] > 90
    assert "tracking-error fit" in proc.stdout


def _write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    "maker, message",
    [
        (lambda d: _write(d, "empty.csv", ""), "file is empty"),
        (lambda d: _write(d, "one.csv", "t_s,commanded_mm,actual_mm\n0,1,1\n"), "single sample"),
        (lambda d: _write(d, "nan.csv", "t_s,commanded_mm,actual_mm\n0,0,0\n0.001,nan,0\n0.002,1,1\n"), "NaN"),
        (lambda d: _write(d, "back.csv", "t_s,commanded_mm,actual_mm\n0,0,0\n0.002,1,1\n0.001,2,2\n"),
         "time goes backwards"),
        (lambda d: write_recording_csv(
            Recording(np.arange(500) * 1e-3, {"X": AxisTrace(np.full(500, 3.0), np.full(500, 3.0))}, 1e-3),
            d / "still.csv"), "no motion on axis X"),
        (lambda d: write_recording_csv(
            Recording(np.arange(2000) * 1e-3,
                      {"X": AxisTrace(np.linspace(0, 10, 2000), np.linspace(0, 10, 2000) - 0.01 * np.tanh(
                          np.arange(2000) / 50))}, 1e-3),
            d / "oneway.csv"), "never reverses direction"),
        (lambda d: d / "absent.mcap", "no such file"),
    ],
)
def test_bad_recordings_give_one_line_errors(tmp_path, maker, message):
    path = maker(tmp_path)
    proc = run_in_process("identify", path, "--no-diagnose")
    assert proc.exit_code != 0
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), proc.stderr
    assert message in lines[0]


def test_an_axis_recorded_but_never_moved_is_left_out_with_a_warning_unless_asked_for(tmp_path):
    # a capture of every axis of the machine while the programs moved X only
    moved = _random_moves()
    still = AxisTrace(np.full(moved.n_samples, 5.0), np.full(moved.n_samples, 5.0))
    path = write_recording_csv(Recording(moved.t, {"X": moved.axes["X"], "Y": still}, moved.sample_period),
                               tmp_path / "xy.csv")
    out = tmp_path / "r.json"
    proc = run_in_process("identify", path, "--no-diagnose", "--json", out)
    assert proc.exit_code == 0, proc.stderr
    assert list(json.loads(out.read_text())["axes"]) == ["X"]
    warned = [ln for ln in proc.stderr.splitlines() if ln.startswith("warning:")]
    assert len(warned) == 1 and "axis Y never moves" in warned[0] and "5 mm" in warned[0]
    asked = run_in_process("identify", path, "--no-diagnose", "--axes", "Y")  # named: refused
    assert asked.exit_code == 2 and "no motion on axis Y" in asked.stderr


def test_metres_given_as_mm_is_refused_unless_the_units_are_given(tmp_path):
    path = write_recording_csv(_random_moves(scale=1e-3), tmp_path / "metres.csv")
    proc = run_in_process("identify", path, "--no-diagnose")
    assert proc.exit_code == 2 and "--units" in proc.stderr and "look like metres" in proc.stderr
    proc = run_in_process("identify", path, "--no-diagnose", "--units", "m", "--json", tmp_path / "m.json")
    assert proc.exit_code == 0, proc.output
    mm = write_recording_csv(_random_moves(), tmp_path / "mm.csv")
    assert run_in_process("identify", mm, "--no-diagnose", "--json", tmp_path / "mm.json").exit_code == 0
    # converted to mm: the poles of the same moves recorded in mm
    poles = [[p["freq_hz"] for p in json.loads((tmp_path / f).read_text())["axes"]["X"]["poles"]]
             for f in ("m.json", "mm.json")]
    np.testing.assert_allclose(poles[0], poles[1], rtol=1e-3)


def test_unknown_axis_and_solver_are_named(tmp_path, good_csv):
    proc = run_in_process("identify", good_csv, "--axis", "Q", "--no-diagnose")
    assert proc.exit_code == 2 and "axis Q is not in" in proc.stderr
    proc = run_in_process("identify", good_csv, "--solver", "magic")
    assert proc.exit_code == 2 and "--solver 'magic'" in proc.stderr

"""Bad input through the real `agent` command: one `error:` line naming the problem in the user's
terms, exit 2, no traceback, and nothing written on a failed run (issue 43's list, one test each)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from core.reader import load_recording
from core.recording import AxisTrace, Recording
from core.writer import write_recording_csv

AGENT = [sys.executable, "-m", "agent.cli"]


def agent(*args, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([*AGENT, *map(str, args)], capture_output=True, text=True, timeout=300, **kw)


def refused(proc: subprocess.CompletedProcess, *words: str) -> str:
    """The run failed as bad input: exit 2, one `error:` line holding ``words``, no traceback."""
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert "Traceback" not in proc.stderr + proc.stdout
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    """Identification programs and their recording on the default virtual machine (5 s, axis X)."""
    d = tmp_path_factory.mktemp("bad_input")
    assert agent("generate", "--axes", "X", "--n-low", 40, "--n-high", 40, "-o", d / "prog").returncode == 0
    assert agent("simulate", d / "prog/ident_low.nc", d / "prog/ident_high.nc", "-o", d / "run.mcap").returncode == 0
    return d


@pytest.fixture(scope="module")
def run(work) -> Recording:
    return load_recording(work / "run.mcap")


def _csv(path: Path, rec: Recording, commanded=None, actual=None, t=None, n: int | None = None) -> Path:
    tr = rec.axes["X"]
    c = tr.commanded if commanded is None else commanded
    a = tr.actual if actual is None else actual
    tt = rec.t if t is None else t
    seg = rec.segment
    if n is not None:
        c, a, tt, seg = c[1000:1000 + n], a[1000:1000 + n], tt[:n], None
    return write_recording_csv(Recording(tt, {"X": AxisTrace(c, a)}, rec.sample_period, segment=seg), path)


# --------------------------------------------------------------------------- recordings no model comes from


def test_no_motion_says_the_axis_does_not_move(tmp_path):
    rec = Recording(np.arange(3000) * 1e-3, {"X": AxisTrace(np.full(3000, 3.0), np.full(3000, 3.0))}, 1e-3)
    refused(agent("identify", write_recording_csv(rec, tmp_path / "still.csv"), "--no-diagnose"),
            "no motion on axis X")


def test_actual_equal_to_commanded_says_there_is_no_tracking_error(tmp_path, run):
    path = _csv(tmp_path / "same.csv", run, actual=run.axes["X"].commanded)
    refused(agent("identify", path, "--no-diagnose", "--json", tmp_path / "r.json"),
            "actual position equals the commanded position", "no tracking error")
    assert not (tmp_path / "r.json").exists()


def test_a_constant_offset_says_so(tmp_path, run):
    path = _csv(tmp_path / "offset.csv", run, actual=run.axes["X"].commanded + 0.5)
    refused(agent("identify", path, "--no-diagnose"), "commanded position plus a constant 0.5 mm")


@pytest.mark.parametrize("n, seconds", [(20, "0.019 s"), (200, "0.199 s")])
def test_a_recording_too_short_to_identify_is_refused(tmp_path, run, n, seconds):
    refused(agent("identify", _csv(tmp_path / "short.csv", run, n=n), "--no-diagnose"),
            f"only {seconds} ({n} samples) long", "at least 1 s")


def test_one_direction_only_says_it_never_reverses(tmp_path):
    x_r = np.linspace(0, 10, 2000)
    rec = Recording(np.arange(2000) * 1e-3, {"X": AxisTrace(x_r, x_r - 0.01 * np.tanh(np.arange(2000) / 50))}, 1e-3)
    refused(agent("identify", write_recording_csv(rec, tmp_path / "oneway.csv"), "--no-diagnose"),
            "never reverses direction", "positive direction only")


def test_time_in_milliseconds_is_refused(tmp_path, run):
    refused(agent("identify", _csv(tmp_path / "ms.csv", run, t=run.t * 1e3), "--no-diagnose"),
            "one sample every 1 s", "milliseconds")


def test_commanded_and_actual_swapped_is_refused(tmp_path, run):
    tr = run.axes["X"]
    refused(agent("identify", _csv(tmp_path / "swapped.csv", run, commanded=tr.actual, actual=tr.commanded),
                  "--no-diagnose"), "actual position leads the commanded position", "swapped")


def test_a_prediction_log_is_not_identified(tmp_path, work):
    result = tmp_path / "r.json"
    assert agent("identify", work / "run.mcap", "--no-diagnose", "--no-refine", "--json", result).returncode == 0
    pred = tmp_path / "pred.mcap"
    assert agent("simulate", work / "prog/ident_low.nc", "--machine", result, "-o", pred).returncode == 0
    refused(agent("identify", pred, "--no-diagnose"), "is a prediction", "not measured")


def test_metres_are_refused_unless_the_units_are_given(tmp_path, run):
    tr = run.axes["X"]
    path = _csv(tmp_path / "metres.csv", run, commanded=tr.commanded * 1e-3, actual=tr.actual * 1e-3)
    refused(agent("identify", path, "--no-diagnose"), "--units", "look like metres")
    ok = agent("identify", path, "--no-diagnose", "--no-refine", "--units", "m")
    assert ok.returncode == 0, ok.stderr
    assert "0.00 µm" not in ok.stdout


# --------------------------------------------------------------------------- result JSONs and --set


@pytest.fixture(scope="module")
def result(work) -> Path:
    """The identified machine of the fixture recording (agent identify --json)."""
    path = work / "result.json"
    proc = agent("identify", work / "run.mcap", "--no-diagnose", "--json", path)
    assert proc.returncode == 0, proc.stderr
    return path


def test_a_json_list_is_not_a_rapid_ident_result(tmp_path, work):
    other = tmp_path / "other.json"
    other.write_text("[1, 2, 3]")
    refused(agent("identify", work / "run.mcap", "--model", other), "--model", "not a rapid-ident result")
    refused(agent("predict", work / "prog/ident_low.nc", "--machine", other), "not a rapid-ident result")


def test_another_tools_json_is_not_called_an_older_rapid_ident(tmp_path, work):
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"tool": "servo-tuner", "axes": {"X": {"kp": 20}}}))
    line = refused(agent("predict", work / "prog/ident_low.nc", "--machine", other), "not a rapid-ident result")
    assert "older" not in line


def test_an_effect_given_as_a_string_is_named(tmp_path, work, result):
    doc = json.loads(result.read_text())
    doc["axes"]["X"]["virtual_model"]["effects"] = {"backlash": "0.01"}
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    refused(agent("predict", work / "prog/ident_low.nc", "--machine", bad), "axis X", "effect backlash",
            "name: value pairs")
    doc["axes"]["X"]["virtual_model"]["effects"] = {"backlash": {"gap_mm": "0.01"}}
    bad.write_text(json.dumps(doc))
    refused(agent("predict", work / "prog/ident_low.nc", "--machine", bad), "backlash gap_mm must be a finite number")


@pytest.mark.parametrize("assignment, words", [
    ("X.a1=-3000", ["'X.a1=-3000'", "unstable", "right half-plane"]),
    ("X.a1=1e30", ["'X.a1=1e30'", "never move"]),
])
def test_set_refuses_a_model_that_cannot_run(tmp_path, work, result, assignment, words):
    json_out = tmp_path / "p.json"
    refused(agent("predict", work / "prog/ident_low.nc", "--machine", result, "--set", assignment,
                  "--json", json_out), *words)
    assert not json_out.exists()


def test_effect_parameters_are_checked_the_same_way_by_set_and_effect(tmp_path, work, result):
    via_set = refused(agent("predict", work / "prog/ident_low.nc", "--machine", result,
                            "--set", "X.backlash.gap_mm=-1"), "backlash gap_mm must be > 0, got -1.0")
    via_effect = refused(agent("simulate", work / "prog/ident_low.nc", "--effect", "backlash=-1",
                               "-o", tmp_path / "x.mcap"), "backlash gap_mm must be > 0, got -1.0")
    assert via_set.split("backlash gap_mm")[1] == via_effect.split("backlash gap_mm")[1]
    assert not (tmp_path / "x.mcap").exists()


def test_generate_refuses_a_negative_seed(tmp_path):
    refused(agent("generate", "--seed", -1, "-o", tmp_path / "p"), "--seed must be a whole number >= 0")
    assert not (tmp_path / "p").exists()


# --------------------------------------------------------------------------- outputs


@pytest.mark.parametrize("command", ["identify", "predict", "ballbar", "simulate", "serve", "capture"])
def test_an_output_into_a_missing_directory_fails_before_the_run(tmp_path, work, result, command):
    missing = tmp_path / "no_such_dir"
    args = {
        "identify": ["identify", work / "run.mcap", "--json", missing / "r.json"],
        "predict": ["predict", work / "prog/ident_low.nc", "--machine", result, "--report", missing / "p.html"],
        "ballbar": ["ballbar", "--machine", result, "--json", missing / "b.json"],
        "simulate": ["simulate", work / "prog/ident_low.nc", "-o", missing / "s.mcap"],
        "serve": ["serve", work / "prog/ident_low.nc", "--transport", "serial", "--fault-log", missing / "f.json"],
        "capture": ["capture", "--port", "serial:///dev/null", "-o", missing / "c.mcap"],
    }[command]
    proc = agent(*args)
    refused(proc, "no_such_dir does not exist")
    assert proc.stdout == ""  # refused before the run: nothing computed, nothing printed


def test_a_closed_stdout_ends_the_command_quietly(work, tmp_path):
    cmd = " ".join([*AGENT, "simulate", str(work / "prog/ident_low.nc"), "-o", str(tmp_path / "s.mcap")])
    proc = subprocess.run(f"{cmd} | head -c 1 >/dev/null; echo ${{PIPESTATUS[0]}}", shell=True, executable="/bin/bash",
                          capture_output=True, text=True, timeout=300)
    assert proc.stderr == ""
    assert proc.stdout.strip() in ("0", "141")  # done, or stopped by the closed pipe: never "error: Broken pipe"
    assert (tmp_path / "s.mcap").exists()


# --------------------------------------------------------------------------- the command line


def test_model_scores_the_old_model_as_it_was_identified(tmp_path, work, result):
    new = tmp_path / "new.mcap"
    assert agent("simulate", work / "prog/ident_low.nc", work / "prog/ident_high.nc", "--seed", 7, "-o",
                 new).returncode == 0
    out = tmp_path / "scored.json"
    report = tmp_path / "scored.html"
    proc = agent("identify", new, "--model", result, "--no-diagnose", "--json", out, "--report", report)
    assert proc.returncode == 0, proc.stderr
    assert f"the model saved in {result.name} as its virtual machine runs it, checked on this recording" \
           in report.read_text()
    old = json.loads(result.read_text())["axes"]["X"]
    assert (f"the model saved in {result.name} as its virtual machine runs it, preview shift "
            f"{old['preview_shift_samples']} sample(s), checked on this recording") in proc.stdout
    assert "equation-error model before refinement" not in proc.stdout  # no fresh-fit lines passed off as its
    scored = json.loads(out.read_text())["axes"]["X"]
    assert scored["model_from"] == result.name
    assert scored["preview_shift_samples"] == old["preview_shift_samples"]
    assert scored["model"] == old["model"]
    # the same model, scored as identified, fits a second recording of the same machine as well
    assert scored["fit"]["identification"]["tracking_error_fit_pct"] > 99


def test_against_without_the_diagnosis_is_refused(work):
    refused(agent("identify", work / "run.mcap", "--no-diagnose", "--against", work / "run.mcap"),
            "--against", "--no-diagnose")


def test_solver_ls_says_it_is_unconstrained_and_flags_poles_outside_the_bounds(work):
    proc = agent("identify", work / "run.mcap", "--solver", "ls", "--no-diagnose")
    assert proc.returncode == 0, proc.stderr
    assert "constrained model reaches" not in proc.stdout and "active constraints: none" not in proc.stdout
    assert "constraints: none applied (solver ls, unconstrained); outside the bounds: f_max (poles up to 500 Hz" \
           in proc.stdout


# --------------------------------------------------------------------------- resource limits and machines


def test_a_program_too_long_to_hold_is_refused_before_allocating(tmp_path, result):
    prog = tmp_path / "long.ngc"
    prog.write_text("G21 G90 G94\nG1 X100000 F60\nM2\n")
    for args in (["predict", prog, "--machine", result], ["simulate", prog, "-o", tmp_path / "long.mcap"]):
        proc = subprocess.run(["/usr/bin/time", "-f", "%M", *AGENT, *map(str, args)], capture_output=True,
                              text=True, timeout=300)
        *lines, peak_kb = [ln for ln in proc.stderr.strip().splitlines() if not ln.startswith("Command exited")]
        refused(subprocess.CompletedProcess(args, proc.returncode, proc.stdout, "\n".join(lines)),
                "long.ngc runs 27.8 h of machine time", "1e+08 samples at 1000 Hz")
        assert int(peak_kb) < 1_000_000  # refused before the arrays: under 1 GB, not the 50 GB it would need
    assert not (tmp_path / "long.mcap").exists()


def test_a_ballbar_circle_too_long_to_hold_is_refused(tmp_path, work):
    agent("generate", "--axes", "X,Y", "--n-low", 30, "--n-high", 30, "-o", tmp_path / "p")
    rec, res = tmp_path / "xy.mcap", tmp_path / "xy.json"
    assert agent("simulate", tmp_path / "p/ident_low.nc", tmp_path / "p/ident_high.nc", "-o", rec).returncode == 0
    assert agent("identify", rec, "--no-diagnose", "--no-refine", "--json", res).returncode == 0
    refused(agent("ballbar", "--machine", res, "--radius", "1e6"), "ballbar runs 419 h of machine time")


def test_a_machine_file_with_an_impossible_servo_loop_is_refused(tmp_path, work):
    toml = tmp_path / "hot.toml"
    toml.write_text('base = "fadal-ppi"\n[axes.X]\nKp = 1e9\n')
    refused(agent("simulate", work / "prog/ident_low.nc", "--machine", toml, "-o", tmp_path / "hot.mcap"),
            "machine hot, axis X", "Kp 1e+09", "above the 500 Hz a servo loop closed every 1 ms can realise")
    assert not (tmp_path / "hot.mcap").exists()


def test_metres_the_log_declares_are_converted_with_a_warning(tmp_path, run):
    from core.writer import write_recording_mcap

    tr = run.axes["X"]
    rec = Recording(run.t, {"X": AxisTrace(tr.commanded * 1e-3, tr.actual * 1e-3)}, run.sample_period,
                    segment=run.segment)
    path = write_recording_mcap(rec, tmp_path / "metres.mcap", metadata={"units": "m"})
    proc = agent("identify", path, "--no-diagnose", "--no-refine")
    assert proc.returncode == 0, proc.stderr
    warnings = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(warnings) == 1 and warnings[0].startswith("warning: ") and "recorded in metres" in warnings[0] \
        and "converted to mm" in warnings[0]
    assert "0.00 µm" not in proc.stdout

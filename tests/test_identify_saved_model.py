"""`agent identify LOG --model OLD.json`: a saved model checked on a new recording of its machine.

The saved model is the one its virtual machine runs (``virtual_model``: eq. 3.3 with the
effects the diagnosis accepted), LOG is held-out data for it, and the diagnosis looks only
for physics that model lacks.  The fixture: a result JSON whose model carries an amplifier
saturation (drive-zoo-dev2 case_003's, rounded), and recordings simulated by that model —
as it is, and with a 10 µm backlash it does not carry.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from core.recording import AxisTrace, Recording
from core.writer import write_recording_csv
from ident.axis_model import AxisModel
from ident.model import DriveModel
from ident.results import RESULT_FORMAT
from tests.test_diagnosis_units import Ts, point_to_point

AGENT = [sys.executable, "-m", "agent.cli"]
BASE = DriveModel(a1=299.4, a2=33472.0, a3=1.4075e6, b0=0.0, b1=273.3, b2=33472.0, d0=396.6, d1=-309.2)
SATURATION = {"limit": 2825.0, "limit_slope": 3.49}
SAVED = AxisModel(BASE, Ts, 0, {"saturation": SATURATION}, "sampled")


def _recording(model: AxisModel, path: Path) -> Path:
    """3 s of point-to-point moves (up to 2000 mm/s², where the limit clips) on ``model``, 0.2 µm noise."""
    x_r = point_to_point(3, T=3.0, span=10.0, v_max=150.0, a_max=2000.0)
    x = model.simulate(x_r) + np.random.default_rng(1).normal(0.0, 2e-4, x_r.size)
    return write_recording_csv(Recording(np.arange(x_r.size) * Ts, {"X": AxisTrace(x_r, x)}, Ts), path)


def _check(work: Path, log: Path) -> tuple[str, dict]:
    """``agent identify LOG --model saved.json --json``: the summary and the JSON's axis X."""
    out = work / f"{log.stem}_checked.json"
    proc = subprocess.run([*AGENT, "identify", str(log), "--model", str(work / "saved.json"), "--json", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout, json.loads(out.read_text())["axes"]["X"]


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    """saved.json: a result JSON whose virtual machine runs SAVED (its "model" is the base alone, as
    a diagnosis re-fit leaves it)."""
    d = tmp_path_factory.mktemp("saved_model")
    axis = {"model": BASE.to_dict(None, Ts)["model"], "preview_shift_samples": 0, "virtual_model": SAVED.to_dict()}
    (d / "saved.json").write_text(json.dumps({"format": RESULT_FORMAT, "source": "earlier.csv", "axes": {"X": axis}}))
    return d


@pytest.fixture(scope="module")
def same_machine(work) -> tuple[str, dict]:
    """The saved model checked on a new recording of the machine it describes."""
    return _check(work, _recording(SAVED, work / "same.csv"))


@pytest.fixture(scope="module")
def worn_machine(work) -> tuple[str, dict]:
    """The saved model checked on a recording of its machine with a 10 µm backlash it does not carry."""
    worn = AxisModel(BASE, Ts, 0, {"saturation": SATURATION, "backlash": {"gap_mm": 0.01}}, "sampled")
    return _check(work, _recording(worn, work / "worn.csv"))


def _line(stdout: str, label: str) -> str:
    return next(ln.strip() for ln in stdout.splitlines() if ln.strip().startswith(label))


def test_the_saved_model_is_scored_with_the_effects_it_carries(same_machine):
    stdout, axis = same_machine
    # without its saturation the saved base fits this recording at 77 %
    assert axis["fit"]["identification"]["tracking_error_fit_pct"] > 99.0
    assert axis["model_from"] == "saved.json"
    assert "with saturation of the control-equivalent acceleration, limit 2825 mm/s²" in _line(stdout, "identified:")


def test_the_new_recording_is_held_out_not_the_identification_recording(same_machine):
    stdout, _ = same_machine
    predicts = _line(stdout, "predicts:")
    assert predicts.startswith("predicts:        held-out fit 99."), predicts
    assert "on this recording, which the model of saved.json was not identified on" in predicts
    assert "identification recording" not in stdout and "--validate" not in stdout


def test_an_effect_the_saved_model_carries_is_not_missing_physics(same_machine):
    stdout, axis = same_machine
    assert axis["diagnosis"]["verdict"] == "none"
    assert "saturation" not in [c["effect"] for c in axis["diagnosis"]["candidates"]]  # not tried again
    assert _line(stdout, "missing physics:").startswith(
        "missing physics: nothing beyond the saturation the model of saved.json carries")


def test_a_saved_model_that_still_holds_is_kept_and_written_unchanged(same_machine):
    stdout, axis = same_machine
    assert _line(stdout, "what to do:") == (
        "what to do:      nothing to fix: the model of saved.json still holds; keep using it as the virtual "
        "machine (agent predict / simulate / ballbar --machine saved.json)")
    written = {k: v for k, v in axis["virtual_model"].items() if k != "identified_range"}
    assert written == SAVED.to_dict()


def test_physics_the_saved_model_lacks_is_named_alone_and_added_to_it(worn_machine):
    stdout, axis = worn_machine
    assert axis["diagnosis"]["verdict"] == "backlash"
    line = _line(stdout, "missing physics:")  # the gap as the fit puts it, not to its last digit
    assert line.startswith("missing physics: backlash, gap ") and line.endswith(" µm")
    assert float(line.split("gap ")[1].split()[0]) == pytest.approx(10.0, rel=0.1)
    assert set(axis["virtual_model"]["effects"]) == {"saturation", "backlash"}
    assert axis["virtual_model"]["effects"]["backlash"]["gap_mm"] == pytest.approx(0.01, rel=0.1)


def test_the_recording_a_model_was_identified_on_is_not_called_held_out(work):
    """A result JSON says which data its model was fitted to (``identified_on_sha256``): checked
    with ``--model`` on those very data, its fit is told as not held out."""
    log = _recording(SAVED, work / "own.csv")
    subprocess.run([*AGENT, "identify", str(log), "--no-diagnose", "--json", str(work / "own.json")],
                   capture_output=True, text=True, timeout=300, check=True)
    proc = subprocess.run([*AGENT, "identify", str(log), "--model", str(work / "own.json"), "--no-diagnose",
                           "--json", str(work / "own_checked.json")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    predicts = _line(proc.stdout, "predicts:")
    assert "the model of own.json was identified on this recording" in predicts and "not held out" in predicts
    assert "held-out fit" not in proc.stdout
    assert json.loads((work / "own_checked.json").read_text())["axes"]["X"]["model_identified_on_this_recording"]


def test_a_new_recording_checked_against_a_saved_model_is_held_out(work, same_machine):
    _, axis = same_machine
    assert axis["model_identified_on_this_recording"] is False

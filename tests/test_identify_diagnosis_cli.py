"""`agent identify` names concealed physics from the command line, and JSON carries the diagnosis (SPEC §6)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from agent import cli

cli._register()
FIX = Path(__file__).resolve().parents[1] / "fixtures" / "diagnosis"


@pytest.mark.slow
# The concealed P-PI backlash is a known miss of the general search (tests/test_diagnosis_concealed.py,
# docs/diagnosis.md): the command line is shown naming a concealed position-periodic error.
@pytest.mark.parametrize("name, verdict", [("cyclic_error", "cyclic_error"), ("clean_ppi", "none")])
def test_identify_diagnoses_concealed_physics_and_leaves_clean_alone(tmp_path, name, verdict):
    out = tmp_path / "r.json"
    res = CliRunner().invoke(cli.app, ["identify", str(FIX / f"{name}.csv"), "--validate",
                                       str(FIX / f"{name}_validation.csv"), "--json", str(out)])
    assert res.exit_code == 0, res.stderr
    diag = json.loads(out.read_text())["axes"]["X"]["diagnosis"]
    assert diag["verdict"] == verdict
    assert {"mismatch", "candidates"} <= set(diag)
    tried = {c["effect"] for c in diag["candidates"]}
    assert tried >= {"backlash", "stribeck", "resonance", "time_delay", "cyclic_error", "saturation"}
    for c in diag["candidates"]:
        assert {"effect", "parameters", "fit_before_pct", "fit_after_pct", "accepted"} <= set(c)
    if verdict == "cyclic_error":
        truth = json.loads((FIX / "cases.json").read_text())[name]["truth"]["period_mm"]
        named = next(c for c in diag["candidates"] if c["effect"] == "cyclic_error" and c["accepted"])
        assert named["parameters"]["period_mm"] == pytest.approx(truth, rel=0.05)
    assert "diagnosis:" in res.stdout

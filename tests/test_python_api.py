"""The Python API of docs/python-api.md: its worked example runs as written, in memory."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest

import ident
from core.errors import InputError, RecordingError

DOC = Path(__file__).resolve().parents[1] / "docs" / "python-api.md"


def _examples() -> list[str]:
    return re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)


def test_the_documented_example_runs_and_writes_no_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for code in _examples():
        exec(compile(code, str(DOC), "exec"), namespace)
    assert os.listdir(tmp_path) == []
    X = namespace["X"]
    assert X.fit_identification.tracking_error_fit_pct > 95
    assert '"axes"' in namespace["doc"] and '"validation"' in namespace["doc"]


def test_from_arrays_defaults_the_period_to_the_time_step_and_checks_shapes():
    t = np.arange(5) * 0.002
    rec = ident.Recording.from_arrays(t=t, commanded={"x": t}, actual={"x": t})
    assert rec.sample_period == pytest.approx(0.002) and rec.axis_names == ["X"]
    assert list(rec.segment) == [0] * 5
    with pytest.raises(RecordingError, match="axis X: commanded"):
        ident.Recording.from_arrays(t=t, commanded={"X": t[:3]}, actual={"X": t})
    with pytest.raises(RecordingError, match="commanded has axes"):
        ident.Recording.from_arrays(t=t, commanded={"X": t}, actual={"Y": t})


def test_identify_names_the_argument_an_error_is_about():
    t = np.arange(2000) * 0.001
    x = 5 * np.sin(10 * t)
    rec = ident.Recording.from_arrays(t=t, commanded={"X": x}, actual={"X": x})
    with pytest.raises(InputError, match="axis Q is not in") as info:
        ident.identify(rec, axes=["Q"])
    assert info.value.parameter == "axes"
    with pytest.raises(InputError, match="solver 'magic'") as info:
        ident.identify(rec, solver="magic")
    assert info.value.parameter == "solver"

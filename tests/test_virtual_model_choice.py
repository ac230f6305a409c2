"""Which model the virtual machine runs: the one that predicts held-out data best."""

from __future__ import annotations

import json

import numpy as np
import pytest

import gcode_gen
import ident
import virtual_cnc


def _rms_error(model, rec) -> float:
    tr = rec.axes["X"]
    x_hat = model.simulate(tr.commanded, segment=rec.segment, x0=tr.actual)
    return float(np.sqrt(np.mean((x_hat - tr.actual) ** 2)))


@pytest.fixture(scope="module")
def cascade():
    """A P-PI cascade in a digital drive (fadal-ppi): eq. 3.3's continuous law is only an
    equivalent of it, the diagnosis's re-fit on a sampled law is the drive's own form."""
    rec = virtual_cnc.simulate(gcode_gen.generate(["X"], seed=5, n_low=40, n_high=15), "fadal-ppi", seed=5)
    val = virtual_cnc.simulate(gcode_gen.generate(["X"], seed=6, n_low=25, n_high=10), "fadal-ppi", seed=6)
    return rec, val, ident.identify(rec, validate=val)


def test_the_virtual_machine_runs_the_refit_where_it_predicts_the_validation_recording_better(cascade):
    rec, val, res = cascade
    r = res.axes["X"]
    assert r.diagnosis.verdict == "none"
    assert r.runs_refit and r.virtual_model.controller != "continuous"
    # checked on the held-out recording itself, not on the diagnosis's figures
    assert _rms_error(r.virtual_model, val) < 0.5 * _rms_error(r.base_model, val)
    saved = json.loads(res.to_json())["axes"]["X"]["virtual_model"]
    assert saved["controller"] == r.virtual_model.controller


def test_without_a_validation_recording_the_identified_model_is_kept(cascade):
    rec, _, _ = cascade
    r = ident.identify(rec).axes["X"]
    assert r.diagnosis.verdict == "none"  # cross-validated figures do not compare with the fit's
    assert not r.runs_refit and r.virtual_model.controller == "continuous"

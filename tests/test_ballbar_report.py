"""The ballbar report names reversal features by their cause in the model and describes its plot."""

from __future__ import annotations

import json
import re

import gcode_gen
import ident
import virtual_cnc
from ident.ballbar_report import render_ballbar_report
from ident.synthetic_ballbar import run_ballbar


def test_a_machine_without_backlash_shows_no_backlash_step_and_its_plot_is_described():
    rec = virtual_cnc.simulate(gcode_gen.generate(["X", "Y"], seed=3), "fadal-ppi", seed=3)
    doc = json.loads(ident.identify(rec, diagnose=False).to_json())
    test = run_ballbar(ident.VirtualMachine.from_result(doc, "identified"), radius=100.0, feed=1000.0 / 60.0)
    assert "without_backlash" not in test.causes["X"]  # the identified model has no backlash
    page = render_ballbar_report([test])
    assert "backlash step" not in page
    steps = [w for w in re.findall(r"<li>([^<]*)</li>", page) if w.startswith("reversal step")]
    assert steps and all(w.endswith("caused by friction, not backlash (the model has none)") for w in steps)
    alts = re.findall(r'<img alt="([^"]*)"', page)
    assert len(alts) == 1 and "polar plot" in alts[0]

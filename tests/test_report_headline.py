"""The summary and the report lead with the answer, and give one held-out figure under one name.

Built on the diagnosis fixtures (fixtures/diagnosis, scripts/make_concealed_recordings.py):
a clean P-ID drive and a P-PI drive with backlash, each with a validation recording.
"""

from __future__ import annotations

import html
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from agent import cli
from ident.headline import HELD_OUT, THESIS, supported_band_hz
from ident.pipeline import identify
from ident.report import render_report

cli._register()
FIX = Path(__file__).resolve().parents[1] / "fixtures" / "diagnosis"


@pytest.fixture(scope="module")
def clean():
    return identify(FIX / "clean_pid.csv", validate=FIX / "clean_pid_validation.csv")


@pytest.fixture(scope="module")
def backlash():
    return identify(FIX / "backlash.csv", validate=FIX / "backlash_validation.csv")


def _text(page: str) -> str:
    """The visible text of a report (tags dropped, entities resolved; images carry only their alt)."""
    return html.unescape(re.sub(r"<[^>]+>", " ", re.sub(r'src="data:[^"]*"', "", page)))


def _held_out_figures(text: str) -> set[str]:
    """Every figure the text names "held-out fit …%"."""
    return set(re.findall(rf"{HELD_OUT}[^%.;()]{{0,60}}?(-?\d+\.\d+) %", text))


def test_a_clean_machine_report_opens_with_the_answer_not_a_mismatch_box(clean):
    page = render_report(clean)
    head = _text(page[:page.index("</div>")])
    x = clean.axes["X"]
    assert "Mismatch" not in head and "Left out" not in head
    assert "Missing physics" in head and "nothing the data can show" in head
    assert f"{HELD_OUT} {x.fit_validation.tracking_error_fit_pct:.2f} %" in head
    assert "What to do" in head and "nothing to fix" in head
    band = supported_band_hz(x)
    assert 10.0 < band < 0.5 / x.sample_period
    assert f"carries information on the response up to {band:.3g} Hz" in head
    # the headline comes before every figure and the diagnosis's own words
    first_img = page.index("<img")
    assert page.index("class='headline'") < first_img < page.index("<h3>Diagnosis</h3>")
    assert html.escape(THESIS) in page


def test_one_held_out_figure_named_the_same_in_report_and_summary(clean):
    x = clean.axes["X"]
    want = f"{x.fit_validation.tracking_error_fit_pct:.2f}"
    assert _held_out_figures(_text(render_report(clean))) == {want}
    # the diagnosis scores a re-fitted reference: its figures carry their own name
    assert x.diagnosis.fit_before_pct != pytest.approx(x.fit_validation.tracking_error_fit_pct, abs=0.005)
    assert f"reference fit {x.diagnosis.fit_before_pct:.2f} %" in x.diagnosis.summary
    assert "held-out tracking-error fit" not in x.diagnosis.summary


def test_the_command_line_summary_leads_with_the_same_answer_and_figure(tmp_path):
    out = tmp_path / "r.json"
    res = CliRunner().invoke(cli.app, ["identify", str(FIX / "clean_pid.csv"), "--validate",
                                       str(FIX / "clean_pid_validation.csv"), "--json", str(out)])
    assert res.exit_code == 0, res.stderr
    import json

    fit = json.loads(out.read_text())["axes"]["X"]["fit"]["validation"]["tracking_error_fit_pct"]
    lines = res.stdout.splitlines()
    first = next(i for i, l in enumerate(lines) if l.startswith("axis X"))
    assert [l.split(":")[0].strip() for l in lines[first + 1:first + 5]] == \
        ["identified", "predicts", "missing physics", "what to do"]
    assert _held_out_figures(res.stdout) == {f"{fit:.2f}"}
    assert lines.index(next(l for l in lines if "diagnosis:" in l)) > first + 4


def test_a_backlash_machine_headline_names_the_gap_and_the_second_figure_says_what_differs(backlash):
    x = backlash.axes["X"]
    page = render_report(backlash)
    head = _text(page[:page.index("</div>")])
    gap = x.diagnosis.augmented_model["effects"]["backlash"]["gap_mm"]
    assert f"backlash, gap {gap * 1e3:.3g} µm" in head
    assert f"backlash compensation to the gap ({gap * 1e3:.3g} µm)" in head
    # two figures: the identified model's held-out fit, and the one with the diagnosed physics, named so
    assert f"{HELD_OUT} {x.fit_validation.tracking_error_fit_pct:.2f} %" in head
    assert f"with the diagnosed physics added (what the virtual machine runs) the {HELD_OUT} is " \
           f"{x.diagnosis.fit_after_pct:.2f} %" in head
    # before/after plots only when an effect was accepted; every image says what it shows
    alts = re.findall(r'<img alt="([^"]*)"', page)
    assert alts and all(len(a) > 30 and a != "figure" for a in alts)
    assert sum("before and after" in a for a in alts) == 2


def test_nothing_accepted_draws_no_before_after_plot_and_localisation_is_a_table_in_um(clean):
    page = render_report(clean)
    assert not any("before and after" in a for a in re.findall(r'<img alt="([^"]*)"', page))
    loc = page[page.index("where the residual concentrates"):]
    assert "rms_mm" not in loc and "<pre>" not in loc
    assert "rms (µm)" in loc and "time since a reversal" in loc


def test_terms_are_explained_in_words(backlash):
    text = _text(render_report(backlash))
    x = backlash.axes["X"]
    assert x.shift == -5
    assert "dead time of 5 ms (preview shift -5 samples" in text
    assert "the frequency-response plot includes it" in text
    fast = [f for f, _ in x.model.poles() if f >= 500.0 * (1 - 1e-3)]
    assert fast, "the fixture's fit puts a pole at or beyond f_max = 500 Hz"
    assert f"A pole at {fast[0]:.4g} Hz" in text and "the upper bound f_max = 500 Hz" in text


def test_against_a_simulated_recording_is_named_in_the_summary_and_the_report(tmp_path, clean):
    """``--against SIM`` leaves a visible trace: the file, its fit to the recording, what was compared."""
    from core.reader import load_recording
    from core.recording import Recording
    from core.writer import write_recording_csv

    rec = load_recording(FIX / "clean_pid.csv")
    x = rec.axes["X"]
    # what `agent simulate --machine result.json` gives for the same program: the identified model's run
    sim_actual = clean.axes["X"].predict(x.commanded, segment=rec.segment, x0=x.actual)
    sim = write_recording_csv(Recording.from_arrays(rec.t, {"X": x.commanded}, {"X": sim_actual},
                                                    segment=rec.segment), tmp_path / "sim.csv")
    report = tmp_path / "r.html"
    res = CliRunner().invoke(cli.app, ["identify", str(FIX / "clean_pid.csv"), "--against", str(sim),
                                       "--report", str(report), "--json", str(tmp_path / "r.json")])
    assert res.exit_code == 0, res.stderr
    line = next(l for l in res.stdout.splitlines() if l.strip().startswith("compared:"))
    assert str(sim) in line and "--against" in line
    head = _text(report.read_text()[:report.read_text().index("</div>")])
    assert f"compared with {sim} (--against)" in head
    import json

    doc = json.loads((tmp_path / "r.json").read_text())
    assert doc["recording"]["against"] == str(sim)
    assert doc["axes"]["X"]["diagnosis"]["mismatch"]["compared_with"] == "simulated recording"

"""The synthetic ballbar on identified drives (issue 15): what the ISO 230-4 test of the
identified machine shows is what the drives' own test shows, and its figures are right."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest
from typer.testing import CliRunner

import gcode_gen
import ident
import virtual_cnc
from agent import cli
from agent.validation import parse_plane
from core.errors import InputError
from ident.synthetic_ballbar import START_DEG, ballbar_of_recording, ballbar_program, run_ballbar

cli._register()

R, V = 100.0, 1000.0 / 60.0  # the QC20's standard bar at 1000 mm/min


def identified_machine(machine, effects=(), diagnose=False) -> ident.VirtualMachine:
    rec = virtual_cnc.simulate(gcode_gen.generate(["X", "Y"], seed=3), machine, effects=effects, seed=3)
    val = virtual_cnc.simulate(gcode_gen.generate(["X", "Y"], seed=4), machine, effects=effects, seed=4)
    doc = json.loads(ident.identify(rec, validate=val, diagnose=diagnose).to_json())
    return ident.VirtualMachine.from_result(doc, "identified")


def drives_own_test(machine, effects=()):
    """The ballbar test run on the virtual CNC itself, read the same way: the truth."""
    recs = [virtual_cnc.simulate([gcode_gen.circle(size=2 * R, feed=V, direction=d, start_deg=START_DEG)],
                                 machine, effects=effects, seed=7) for d in ("ccw", "cw")]
    return ballbar_of_recording(recs, ("X", "Y"), R, V)


@pytest.fixture(scope="module")
def mismatched(tmp_path_factory):
    """fadal-ppi with the Y position gain lowered from 30 to 21 1/s: Y lags X."""
    path = tmp_path_factory.mktemp("m") / "mismatched.toml"
    path.write_text('base = "fadal-ppi"\n[axes.Y]\nKp = 21.0\n')
    return str(path)


def test_mismatched_loops_show_the_ellipse_on_the_right_diagonal_and_the_lag_difference(mismatched):
    test = run_ballbar(identified_machine(mismatched), radius=R, feed=V)
    truth_ms = 1e3 * (1 / 30.0 - 1 / 21.0)  # P-PI without feedforward lags by 1/Kp at low frequency
    assert test.result.servo_mismatch_ms == pytest.approx(truth_ms, rel=0.10)
    assert test.model_servo_mismatch_ms == pytest.approx(truth_ms, rel=0.10)
    own = drives_own_test(mismatched)
    assert test.result.servo_ellipse_deg == own.servo_ellipse_deg == {"ccw": 135, "cw": 45}
    assert any(w.startswith("servo mismatch") and "Y lags X" in w for w in test.words())


def test_the_ballbar_runs_in_every_plane_and_ccw_turns_from_the_first_axis_to_the_second(mismatched):
    vm = identified_machine(mismatched)
    xy = run_ballbar(vm, radius=R, feed=V, axes=("X", "Y"))
    # the same drives as X and Z: the XZ plane (G18 arcs, which turn from Z to X) reads the same
    xz = run_ballbar(replace(vm, axes={"X": vm.axes["X"], "Z": vm.axes["Y"]}), radius=R, feed=V, axes=("X", "Z"))
    assert xz.result.servo_mismatch_ms == pytest.approx(xy.result.servo_mismatch_ms, rel=1e-6)
    assert xz.result.servo_ellipse_deg == xy.result.servo_ellipse_deg == {"ccw": 135, "cw": 45}
    # the axes the other way round: Y is now the first axis, and it lags
    yx = run_ballbar(vm, radius=R, feed=V, axes=("Y", "X"))
    assert yx.result.servo_mismatch_ms == pytest.approx(-xy.result.servo_mismatch_ms, rel=1e-6)
    with pytest.raises(InputError, match="XY, XZ or YZ plane"):
        run_ballbar(replace(vm, axes={"X": vm.axes["X"], "A": vm.axes["Y"]}), radius=R, feed=V, axes=("X", "A"))


def test_a_ballbar_program_outside_the_xy_plane_selects_its_plane_and_gives_its_centre_in_i_j_k():
    text = gcode_gen.write(ballbar_program(10.0, 20.0, (0.0, 0.0), ("X", "Z"), lead_deg=0.0), "linuxcnc")
    arcs = [ln for ln in text.splitlines() if ln.startswith(("G2 ", "G3 ", "G18 "))]
    # ccw from X towards Z is clockwise in G18 (seen from +Y, Z to X counts as ccw)
    assert arcs == ["G18 G2 X7.0711 Z7.0711 I-7.0711 K-7.0711 F1200", "G3 X7.0711 Z7.0711 I-7.0711 K-7.0711"]


@pytest.mark.parametrize("text, plane", [("X,Z", ("X", "Z")), ("xz", ("X", "Z")), ("Y, X", ("Y", "X")),
                                         ("Y2,X", ("Y2", "X"))])
def test_a_plane_is_two_axis_names_or_two_letters(text, plane):
    assert parse_plane(text) == plane


@pytest.mark.slow
def test_backlash_on_one_axis_shows_at_its_reversals_with_the_drives_size():
    effects = ["backlash=gap_mm:0.03,axis:X"]
    vm = identified_machine("fadal-ppi", effects, diagnose=True)
    assert "backlash" in vm.axes["X"].effects and "backlash" not in vm.axes["Y"].effects
    test = run_ballbar(vm, radius=R, feed=V)
    own = drives_own_test("fadal-ppi", effects)
    x, own_x = test.result.axis_reversals[0], own.axis_reversals[0]
    assert x.axis == "X" and x.angles_deg == (0.0, 180.0)
    assert x.spike_um == pytest.approx(own_x.spike_um, rel=0.25)
    assert x.step_um == pytest.approx(own_x.step_um, rel=0.25)
    # the model says the X backlash causes part of what shows at the X reversals
    causes = test.causes["X"]
    assert causes["model"]["step_um"] - causes["without_backlash"]["step_um"] > 0.5


def test_agent_ballbar_prints_the_reading_and_writes_a_self_contained_report(tmp_path, mismatched):
    vm = identified_machine(mismatched)
    result = tmp_path / "result.json"
    doc = {"format": "rapid-ident-result/2", "axes": {a: {"virtual_model": m.to_dict()} for a, m in vm.axes.items()}}
    result.write_text(json.dumps(doc))
    res = CliRunner().invoke(cli.app, ["ballbar", "--machine", str(result), "--report", str(tmp_path / "b.html"),
                                       "--json", str(tmp_path / "b.json")])
    assert res.exit_code == 0, res.output
    assert "servo mismatch" in res.output and "Y lags X" in res.output
    text = (tmp_path / "b.html").read_text()
    assert "data:image/png;base64," in text and "http" not in text.replace("http-equiv", "")
    out = json.loads((tmp_path / "b.json").read_text())
    assert math.isclose(out["tests"][0]["radius_mm"], 100.0)
    bad = CliRunner().invoke(cli.app, ["ballbar", "--machine", str(result), "--axes", "X,Z"])
    assert bad.exit_code == 2 and bad.output.startswith("error:") and len(bad.output.strip().splitlines()) == 1
    for option, value, told in (("--radius", "-5", "error: --radius must be > 0 mm, got -5"),
                                ("--feed", "0", "error: --feed must be > 0 mm/s, got 0")):
        bad = CliRunner().invoke(cli.app, ["ballbar", "--machine", str(result), option, value])
        assert bad.exit_code == 2 and bad.output.strip() == told  # the one option that is wrong, alone
    # a feed whose quarter turns are shorter than a reversal's windows: no baseline is left
    # between the reversals to read the circle from (before, servo mismatch read 0.00 ms)
    bad = CliRunner().invoke(cli.app, ["ballbar", "--machine", str(result), "--radius", "0.5", "--feed", "10"])
    assert bad.exit_code == 2 and bad.output.startswith("error: --feed 10 mm/s on radius 0.5 mm: a quarter turn")
    assert "at most 4.91 mm/s" in bad.output and len(bad.output.strip().splitlines()) == 1


def test_generated_ballbar_programs_recorded_on_the_drives_overlay_the_prediction(tmp_path, mismatched):
    """agent generate writes the test's pair; their recordings read like the prediction."""
    def run(*args):
        res = CliRunner().invoke(cli.app, [str(a) for a in args])
        assert res.exit_code == 0, res.output
        return res.output

    run("generate", "--toolpath", "circle", "--size", 2 * R, "--feed", V, "--direction", "both",
        "--start-angle", 45, "--dialect", "linuxcnc", "-o", tmp_path)
    for d in ("ccw", "cw"):
        run("simulate", tmp_path / f"circle_{d}.ngc", "--machine", mismatched, "-o", tmp_path / f"{d}.mcap")
    vm = identified_machine(mismatched)
    test = run_ballbar(vm, radius=R, feed=V, against=[ident.load(tmp_path / f"{d}.mcap") for d in ("ccw", "cw")])
    assert test.measured is not None
    assert test.measured.servo_mismatch_ms == pytest.approx(test.result.servo_mismatch_ms, rel=0.05)
    for got, want in zip(test.result.runs, test.measured.runs):
        assert got.direction == want.direction
        assert got.circularity_um == pytest.approx(want.circularity_um, rel=0.05)

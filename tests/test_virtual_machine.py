"""The identified drives as a virtual machine (issue 15): any program run on the identified
models predicts the tracking and contour errors the machine itself shows."""

from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import gcode_gen
import ident
import virtual_cnc
from agent import cli
from core.errors import InputError
from ident.contour import path_contour_error
from ident.prediction import analyse, compare

cli._register()


def invoke(*args):
    return CliRunner().invoke(cli.app, [str(a) for a in args])


def identified(machine: str, effects: list[str] = (), diagnose: bool = False, seed: int = 3) -> dict:
    """The result JSON of identifying a two-axis capture of ``machine`` (as agent identify --json writes)."""
    rec = virtual_cnc.simulate(gcode_gen.generate(["X", "Y"], seed=seed), machine, effects=effects, seed=seed)
    val = virtual_cnc.simulate(gcode_gen.generate(["X", "Y"], seed=seed + 1), machine, effects=effects, seed=seed + 1)
    return json.loads(ident.identify(rec, validate=val, diagnose=diagnose).to_json())


@pytest.fixture(scope="module")
def pid_result():
    return identified("fadal-pid")


@pytest.fixture(scope="module")
def pid_machine(pid_result):
    return ident.VirtualMachine.from_result(pid_result, "fadal-pid.json")


def contour_match(vm, toolpath, machine, effects=()):
    """(max ratio, rms of the difference / rms) of predicted vs the virtual CNC's own recording."""
    recorded = virtual_cnc.simulate([toolpath], machine, effects=effects, seed=5)
    c = compare(vm, recorded, vm.run([toolpath]).run)
    return c.max_ratio, c.rms_difference_ratio


# -- the virtual machine is the identified model ------------------------------------------

def test_a_prediction_is_each_axis_model_driven_by_the_interpolated_program(pid_machine):
    pred = pid_machine.run([gcode_gen.circle(size=20, feed=100)])
    rec = pred.recording
    assert rec.metadata["transport"] == "prediction" and "predicted" in rec.metadata["actual_is"]
    for axis, tr in rec.axes.items():
        expected = pid_machine.axes[axis].simulate(tr.commanded, segment=rec.segment)
        np.testing.assert_array_equal(tr.actual, expected)
    # the same interpolator as the built-in virtual CNC: the same command, sample for sample
    cnc = virtual_cnc.simulate([gcode_gen.circle(size=20, feed=100)], "fadal-pid")
    np.testing.assert_array_equal(rec.axes["X"].commanded, cnc.axes["X"].commanded)


@pytest.mark.parametrize("kind", ["circle", "diamond"])
@pytest.mark.parametrize("feed", [50.0, 150.0])
def test_predicted_contour_error_matches_the_drives_own_recording(pid_machine, kind, feed):
    max_ratio, rms_diff = contour_match(pid_machine, gcode_gen.TOOLPATHS[kind](size=20, feed=feed), "fadal-pid")
    assert abs(max_ratio - 1) <= 0.05
    assert rms_diff <= 0.10


@pytest.mark.slow
def test_with_backlash_the_diagnosed_model_predicts_the_contour(tmp_path):
    vm = ident.VirtualMachine.from_result(identified("fadal-pid", ["backlash=0.01"], diagnose=True), "bl.json")
    assert any("backlash" in m.effects for m in vm.axes.values())
    for kind in ("circle", "diamond"):
        for feed in (50.0, 150.0):
            max_ratio, rms_diff = contour_match(vm, gcode_gen.TOOLPATHS[kind](size=20, feed=feed), "fadal-pid",
                                                ["backlash=0.01"])
            assert abs(max_ratio - 1) <= 0.05, (kind, feed)
            assert rms_diff <= 0.10, (kind, feed)


@pytest.mark.parametrize("phase", [0.25, 0.5, 0.75])
def test_the_stand_alone_figure_pairs_samples_at_the_same_point_of_the_path(pid_machine, phase):
    """A controller samples the planned motion at its own clock's phase: the same motion
    recorded ``phase`` of a sample later is paired with the prediction where the command
    stands on the path, not by sample number from each block's start (which reads the
    phase as a contour-error difference: 4–9 % here)."""
    prog = gcode_gen.diamond(size=20, feed=150)
    pred = pid_machine.run([prog])
    rec = pred.recording
    axes = {}
    for a, tr in rec.axes.items():
        cmd = np.interp(rec.t + phase * rec.sample_period, rec.t, tr.commanded)
        axes[a] = ident.AxisTrace(cmd, pid_machine.axes[a].simulate(cmd, segment=rec.segment))
    c = compare(pid_machine, dataclasses.replace(rec, axes=axes), pred.run)
    s = c.standalone
    assert s["paired_samples"] >= 0.98 * np.count_nonzero(c.mask)  # all but a block's edge sample
    assert s["rms_difference_ratio"] <= 0.04


def test_overrides_change_one_parameter_and_the_prediction(pid_machine):
    stiffer = pid_machine.with_overrides(["X.a1=150"])
    assert stiffer.axes["X"].model.a1 == 150 and stiffer.axes["Y"] == pid_machine.axes["Y"]
    prog = [gcode_gen.circle(size=20, feed=100)]
    assert analyse(stiffer.run(prog)).contour_max_mm != pytest.approx(analyse(pid_machine.run(prog)).contour_max_mm)
    with pytest.raises(InputError, match="AXIS.PARAM=VALUE"):
        pid_machine.with_overrides(["a1=3"])
    with pytest.raises(InputError, match="no axis Z"):
        pid_machine.with_overrides(["Z.a1=3"])


def test_worst_places_name_the_program_line_and_feed(pid_machine):
    s = ident.predict([gcode_gen.diamond(size=20, feed=100)], pid_machine)
    lines = {b.line for b in gcode_gen.parse_program(gcode_gen.write(gcode_gen.diamond(size=20, feed=100),
                                                                       "linuxcnc")).blocks if b.motion == "G1"}
    assert s.worst and all(p.line in lines and p.feed_mm_s == 100 for p in s.worst)
    assert s.worst[0].contour_error_mm == pytest.approx(s.contour_max_mm)
    assert [p.contour_error_mm for p in s.worst] == sorted((p.contour_error_mm for p in s.worst), reverse=True)


def test_a_line_with_a_block_number_is_named_by_line_and_n_word(pid_machine, tmp_path):
    # CAM programs number their blocks; a machinist looks a place up by either
    prog = tmp_path / "cam.ngc"
    prog.write_text("%\n(cam)\nN10 G21 G90 G64 P0.01\nN20 G1 X0 Y0 F1200\nN30 G1 X20 Y0\nN40 G1 X20 Y20\n"
                    "G1 X0 Y20\nN60 M2\n%\n")
    s = ident.predict([prog], pid_machine)
    numbers = {5: 30, 6: 40, 7: None}  # line -> N word (line 7 has none)
    assert s.worst and all(p.n == numbers[p.line] for p in s.worst)
    named = [p for p in s.worst if p.n is not None][0]
    assert named.where == f"cam.ngc line {named.line} (N{named.n})"
    assert named.to_dict()["block_number"] == named.n
    assert {e.n for e in s.tracking.values()} <= {30, 40, None}


# -- contour error: the normal distance to lines and arcs ------------------------------------

def test_contour_error_of_a_circle_is_its_radial_deviation_not_the_chord():
    th = np.linspace(0, 2 * np.pi, 200)  # coarse: the chord sags 0.012 mm at r = 10
    P = np.column_stack([10 * np.cos(th), 10 * np.sin(th)])
    Q = np.column_stack([10.003 * np.cos(th + 0.01), 10.003 * np.sin(th + 0.01)])
    arcs = [(np.zeros(2), 10.0, 1.0)]
    e = path_contour_error(P, Q, arcs=arcs, arc_of_vertex=np.zeros(th.size, dtype=int), t=th)
    np.testing.assert_allclose(e, -0.003, atol=1e-9)  # outside a ccw circle: right of travel


def test_an_arc_outside_the_xy_plane_counts_as_the_path_it_draws(pid_result, tmp_path):
    # LinuxCNC's tort.ngc programs X, Y and Z on G18/G19 arcs, whose centre is in X–Z or Y–Z
    doc = json.loads(json.dumps(pid_result))
    doc["axes"]["Z"] = doc["axes"]["Y"]
    vm = ident.VirtualMachine.from_result(doc, "xyz.json")
    prog = tmp_path / "planes.ngc"
    prog.write_text("G21 G90 G17\nG1 X0 Y0 Z0 F600\nG18 G2 X10 Y0 Z0 I5 K0\nG19 G3 X10 Y10 Z0 J5 K0\n"
                    "G17 G3 X0 Y10 I-5 J0\nM2\n")
    s = analyse(vm.run([prog]))
    assert np.isfinite(s.contour[s.feed_move]).all()
    # the contour error is the distance to the path: never more than the tracking error's length
    err = np.sqrt(sum(s.prediction.recording.axes[a].tracking_error ** 2 for a in "XYZ"))
    assert s.contour_max_mm <= err[s.feed_move].max() + 1e-9


def test_an_arc_line_run_in_a_loop_is_measured_against_each_run_of_it(pid_result, tmp_path):
    """One program line that runs as three circles about three centres (an o-word loop, as
    LinuxCNC's useful-subroutines.ngc cuts its slots): every circle's contour error is its own,
    not the distance to the last circle the line drew (40 mm here before)."""
    vm = ident.VirtualMachine.from_result(pid_result, "pid.json")
    prog = tmp_path / "loop.ngc"
    prog.write_text("G21 G90 G17 G61.1\nG0 X0 Y0\n#1 = 0\no100 while [#1 LT 3]\nG1 X[#1 * 20] Y0 F3000\n"
                    "G3 X[#1 * 20] Y0 I5 J0\n#1 = [#1 + 1]\no100 endwhile\nM2\n")
    s = analyse(vm.run([prog]))
    err = np.sqrt(sum(s.prediction.recording.axes[a].tracking_error ** 2 for a in "XY"))
    assert 0 < s.contour_max_mm <= err[s.feed_move].max() + 1e-9


def test_a_recording_of_a_loop_is_labelled_in_the_order_its_blocks_ran(pid_result, tmp_path):
    """--against walks the program's blocks as they ran (a loop's once per pass), not by line:
    the machine's own run, compared with itself, has its cycle time and every feed sample
    paired (by line, the walk ended after the first pass: 1.08 s of 3.015 s)."""
    vm = ident.VirtualMachine.from_result(pid_result, "pid.json")
    prog = tmp_path / "loop.ngc"
    prog.write_text("G21 G90 G17 G61.1\nG0 X0 Y0\n#1 = 0\no100 while [#1 LT 3]\nG1 X[#1 * 20] Y0 F3000\n"
                    "G3 X[#1 * 20] Y0 I5 J0\nG4 P0.1\n#1 = [#1 + 1]\no100 endwhile\nM2\n")
    pred = vm.run([prog])
    c = compare(vm, pred.recording, pred.run)
    assert c.measured_cycle_s == pytest.approx(c.predicted_cycle_s)
    assert c.standalone["paired_samples"] == np.count_nonzero(c.mask)
    assert c.standalone["rms_difference_ratio"] == pytest.approx(0.0, abs=1e-12)


def test_contour_error_near_the_end_of_a_closed_path_is_measured_on_its_last_side():
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], dtype=float)
    P = np.concatenate([np.linspace(sq[i], sq[i + 1], 101)[:-1] for i in range(4)] + [sq[-1:]])
    Q = P + np.array([0.002, 0.0])  # +x is left of the last side (x = 0, travelled towards −y)
    e = path_contour_error(P, Q, t=np.arange(len(P)) * 0.001)
    assert e[-3] == pytest.approx(0.002, abs=1e-12)


# -- the CLI --------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def files(tmp_path_factory, pid_result):
    d = tmp_path_factory.mktemp("vm")
    (d / "result.json").write_text(json.dumps(pid_result))
    (d / "circle.ngc").write_text(gcode_gen.write(gcode_gen.circle(size=20, feed=100), "linuxcnc"))
    return d


def test_simulate_runs_a_program_on_the_identified_machine(files, tmp_path):
    res = invoke("simulate", files / "circle.ngc", "--machine", files / "result.json", "-o", tmp_path / "p.mcap")
    assert res.exit_code == 0, res.output
    rec = ident.load(tmp_path / "p.mcap")
    assert set(rec.axes) == {"X", "Y"} and rec.metadata["transport"] == "prediction"


def test_predict_compares_two_tunings_in_one_self_contained_report(files, tmp_path):
    report, out = tmp_path / "p.html", tmp_path / "p.json"
    res = invoke("predict", files / "circle.ngc", "--machine", files / "result.json", "--set", "X.a1=150",
                 "--report", report, "--json", out)
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    assert [m["machine"] for m in doc["machines"]] == ["result.json", "result.json with X.a1=150"]
    assert doc["machines"][0]["contour_error"]["worst_places"][0]["line"] > 0
    text = report.read_text()
    assert "with X.a1=150" in text and "data:image/png;base64," in text
    assert "http://" not in text and "https://" not in text and "<script" not in text


def test_predict_overlays_a_recording_of_the_same_motion(files, tmp_path):
    cnc = tmp_path / "circle.mcap"
    assert invoke("simulate", files / "circle.ngc", "--machine", "fadal-pid", "-o", cnc).exit_code == 0
    res = invoke("predict", files / "circle.ngc", "--machine", files / "result.json", "--against", cnc)
    assert res.exit_code == 0, res.output
    assert "against circle.mcap" in res.output


@pytest.mark.parametrize("mangle, message", [
    (lambda d: {k: v for k, v in d.items() if k != "format"}, "older rapid-ident"),
    (lambda d: {**d, "axes": {"X": d["axes"]["X"]}}, "moves axis Y"),
    (lambda d: {**d, "virtual_machine": {"max_feed_mm_s": 50}}, "above result.json's maximum feed 50"),
    (lambda d: {**d, "virtual_machine": {"travel_mm": {"X": [-5, 5]}}}, "outside result.json's travel"),
])
def test_bad_machine_or_program_is_a_one_line_error(files, tmp_path, pid_result, mangle, message):
    bad = tmp_path / "result.json"
    bad.write_text(json.dumps(mangle(pid_result)))
    res = invoke("predict", files / "circle.ngc", "--machine", bad)
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and message in lines[0], res.output


def test_effects_cannot_be_added_to_an_identified_machine(files, tmp_path):
    res = invoke("simulate", files / "circle.ngc", "--machine", files / "result.json", "--effect", "backlash=0.01",
                 "-o", tmp_path / "x.mcap")
    assert res.exit_code == 2 and "--effect" in res.output


def test_the_documented_example_runs(tmp_path, monkeypatch):
    import re
    from pathlib import Path

    doc = Path(__file__).resolve().parents[1] / "docs" / "virtual-machine.md"
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for code in re.findall(r"```python\n(.*?)```", doc.read_text(), flags=re.S):
        exec(compile(code, str(doc), "exec"), namespace)
    assert abs(namespace["c"].max_ratio - 1) < 0.05
    assert namespace["test"].result.runs and namespace["summary"].worst


@pytest.mark.slow
@pytest.mark.skipif(not (shutil.which("chromium") or shutil.which("chromium-browser")),
                    reason="headless Chromium not installed (apt-get install chromium)")
def test_the_report_renders_in_a_headless_browser(files, tmp_path):
    report, shot = tmp_path / "p.html", tmp_path / "p.png"
    assert invoke("predict", files / "circle.ngc", "--machine", files / "result.json", "--report", report).exit_code == 0
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run(["bash", str(root / "scripts" / "screenshot.sh"), str(report), str(shot)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    from matplotlib.image import imread

    img = imread(shot)
    assert img.shape[0] > 1000 and img.shape[1] > 1000
    # the figures are there: far more than a blank page's one colour
    assert len(np.unique((img[..., :3] * 255).astype(np.uint8).reshape(-1, 3), axis=0)) > 50

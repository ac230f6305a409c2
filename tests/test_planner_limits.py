"""Planning like LinuxCNC (issue 41): per-axis velocity and acceleration limits, read from the
controller's INI, and the prediction saying which planner it used."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import gcode_gen
from agent import cli
from core.errors import InputError
from gcode_gen.interpolator import interpolate
from gcode_gen.interpreter import parse_program
from gcode_gen.planner_limits import PlannerLimits, read_linuxcnc_ini

cli._register()
ROOT = Path(__file__).resolve().parent.parent
LIMITS = {"X": (200.0, 2000.0), "Y": (200.0, 2000.0)}


def _program(text: str):
    return parse_program("G21 G90 G17 G94\nG61.1\n" + text + "\nM2\n", name="t.ngc")


def _path_acceleration(tr) -> np.ndarray:
    P = np.column_stack([tr.axes["X"], tr.axes["Y"]])
    return np.linalg.norm(np.diff(P, 2, axis=0), axis=1) / tr.Ts ** 2


def test_a_45_degree_line_accelerates_at_each_axis_limit_not_the_path_limit():
    """2000 mm/s² per axis is 2828 mm/s² along a 45° line (each axis at its limit)."""
    prog = _program("G0 X0 Y0\nG1 X20 Y20 F6000")
    per_axis = interpolate(prog, axis_limits=LIMITS, rapid_feed=200.0)
    path = interpolate(prog, a_max=2000.0)
    assert _path_acceleration(per_axis).max() == pytest.approx(2000 * math.sqrt(2), rel=0.02)
    assert _path_acceleration(path).max() == pytest.approx(2000, rel=0.02)
    for ax in "XY":
        a = np.abs(np.diff(per_axis.axes[ax], 2)) / per_axis.Ts ** 2
        assert a.max() <= 2000 * 1.001
    assert per_axis.duration < path.duration


def test_an_axis_limit_caps_the_speed_of_the_line_it_moves_along():
    prog = _program("G0 X0 Y0\nG1 X100 Y10 F6000")  # X carries almost all the motion
    tr = interpolate(prog, axis_limits={"X": (50.0, 2000.0), "Y": (200.0, 2000.0)}, rapid_feed=200.0)
    vx = np.abs(np.diff(tr.axes["X"])) / tr.Ts
    assert vx.max() == pytest.approx(50.0, rel=1e-3)


def test_an_arc_has_half_the_acceleration_along_it_when_its_speed_limit_is_cut():
    """LinuxCNC sets an arc's tangential acceleration for the arc's speed limit (here 200 mm/s,
    whose v²/r exceeds 0.866·a on r = 10 mm), not for the feed: a/2 = 1000 mm/s²."""
    prog = _program("G0 X10 Y0\nG3 X10 Y0 I-10 J0 F6000")
    tr = interpolate(prog, axis_limits=LIMITS, rapid_feed=200.0)
    arc = tr.block == max(tr.block)
    P = np.column_stack([tr.axes["X"], tr.axes["Y"]])[arc]
    v = np.linalg.norm(np.diff(P, axis=0), axis=1) / tr.Ts
    ramp = v[:40]
    assert np.diff(ramp).max() / tr.Ts == pytest.approx(1000.0, rel=0.05)
    assert v.max() == pytest.approx(100.0, rel=1e-3)


def test_the_test_machines_ini_gives_its_axis_limits():
    lim = read_linuxcnc_ini(ROOT / "fixtures/linuxcnc/machine.ini")
    assert lim.axes == {"X": (200.0, 2000.0)}  # the one-axis machine: [TRAJ] COORDINATES = X
    assert lim.max_linear_velocity == 200.0
    assert "machine.ini" in lim.describe() and "2000 mm/s²" in lim.describe()


def test_a_rotary_axis_limits_are_told_in_degrees():
    lim = PlannerLimits({"X": (100.0, 1000.0), "A": (360.0, 3600.0)}, None, "m.ini")
    assert lim.describe().endswith("X 100 mm/s 1000 mm/s², A 360 deg/s 3600 deg/s²")


def test_an_ini_without_limits_is_one_line(tmp_path):
    ini = tmp_path / "bad.ini"
    ini.write_text("[TRAJ]\nCOORDINATES = X Y\n[AXIS_X]\nMAX_VELOCITY = 100\nMAX_ACCELERATION = 500\n")
    with pytest.raises(InputError, match="axis Y has no MAX_VELOCITY/MAX_ACCELERATION"):
        read_linuxcnc_ini(ini)
    with pytest.raises(InputError, match="no such INI file"):
        read_linuxcnc_ini(tmp_path / "missing.ini")


def test_an_inch_machines_limits_are_read_in_mm(tmp_path):
    # LinuxCNC's own sim/axis/axis.ini is an inch machine: MAX_VELOCITY = 4 is 4 in/s
    ini = tmp_path / "inch.ini"
    ini.write_text("[TRAJ]\nCOORDINATES = X Y\nLINEAR_UNITS = inch\nMAX_LINEAR_VELOCITY = 5\n"
                   "[AXIS_X]\nMAX_VELOCITY = 4\nMAX_ACCELERATION = 100\n"
                   "[AXIS_Y]\nMAX_VELOCITY = 4\nMAX_ACCELERATION = 50\n")
    lim = read_linuxcnc_ini(ini)
    assert lim.axes == {"X": (pytest.approx(101.6), pytest.approx(2540.0)),
                        "Y": (pytest.approx(101.6), pytest.approx(1270.0))}
    assert lim.max_linear_velocity == pytest.approx(127.0)
    ini.write_text(ini.read_text().replace("LINEAR_UNITS = inch", "LINEAR_UNITS = furlong"))
    with pytest.raises(InputError, match="LINEAR_UNITS = .furlong.: LinuxCNC knows mm, metric, in, inch, imperial or a number"):
        read_linuxcnc_ini(ini)


def test_an_ini_is_read_as_linuxcnc_reads_it_includes_indented_keys_and_the_first_of_two(tmp_path):
    # LinuxCNC's sample configs indent keys to align them, and pull sections in with #INCLUDE
    (tmp_path / "axes.inc").write_text("[AXIS_X]\n    MAX_VELOCITY =  20\nMAX_ACCELERATION =  300\n"
                                       "MAX_VELOCITY = 99\n")
    ini = tmp_path / "m.ini"
    # (a missing include is skipped, as LinuxCNC's start script skips it after saying so)
    ini.write_text("#INCLUDE axes.inc\n#INCLUDE nosuchfile\n[TRAJ]\n  COORDINATES = X\n# a comment\n; another\n")
    lim = read_linuxcnc_ini(ini)
    assert lim.axes == {"X": (20.0, 300.0)} and lim.max_linear_velocity is None


@pytest.fixture(scope="module")
def result_json(tmp_path_factory):
    import ident
    import virtual_cnc

    rec = virtual_cnc.simulate(gcode_gen.generate(["X", "Y"], seed=3, n_low=60, n_high=20), "fadal-pid", seed=3)
    path = tmp_path_factory.mktemp("m") / "result.json"
    path.write_text(ident.identify(rec, diagnose=False).to_json())
    return path


def _xy_ini(tmp_path: Path) -> Path:
    """The test machine's INI with X and Y, as fixtures/linuxcnc/machine.py writes it for ``--axes XY``."""
    text = (ROOT / "fixtures/linuxcnc/machine.ini").read_text()
    for old, new in (("COORDINATES = X\n", "COORDINATES = X Y\n"), ("JOINTS = 1\n", "JOINTS = 2\n"),
                     ("coordinates=X\n", "coordinates=XY\n")):
        assert old in text
        text = text.replace(old, new)
    ini = tmp_path / "machine.ini"
    ini.write_text(text)
    return ini


def test_predict_says_which_planner_and_limits_it_used_and_the_cycle_time(result_json, tmp_path):
    prog = tmp_path / "diamond.ngc"
    prog.write_text(gcode_gen.write(gcode_gen.diamond(size=20, feed=100), "linuxcnc"))
    out = tmp_path / "p.json"
    res = CliRunner().invoke(cli.app, ["predict", str(prog), "--machine", str(result_json), "--ini",
                                       str(_xy_ini(tmp_path)), "--json", str(out)])
    assert res.exit_code == 0, res.output
    assert ("planner: LinuxCNC planner, per-axis limits from machine.ini: X 200 mm/s 2000 mm/s², "
            "Y 200 mm/s 2000 mm/s²") in res.output
    doc = json.loads(out.read_text())["machines"][0]
    assert doc["planner"]["kind"] == "per-axis" and doc["planner"]["source"] == "machine.ini"
    assert doc["cycle_time_s"] > 0.2
    plain = CliRunner().invoke(cli.app, ["predict", str(prog), "--machine", str(result_json)])
    assert "planner: path-limited planner (2000 mm/s² along the path" in plain.output


def test_a_bad_ini_is_a_one_line_error_with_exit_2(result_json, tmp_path):
    prog = tmp_path / "c.ngc"
    prog.write_text(gcode_gen.write(gcode_gen.circle(size=20, feed=100), "linuxcnc"))
    res = CliRunner().invoke(cli.app, ["predict", str(prog), "--machine", str(result_json), "--ini",
                                       str(tmp_path / "nope.ini")])
    assert res.exit_code == 2
    assert "no such INI file" in res.output and "Traceback" not in res.output


def test_blending_the_planner_does_not_model_is_predicted_as_exact_stop_with_a_warning(result_json, tmp_path):
    prog = tmp_path / "blend.ngc"
    ini = ["--ini", str(_xy_ini(tmp_path))]
    prog.write_text("G21 G90 G17 G94\nG64 P0.01 (blend)\nG0 X0 Y0\nG1 X10 Y0 F3000\nG1 X10 Y10\nM2\n")
    res = CliRunner().invoke(cli.app, ["predict", str(prog), "--machine", str(result_json)])
    assert res.exit_code == 0, res.output
    assert "warning: blend.ngc: G64 path blending (modelled with --ini's per-axis planner) is not modelled" in res.output
    assert "G64" not in CliRunner().invoke(cli.app, ["predict", str(prog), "--machine", str(result_json), *ini]).output
    prog.write_text("G21 G90 G17 G94\nG64 (no tolerance)\nG0 X0 Y0\nG1 X10 Y0 F3000\nG1 X10 Y10\nM2\n")
    res = CliRunner().invoke(cli.app, ["predict", str(prog), "--machine", str(result_json), *ini])
    assert "warning: blend.ngc: G64 without P is not modelled" in res.output
    prog.write_text("G21 G90 G17 G94\nG64 P0.01\nG0 X0 Y0\nG1 X10 Y0 F3000\nG3 X10 Y10 I0 J5\nM2\n")
    res = CliRunner().invoke(cli.app, ["predict", str(prog), "--machine", str(result_json), *ini])
    assert "warning: blend.ngc: blending into or out of an arc under G64 is not modelled" in res.output
    prog.write_text("G21 G90 G17 G94\nG61.1 (not G64)\nG0 X0 Y0\nG1 X10 Y0 F3000\nG1 X10 Y10\nM2\n")
    res = CliRunner().invoke(cli.app, ["predict", str(prog), "--machine", str(result_json)])
    assert "G64" not in res.output


@pytest.mark.parametrize("P", [0.01, 0.1])
def test_g64_p_blends_a_corner_with_an_arc_through_the_tolerance(P):
    """LinuxCNC's tangent-arc blend at a 90° corner: the path passes P from the corner, on an
    arc of R = P·sin45°/(1 − sin45°) run at sqrt(0.866·a·R), the lines at their per-axis limits."""
    prog = parse_program(f"G21 G90 G17 G94\nG64 P{P}\nG0 X10 Y0\nG1 X0 Y10 F6000\nG1 X-10 Y0\nG1 X0 Y-10\nM2\n",
                         name="d.ngc")
    tr = interpolate(prog, axis_limits=LIMITS, rapid_feed=200.0, start={"X": 10.0, "Y": 0.0})
    x, y = tr.axes["X"], tr.axes["Y"]
    d = np.hypot(x - 0.0, y - 10.0)
    k = int(np.argmin(d))
    assert P - 1e-6 <= d[k] <= 1.1 * P  # the nearest sample, within half a period of the arc's middle
    R = P * math.sin(math.pi / 4) / (1 - math.sin(math.pi / 4))
    v = np.hypot(np.diff(x), np.diff(y)) / tr.Ts
    assert v[k] == pytest.approx(math.sqrt(0.866 * 2000.0 * R), rel=0.03)
    assert v.max() == pytest.approx(100.0, rel=5e-3)
    assert (x[-1], y[-1]) == (0.0, -10.0)
    # the last line ends without a blend: LinuxCNC runs it at half its acceleration (2828/2)
    acc = np.diff(v[-60:]) / tr.Ts
    assert acc.min() == pytest.approx(-1414.0, rel=0.03)


def test_a_program_moving_an_axis_the_ini_does_not_have_is_refused_naming_it(result_json, tmp_path):
    """LinuxCNC configured by an INI without Y does not move Y: neither does its planner here
    (an axis without limits would be planned at infinite acceleration)."""
    prog = tmp_path / "y.ngc"
    prog.write_text("G21 G90 G17 G94\nG0 X0 Y0\nG1 X10 F3000\nG1 Y10\nM2\n")
    res = CliRunner().invoke(cli.app, ["predict", str(prog), "--machine", str(result_json), "--ini",
                                       str(ROOT / "fixtures/linuxcnc/machine.ini")])
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert lines == ["error: y.ngc: line 4: moves axis Y, for which the per-axis limits give no velocity and "
                     "acceleration (limits for X)"], res.output


def test_under_the_ini_a_feed_above_the_limits_is_lowered_to_them_as_linuxcnc_does(result_json, tmp_path):
    """A sample program's F1000000 runs at the path speed cap ([TRAJ] MAX_LINEAR_VELOCITY)."""
    prog = tmp_path / "fast.ngc"
    prog.write_text("G21 G90 G17 G94\nG0 X0 Y0\nG1 X20 F1000000\nM2\n")
    out = tmp_path / "p.json"
    res = CliRunner().invoke(cli.app, ["predict", str(prog), "--machine", str(result_json), "--ini",
                                       str(_xy_ini(tmp_path)), "--json", str(out)])
    assert res.exit_code == 0, res.output
    plain = CliRunner().invoke(cli.app, ["predict", str(prog), "--machine", str(result_json)])
    assert plain.exit_code == 2 and "above result.json's maximum feed 200 mm/s" in plain.output


def test_a_blended_corner_within_rounding_of_straight_is_planned():
    """Two G1 lines under G64 P whose directions differ by 1.5e-8 rad, as a sample program's
    3-decimal coordinates give them (LinuxCNC's 3D_Chips.ngc): the sine of half the corner's
    interior angle rounds to 1, and the blend's radius is still planned, not a division by zero."""
    prog = parse_program("G21 G90 G17 G94\nG64 P0.1\nG0 X20.696 Y-3.724 Z17.861\nG1 X-25.968 Y-8.569 Z-20.918 F6000\n"
                         "G1 X-33.336 Y-9.334 Z-27.041\nM2\n", name="s.ngc")
    tr = interpolate(prog, axis_limits={**LIMITS, "Z": (200.0, 2000.0)}, rapid_feed=200.0,
                     start={"X": 20.696, "Y": -3.724, "Z": 17.861})
    assert all(np.isfinite(x).all() for x in tr.axes.values())
    assert (tr.axes["X"][-1], tr.axes["Y"][-1], tr.axes["Z"][-1]) == pytest.approx((-33.336, -9.334, -27.041))

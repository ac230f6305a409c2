"""The RS274/NGC interpreter (gcode_gen.ngc): the language, offsets, cycles, and agreement
with LinuxCNC's own interpreter ``rs274``.

The language tests need nothing installed: small programs with end points worked out by
hand.  The agreement tests run ``rs274`` on LinuxCNC's sample programs and on programs
written here, and are skipped when it is not installed.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from core.errors import ProgramError
from gcode_gen.interpreter import parse_program
from gcode_gen.ngc import interpret, parse_tool_table, read_tool_table
from gcode_gen.ngc.rs274_canon import RS274, compare, parse_canon, run_rs274

ROOT = Path(__file__).resolve().parents[1]
TOOLS_IN = ROOT / "fixtures" / "rs274" / "tools.tbl"
NCFILES = Path("/usr/share/linuxcnc/ncfiles")
needs_rs274 = pytest.mark.skipif(RS274 is None, reason="LinuxCNC rs274 interpreter not installed (linuxcnc-uspace)")


def _ends(text: str, **kw) -> list[dict[str, float]]:
    """Machine position after every block (all axes that moved so far)."""
    blocks, _ = interpret(text, **kw)
    pos: dict[str, float] = {}
    out = []
    for b in blocks:
        pos = {**pos, **b.target}
        out.append({a: round(v, 9) for a, v in pos.items()})
    return out


# ---- language ---------------------------------------------------------------------------

def test_numbered_and_named_parameters_and_expressions():
    text = """G21
#100 = 10.0
#<xscale> = 2
#<_glob> = [#100 / 4]
G1 X[#100 * #<xscale>] Y#<_glob> F[60 * 10]
G1 X[2 ** 3] Y[7 MOD 3] Z[-#100 + 1]
G1 X[SQRT[16] + ABS[-1] + FIX[2.7] + FUP[2.1] + ROUND[2.5]] Y[ATAN[1]/[1]] Z[SIN[30] * 10]
G1 X[EXP[0] + LN[1] + COS[60]] Y[1 + 2 * 3 - 4 / 2] Z[[1 LT 2] + [2 EQ 2] + [1 GT 2 OR 1] + [1 AND 0]]
M2
"""
    ends = _ends(text)
    assert ends[0]["X"] == 20.0 and ends[0]["Y"] == 2.5
    assert (ends[1]["X"], ends[1]["Y"], ends[1]["Z"]) == (8.0, 1.0, -9.0)
    assert ends[2]["X"] == pytest.approx(4 + 1 + 2 + 3 + 3) and ends[2]["Y"] == pytest.approx(45.0)
    assert ends[2]["Z"] == pytest.approx(5.0)
    assert (ends[3]["X"], ends[3]["Y"], ends[3]["Z"]) == (pytest.approx(1.5), 5.0, 3.0)
    blocks, _ = interpret(text)
    assert blocks[0].feed == pytest.approx(10.0)  # F600 mm/min


def test_parameters_set_on_a_line_take_effect_on_the_next():
    ends = _ends("#1=5\n#1=7 #2=#1\nG0 X#2 Y#1\nM2\n")
    assert ends == [{"X": 5.0, "Y": 7.0}]


def test_subroutine_arguments_locals_and_return_value():
    text = """G21
o<square> sub
  #<half> = [#1 / 2]
  G1 X#<half> F100
  G1 Y[#<half> + #2]
  o<square> return [#1 * 3]
  G1 X999
o<square> endsub
o<square> call [4] [1]
G0 X#<_value>
#1 = 9
o<square> call [10]
G0 Y#1
M2
"""
    ends = _ends(text)
    assert [e["X"] for e in ends] == [2.0, 2.0, 12.0, 5.0, 5.0, 5.0]
    assert [e["Y"] for e in ends if "Y" in e][-1] == 9.0  # #1 restored after the call
    with pytest.raises(ProgramError, match=r"^p:4: named parameter #<half> is not defined"):
        interpret("o1 sub\n#<half>=1\no1 endsub\nG0 X#<half>\n", name="p")


def test_loops_and_conditionals():
    text = """G21 G91 F600
#1 = 0
o10 while [#1 LT 3]
  G1 X1
  #1 = [#1 + 1]
o10 endwhile
o20 repeat [2]
  G1 Y1
o20 endrepeat
o30 do
  G1 Z-1
  #1 = [#1 - 1]
o30 while [#1 GT 1]
#2 = 0
o40 while [1]
  #2 = [#2 + 1]
  o41 if [#2 EQ 2]
    o40 continue
  o41 elseif [#2 GT 3]
    o40 break
  o41 else
    G1 X10
  o41 endif
o40 endwhile
M2
"""
    ends = _ends(text)
    assert ends[2]["X"] == 3.0 and ends[4]["Y"] == 2.0 and ends[6]["Z"] == -2.0
    assert [e["X"] for e in ends[7:]] == [13.0, 23.0]  # #2 = 1 and 3 move, 2 continues, 4 breaks
    assert len(ends) == 9


def test_comments_messages_percent_and_block_delete():
    text = "%\n(MSG, hello)\n(DEBUG, #1)\n/G0 X1 ; comment\nG0 Y2 (two) (comments)\n%\nG0 X99\n"
    assert _ends(text) == [{"X": 1.0}, {"X": 1.0, "Y": 2.0}]


def test_modal_moves_after_a_linear_move_and_arcs_from_the_known_position():
    ends = _ends("G21\nG1 X10 F100\nG2 X20 Y0 I5 J0\nM2\n")
    assert ends[-1] == {"X": 20.0, "Y": 0.0}
    blocks, _ = interpret("G21\nG1 X10 F100\nG2 X20 Y0 I5 J0\nM2\n")
    assert blocks[1].center == {"X": 15.0, "Y": 0.0}


def test_arcs_in_the_three_planes_helix_and_turns():
    text = """G21 F60
G18 G2 X10 Z10 I5 K5
G19 G3 Y10 Z0 J5 K-5 X3
G17 G3 X-2 Y15 I-5 J0 Z1 P3
M2
"""
    blocks, _ = interpret(text)
    assert [b.plane for b in blocks] == ["XZ", "YZ", "XY"]
    assert blocks[0].center == {"Z": 5.0, "X": 5.0}
    assert blocks[1].center == {"Y": 5.0, "Z": 5.0} and blocks[1].target["X"] == 3.0
    assert blocks[2].turns == 3 and blocks[2].target["Z"] == 1.0


def test_units_work_offsets_g92_and_g53():
    text = """G20
G10 L2 P2 X1 Y2
G55 G0 X1 Y1
G92 X0 Y0
G0 X1
G53 G0 X0 Y0
G92.1
G10 L20 P1 X0
G54 G0 X1
M2
"""
    ends = _ends(text)
    assert ends[0] == {"X": pytest.approx(2 * 25.4), "Y": pytest.approx(3 * 25.4)}
    assert ends[1]["X"] == pytest.approx(3 * 25.4)  # G92 made (2, 3) in the G55 system the origin
    assert ends[2] == {"X": 0.0, "Y": 0.0}
    assert ends[3]["X"] == pytest.approx(25.4)  # G10 L20 at X0 machine: G54 X offset 0


def test_tool_change_and_tool_length_offset_from_a_table():
    tools = parse_tool_table("T1 P1 Z10 D6\nT2 P2 Z25.5 ;long\n")
    ends = _ends("G21\nT2 M6\nG43\nG0 Z5\nG43 H1\nG0 X1\nG49\nG0 Z0\nM2\n", tools=tools)
    assert ends[0]["Z"] == 30.5 and ends[1] == {"Z": 30.5, "X": 1.0} and ends[2]["Z"] == 0.0
    with pytest.raises(ProgramError, match="no tool table was given"):
        interpret("G21\nT1 M6\nG43\nG0 Z1\n")
    with pytest.raises(ProgramError, match="tool 3 is not in the tool table"):
        interpret("G21\nG43 H3\n", tools=tools)


def test_g28_g30_and_stored_positions():
    ends = _ends("G21\nG0 X5 Y5 Z5\nG28.1\nG0 X9\nG91 G28 Z1\nG90\n#5181=2 #5182=3\nG30\nM2\n")
    assert ends[2] == {"X": 9.0, "Y": 5.0, "Z": 6.0}  # intermediate point Z+1
    assert ends[3] == {"X": 9.0, "Y": 5.0, "Z": 5.0}  # G28 moves only the named axis home
    assert ends[4]["X"] == 2.0 and ends[4]["Y"] == 3.0 and ends[4]["Z"] == 0.0


def test_canned_cycles_g81_g98_g99_and_repeats():
    blocks, _ = interpret("G21 G0 X0 Y0 Z10\nG99 G81 X5 R2 Z-3 F60\nG91 G98 X5 L2\nG80\nM2\n")
    path = [(b.motion, b.target.get("X"), b.target.get("Z")) for b in blocks[1:]]
    assert path[:4] == [("G0", 5.0, 10.0), ("G0", None, 2.0), ("G1", None, -3.0), ("G0", None, 2.0)]
    # same series: G91 R is relative to the series' initial level Z10 (R12), Z-3 from R (9)
    assert path[4:] == [("G0", None, 12.0), ("G0", 10.0, 12.0), ("G1", None, 9.0), ("G0", None, 12.0),
                        ("G0", 15.0, 12.0), ("G1", None, 9.0), ("G0", None, 12.0)]


def test_peck_drilling_g83_retracts_to_r_and_backs_off_0_254_mm():
    blocks, _ = interpret("G21 G0 Z5\nG83 R1 Z-2 Q1 F60\nM2\n")
    zs = [b.target["Z"] for b in blocks[1:]]  # G99 (the start state): back to R at the end
    assert zs == pytest.approx([5.0, 1.0, 0.0, 1.0, 0.254, -1.0, 1.0, -0.746, -2.0, 1.0])


def test_polar_coordinates():
    ends = _ends("G21 G0 @10 ^90\nG91 G0 ^90\nM2\n")
    assert ends[0]["X"] == pytest.approx(0.0, abs=1e-12) and ends[0]["Y"] == pytest.approx(10.0)
    assert ends[1]["X"] == pytest.approx(-10.0) and ends[1]["Y"] == pytest.approx(0.0, abs=1e-12)


def test_inverse_time_feed():
    blocks, _ = interpret("G21 G93\nG1 X30 F2\nM2\n")
    assert blocks[0].feed == pytest.approx(30 * 2 / 60)  # 30 mm in 1/2 min
    with pytest.raises(ProgramError, match="G93"):
        interpret("G21 G93\nG1 X30 F2\nG1 X40\n")


def test_path_mode_is_carried_on_the_blocks():
    blocks, _ = interpret("G21 G61\nG0 X1\nG64 P0.05\nG0 X2\nG64\nG0 X3\n")
    assert blocks[0].blend_tolerance is None and blocks[1].blend_tolerance == 0.05
    assert math.isinf(blocks[2].blend_tolerance)


@pytest.mark.parametrize("text, line, message", [
    ("G21\nG5.2 X1 Y1 P1 L3\n", 2, "NURBS G5.2 is not supported"),
    ("G21\nG38.2 Z-1 F10\n", 2, "probing G38.2 is not supported"),
    ("G21\nM101\n", 2, "user-defined M-code M101"),
    ("G21\no<ext> call\n", 2, "subroutine o<ext> is not defined"),
    ("G21\n#1 = [1 +\n", 2, "value missing"),
    ("G21\nG0 X[1/0]\n", 2, "division by zero"),
    ("G21\nG0 X[FOO[1]]\n", 2, "unknown function"),
    ("G21\no1 if [0]\nG0 X1\n", 2, "without a matching"),
    ("G21\no1 endsub\n", 2, "without a matching o1 sub"),
    ("G21\nG0 X1\nG41 D1\n", 3, "no tool table"),
    ("G21\nG10 L1 P1 Z3\n", 2, "G10 L1"),
])
def test_unsupported_constructs_give_one_line_with_file_and_line(text, line, message):
    with pytest.raises(ProgramError, match=message) as err:
        parse_program(text, dialect="linuxcnc", name="part.ngc")
    assert str(err.value).startswith(f"part.ngc:{line}: ")
    assert "\n" not in str(err.value)


def test_tool_table_file(tmp_path):
    path = tmp_path / "t.tbl"
    path.write_text("; tools\nT7 P1 Z1.5 D0.25 ;drill\n")
    tool = read_tool_table(path, unit_mm=25.4)[7]
    assert tool.offsets["Z"] == pytest.approx(38.1) and tool.diameter == pytest.approx(6.35)
    path.write_text("T7 P1 Z1.5 Dx\n")
    with pytest.raises(Exception, match=r"t.tbl:1: cannot read"):
        read_tool_table(path)


# ---- rs274's canonical output -----------------------------------------------------------

CANON = """\
    1 N..... USE_LENGTH_UNITS(CANON_UNITS_INCHES)
    2 N..... SET_G5X_OFFSET(1, 1.0000, 0.0000, 0.0000, 0.0000, 0.0000, 0.0000)
    3 N..... USE_TOOL_LENGTH_OFFSET(0.0000 0.0000 0.5000, 0.0000 0.0000 0.0000, 0.0000 0.0000 0.0000)
    4 N0010  STRAIGHT_TRAVERSE(1.0000, 0.0000, 1.0000, 0.0000, 0.0000, 0.0000)
    5 N..... SET_FEED_RATE(60.0000)
    6 N..... SELECT_PLANE(CANON_PLANE_XZ)
    7 N..... ARC_FEED(1.0000, 2.0000, 1.0000, 1.0000, -2, 0.0000, 0.0000, 0.0000, 0.0000)
    8 N..... DWELL(0.5000)
"""


def test_parse_canon_replays_offsets_units_and_planes():
    moves, unsupported = parse_canon(CANON)
    assert unsupported is None
    assert [m.kind for m in moves] == ["G0", "G2", "G4"]
    assert moves[0].end["X"] == pytest.approx(2 * 25.4) and moves[0].end["Z"] == pytest.approx(1.5 * 25.4)
    arc = moves[1]
    assert arc.plane == "XZ" and arc.turns == 2 and arc.feed == pytest.approx(25.4)
    assert arc.end["Z"] == pytest.approx(1.5 * 25.4) and arc.end["X"] == pytest.approx(3 * 25.4)
    assert arc.center == {"Z": pytest.approx(1.5 * 25.4), "X": pytest.approx(2 * 25.4)}
    assert moves[2].dwell_s == 0.5


# ---- agreement with rs274 ---------------------------------------------------------------

def _agree(path: Path, tmp_tools: Path = TOOLS_IN):
    ref = run_rs274(path, tool_table=tmp_tools)
    assert ref.returncode == 0, ref.message
    blocks, _ = interpret(path.read_text(), name=path.name, tools=read_tool_table(tmp_tools, unit_mm=25.4))
    return compare(blocks, ref.moves)


@needs_rs274
@pytest.mark.parametrize("sample", ["3dtest.ngc", "cds.ngc", "hole-circle.ngc", "polar.ngc", "daisy.ngc",
                                    "tort.ngc", "arcspiral.ngc", "flowsnake.ngc"])
def test_linuxcnc_samples_run_the_same_moves_as_rs274(sample):
    path = NCFILES / sample
    if not path.exists():
        pytest.skip(f"{path} not installed")
    agreement = _agree(path)
    assert agreement.problem is None
    assert agreement.max_end_error_mm <= 0.005 and agreement.n_moves > 5


CAM_POST = """%
(a CAM post-processor's program: tool change, length offset, work offset, cycles, arcs)
G21 G90 G17 G40 G49 G80 G94
G10 L2 P1 X12.5 Y-4 Z0
T1 M6
S12000 M3 M8
G54 G43 H1
G0 X0 Y0 Z15
G64 P0.02
G1 Z-1 F300
G1 X20 Y0
G3 X30 Y10 R10
G2 X40 Y20 I10 J0
G91.1 G3 X40 Y20 I-5 J-5
G90 G0 Z10
G98 G83 X5 Y5 R2 Z-6 Q2 F150
X10 L2
G99 G73 X20 Y5 R1 Z-4 Q1.5
G80
G0 Z20
G92 X0 Y0
G1 X5 Y5 F400
G92.1
G0 X0 Y0 Z0
G18 G2 X10 Z0 I5 K0
G19 G3 Y10 Z0 J5 K0
G17
G28 Z30
G30
M5 M9
M30
%
"""


@needs_rs274
def test_a_cam_style_program_agrees_with_rs274(tmp_path):
    path = tmp_path / "post.ngc"
    path.write_text(CAM_POST)
    agreement = _agree(path)
    assert agreement.problem is None
    assert agreement.n_moves >= 25


@needs_rs274
def test_a_wrong_move_is_found(tmp_path):
    path = tmp_path / "p.ngc"
    path.write_text("G21\nG0 X1 Y2\nG1 X3 F100\nM2\n")
    blocks, _ = interpret("G21\nG0 X1 Y2\nG1 X3.01 F100\nM2\n")
    agreement = compare(blocks, run_rs274(path).moves)
    assert agreement.problem is not None and "end X" in agreement.problem


# ---- cutter radius compensation ---------------------------------------------------------

COMP = """G21 G17 G90
G0 X-10 Y0
G41 D1
G1 X0 Y0 F100
G1 X10 Y0
G1 X10 Y10
G1 X20 Y10
G1 X20 Y0
G40
G1 X30 Y-5
M2
"""


def test_cutter_compensation_offsets_the_path_and_rounds_convex_corners():
    tools = parse_tool_table("T1 P1 Z0 D2\n")  # radius 1 mm
    blocks, _ = interpret(COMP, tools=tools)
    moves = [(b.motion, round(b.target["X"], 9), round(b.target["Y"], 9)) for b in blocks[1:]]
    assert moves == [
        ("G1", 0.0, 1.0),     # entry: tangent to the tool circle at the programmed end, on the left
        ("G1", 9.0, 1.0),     # concave corner at (10, 0): end pulled back to where the offsets meet
        ("G1", 9.0, 10.0),
        ("G2", 10.0, 11.0),   # convex corner at (10, 10): an arc about the programmed corner
        ("G1", 20.0, 11.0),
        ("G2", 21.0, 10.0),   # convex corner at (20, 10)
        ("G1", 21.0, 0.0),
        ("G1", 30.0, -5.0),   # exit after G40: to the programmed point
    ]
    assert blocks[4].center == {"X": 10.0, "Y": 10.0} and blocks[6].center == {"X": 20.0, "Y": 10.0}
    assert all(b.feed == pytest.approx(100 / 60) for b in blocks[1:])


def test_cutter_compensation_gouge_and_modes_are_refused():
    tools = parse_tool_table("T1 P1 Z0 D6\n")  # a 1 mm step is too small for a 3 mm radius
    with pytest.raises(ProgramError, match=r"p:7: .*gouging"):
        interpret("G21\nG0 X-10 Y0\nG41 D1\nG1 X0 Y0 F100\nG1 X10 Y0\nG1 X10 Y1\nG1 X20 Y1\nM2\n", tools=tools, name="p")
    with pytest.raises(ProgramError, match="G81 canned cycle with cutter radius compensation on"):
        interpret("G21\nG41\nG81 R1 Z-1 F10\n", tools=tools)
    with pytest.raises(ProgramError, match="just after G40 must be straight"):
        interpret("G21 F10\nG0 X-5\nG41 D1\nG1 X0\nG1 X10\nG40\nG2 X20 R5\n", tools=parse_tool_table("T1 D1\n"))


@needs_rs274
@pytest.mark.parametrize("sample", ["comp.ngc", "comp-g1.ngc", "comp311.ngc", "gmoccapy_2_tools_with_cutter_radius_compensation.ngc",
                                    "useful-subroutines.ngc"])
def test_cutter_compensation_samples_agree_with_rs274(sample):
    path = NCFILES / sample
    if not path.exists():
        pytest.skip(f"{path} not installed")
    agreement = _agree(path)
    assert agreement.problem is None and agreement.n_moves > 5


@needs_rs274
def test_cutter_compensation_program_agrees_with_rs274(tmp_path):
    path = tmp_path / "comp.ngc"
    path.write_text(COMP.replace("G21", "G20"))  # tools.tbl T1: D 0.125 in
    assert _agree(path).problem is None


def test_g94_resets_the_feed_as_linuxcnc():
    with pytest.raises(ProgramError, match="without a programmed feed"):
        interpret("G21 F100\nG1 X1\nG94\nG1 X2\n")


def test_an_endless_loop_is_stopped_with_a_line():
    with pytest.raises(ProgramError, match=r"^loop.ngc:[1-3]: more than .* statements executed: an endless loop"):
        interpret("o1 while [1]\n#1=[#1+1]\no1 endwhile\n", name="loop.ngc")


def test_iso_program_numbers_and_cycle_dwell_in_milliseconds():
    blocks, _ = interpret("O1234 (PART)\nN10 G21 G0 X0 Y0 Z5\nN20 G82 R1 Z-1 P500 F60\n", dialect="iso")
    assert [b.dwell_s for b in blocks if b.motion == "G4"] == [0.5]
    with pytest.raises(ProgramError, match="o1234 without a keyword"):
        interpret("O1234\nG0 X1\n")


@pytest.mark.parametrize("text, message", [
    ("G0 X[EXP[1000]]\n", "out of range"),
    ("G0 X[10 ** 400]\n", "out of range"),
    ("T[1/0]\n", "division by zero"),
])
def test_numbers_out_of_range_are_errors_with_a_line(text, message):
    with pytest.raises(ProgramError, match=rf"^p:1: .*{message}"):
        interpret(text, name="p")


@needs_rs274
def test_a_series_of_different_cycles_keeps_its_initial_level(tmp_path):
    path = tmp_path / "cycles.ngc"
    path.write_text("G21 G0 X0 Y0 Z10\nG98 G81 X5 R2 Z-3 F60\nG0 Z20\nG82 X6 R2 Z-3 P1\nG83 X7 Z-3 R2 Q1\n"
                    "G91 G85 X1 R-15 Z-5 L2\nG90 G89 X20 R2 Z-1 P0.5\nM2\n")
    agreement = _agree(path)
    assert agreement.problem is None and agreement.n_moves > 25


@needs_rs274
def test_cycles_from_below_r_incremental_repeats_and_polar_agree_with_rs274(tmp_path):
    path = tmp_path / "cycles2.ngc"
    path.write_text("G21 S1000 M3 G0 X0 Y0 Z10\nG98 G73 X5 R2 Z-3 Q1.2 F60\nG86 X6 R2 Z-3 P0.2\nG99 X8\n"
                    "G91 G82 X2 Y1 R-5 Z-3 P0.1 L3\nG90 G80\nG0 X10 Y0\nG91 G81 ^30 R1 Z-2 L4\n"
                    "G90 G81 @5 ^10 R1 Z-2\nM2\n")
    agreement = _agree(path)
    assert agreement.problem is None and agreement.n_moves > 40


def test_changing_units_with_a_tool_length_offset_active_is_refused():
    tools = parse_tool_table("T1 P1 Z10\n")
    with pytest.raises(ProgramError, match=r"^p:3: G20 changes the units with a tool length offset active"):
        interpret("G21\nG43 H1\nG20\n", tools=tools, name="p")
    blocks, _ = interpret("G21\nG43 H1\nG49\nG20\nG0 X1\nG21\n", tools=tools)  # cancelled first: fine
    assert blocks[0].target == {"X": pytest.approx(25.4)}


@needs_rs274
@pytest.mark.parametrize("kind", ["general", "comp"])
def test_random_programs_agree_with_rs274(kind):
    import subprocess
    import sys

    res = subprocess.run([sys.executable, str(ROOT / "scripts" / "fuzz_rs274.py"), "--seed", "11", "--count", "40",
                          "--kind", kind], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    assert "disagree 0" in res.stdout


# ---- the language against rs274 ---------------------------------------------------------

EXPRESSIONS = ['[-7 MOD 3]', '[7 MOD -3]', '[-7 MOD -3]', '[7.5 MOD 2]', '[ROUND[-2.5]]', '[ROUND[2.5]]', '[FIX[-2.5]]', '[FUP[-2.5]]', '[ATAN[-1]/[-1]]', '[ATAN[0]/[-1]]', '[2 ** 3 ** 2]', '[-2 ** 2]', '[0 - 2 ** 2]', '[1 EQ 1.00001]', '[1 NE 1.00001]', '[1 EQ 1.001]', '[3 - 2 - 1]', '[8 / 2 / 2]', '[1 + 2 * 3 ** 2]', '[1 OR 0 AND 0]', '[2 XOR 3]', '[ACOS[0.5]]', '[ASIN[0.5]]', '[TAN[45]]', '[EXP[1]]', '[LN[10]]', '[--3]', '[3 * -2]', '[10 MOD 0.3]', '[EXISTS[#<foo>]]', '[1 EQ 1 EQ 1]', '[5 - -3]']


def test_mod_is_non_negative_and_eq_has_linuxcnc_tolerance():
    ends = _ends("G21\nG0 X[7 MOD -3] Y[-7 MOD -3] Z[-7 MOD 3]\nG0 X[1 EQ 1.00001] Y[1 NE 1.00001] Z[1 EQ 1.001]\n")
    assert ends[0] == {"X": 1.0, "Y": 2.0, "Z": 2.0}
    assert ends[1] == {"X": 1.0, "Y": 0.0, "Z": 0.0}


@needs_rs274
def test_expressions_evaluate_as_in_rs274(tmp_path):
    path = tmp_path / "expr.ngc"
    text = "G21\n" + "\n".join(f"G0 X{e}" for e in EXPRESSIONS) + "\nM2\n"
    path.write_text(text)
    ref = run_rs274(path)
    blocks, _ = interpret(text)
    assert ref.returncode == 0 and len(ref.moves) == len(blocks) == len(EXPRESSIONS)
    for expr, ours, theirs in zip(EXPRESSIONS, blocks, ref.moves):
        assert ours.target["X"] == pytest.approx(theirs.end["X"], abs=1e-4), expr


FLOW = 'G21 G90 F600\n#<_g> = 0\no<inner> sub\n  #<loc> = [#1 * 2]\n  #<_g> = [#<_g> + 1]\n  G1 X#<loc> Y#<_g>\n  o<inner> return [#<loc> + 1]\no<inner> endsub\no<outer> sub\n  #2 = 0\n  o11 while [#2 LT #1]\n    o<inner> call [#2]\n    G1 Z#<_value>\n    o12 if [#2 EQ 1]\n      #2 = [#2 + 2]\n      o11 continue\n    o12 endif\n    #2 = [#2 + 1]\n  o11 endwhile\n  o14 repeat [2]\n    o15 repeat [2]\n      G1 X[#<_g> * 3] Y#1\n      #<_g> = [#<_g> + 0.5]\n    o15 endrepeat\n  o14 endrepeat\no<outer> endsub\n#1 = 42\no<outer> call [7]\nG0 X#1 Y#<_g>\no20 do\n  #1 = [#1 - 10]\n  G1 X#1\no20 while [#1 GT 10]\no30 sub\n  M73\n  G20 G91\n  G1 X1\no30 endsub\no30 call\nG1 X5 Y5\nM2\n'


@needs_rs274
def test_subroutines_loops_return_values_and_m73_agree_with_rs274(tmp_path):
    path = tmp_path / "flow.ngc"
    path.write_text(FLOW)
    agreement = _agree(path)
    assert agreement.problem is None and agreement.n_moves > 20

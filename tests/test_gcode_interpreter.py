"""Interpreter: the three dialects, modal state, arcs, units, header, errors with line numbers."""

from __future__ import annotations

import math

import pytest

from core.errors import InputError, ProgramError
from gcode_gen.interpreter import detect_dialect, parse_program, read_program

TABLE_3_2 = """\
N0000 G00 X0.000 F12000
N0010 G01 X 0.258
N0020 G01 X-0.790
N0030 G01 X-2.992
N1830 G01 X9.849
N2010 G01 X 0.000
"""

TABLE_4_3 = """\
0 BEGIN PGM RAPIDIDENT MM
;Rapid Identification on TNC 430 5 axis machine
1 BLK FORM 0.1 Z X-50.000 Y-50.000 Z-50.000
2 BLK FORM 0.2 X+50.000 Y+50.000 Z+50.000
3 TOOL CALL 0 Z
4 L Z+200.000 F MAX
5 L X+0.000 Y+0.000 R0 F MAX M3
7 L X-0.000 F 15000.000
8 L X+0.000
9 L X-0.002
13 L X-.001
204 L X+0.028
205 L X+0.000
206 M30
207 END PGM RAPIDIDENT MM
"""


def _xs(prog, axis="X"):
    return [b.target.get(axis) for b in prog.blocks]


def test_reads_thesis_table_3_2():
    prog = parse_program(TABLE_3_2)
    assert prog.dialect == "iso"
    assert _xs(prog) == [0.0, 0.258, -0.79, -2.992, 9.849, 0.0]
    assert [b.n for b in prog.blocks] == [0, 10, 20, 30, 1830, 2010]
    assert [b.line for b in prog.blocks] == [1, 2, 3, 4, 5, 6]
    assert prog.blocks[0].motion == "G0" and prog.blocks[0].feed is None
    assert all(b.feed == 200.0 for b in prog.blocks[1:])  # F12000 mm/min


def test_reads_thesis_table_4_3():
    prog = parse_program(TABLE_4_3)
    assert prog.dialect == "heidenhain" and prog.name == "RAPIDIDENT"
    assert [b.motion for b in prog.blocks[:3]] == ["G0", "G0", "G1"]
    assert prog.blocks[0].target == {"Z": 200.0}
    assert prog.blocks[1].target == {"X": 0.0, "Y": 0.0}
    assert _xs(prog)[2:] == [-0.0, 0.0, -0.002, -0.001, 0.028, 0.0]
    assert all(b.feed == 250.0 for b in prog.blocks[2:])  # F 15000 mm/min
    assert prog.blocks[-1].n == 205


def test_header_key_values_before_the_first_move():
    text = "(seed=3)\n(range = 10)\n( a plain comment )\nG21 G90 ; feed=200\nG0 X0\n(late=1)\nM2\n"
    prog = parse_program(text, dialect="linuxcnc")
    assert prog.header == {"seed": "3", "range": "10", "feed": "200"}


def test_incremental_and_absolute_modes():
    prog = parse_program("G21 G90\nG0 X1 Y1\nG91 G1 X0.5 F600\nX0.5 Y-1\nG90 X0\nM2\n", dialect="linuxcnc")
    assert [b.target for b in prog.blocks] == [{"X": 1, "Y": 1}, {"X": 1.5}, {"X": 2.0, "Y": 0.0}, {"X": 0.0}]
    assert prog.blocks[1].feed == 10.0


def test_inch_programs_are_converted_to_mm():
    prog = parse_program("G20 G90\nG1 X1 Y-0.5 F10\nM2\n", dialect="linuxcnc")
    assert prog.blocks[0].target == {"X": pytest.approx(25.4), "Y": pytest.approx(-12.7)}
    assert prog.blocks[0].feed == pytest.approx(25.4 * 10 / 60)


def test_arcs_with_ij_and_with_r():
    text = """G21 G90 G17
G0 X0 Y10
G2 X10 Y0 I0 J-10 F600
G3 X0 Y10 R10
G2 X10 Y0 R-10
G90.1 G3 X0 Y10 I0 J0
G91.1 G2 I-10 J0
M2
"""
    prog = parse_program(text, dialect="linuxcnc")
    arcs = prog.blocks[1:]
    assert [b.motion for b in arcs] == ["G2", "G3", "G2", "G3", "G2"]
    assert arcs[0].center == {"X": 0.0, "Y": 0.0}
    assert arcs[1].center == {"X": pytest.approx(0.0, abs=1e-12), "Y": pytest.approx(0.0, abs=1e-12)}
    assert arcs[2].center == {"X": pytest.approx(10.0), "Y": pytest.approx(10.0)}  # R<0: the long way round
    assert arcs[3].center == {"X": 0.0, "Y": 0.0}
    assert arcs[4].target == {"X": 0.0, "Y": 10.0} and arcs[4].center == {"X": -10.0, "Y": 10.0}  # full circle
    assert all(b.feed == 10.0 for b in arcs)


def test_dwell_units_per_dialect():
    assert parse_program("G4 P0.5\n", dialect="linuxcnc").blocks[0].dwell_s == 0.5
    iso = parse_program("N10 G04 P500\nN20 G04 X1.5\n", dialect="iso")
    assert [b.dwell_s for b in iso.blocks] == [0.5, 1.5]
    assert all(b.motion == "G4" and b.target == {} for b in iso.blocks)
    tnc = parse_program("0 BEGIN PGM D MM\n1 CYCL DEF 9.0 DWELL TIME\n2 CYCL DEF 9.1 DWELL 2.5\n3 END PGM D MM\n")
    assert tnc.blocks[0].dwell_s == 2.5


def test_program_end_stops_reading():
    prog = parse_program("%\nG0 X1\nM30\nG0 X5\n%\n", dialect="iso")
    assert _xs(prog) == [1.0]
    prog = parse_program("%\nG0 X1\n%\nthis is ignored\n", dialect="linuxcnc")
    assert _xs(prog) == [1.0]


def test_heidenhain_arcs_incremental_and_fmax():
    text = """0 BEGIN PGM ARCS MM
1 L X+10 Y+0 R0 FMAX
2 CC X+0 Y+0
3 C X+0 Y+10 DR+ F6000
4 C X+10 Y+0 DR-
5 L IX-5 IY+2.5
6 CR X+10 Y+10 R+5 DR+
7 L X+0 FMAX
8 L X+1
9 CC
10 L X+2
11 C X+1 Y+11 DR-
12 END PGM ARCS MM
"""
    prog = parse_program(text)
    m = [b.motion for b in prog.blocks]
    assert m == ["G0", "G3", "G2", "G1", "G3", "G0", "G1", "G1", "G2"]
    assert prog.blocks[1].center == {"X": 0.0, "Y": 0.0} and prog.blocks[1].feed == 100.0
    assert prog.blocks[3].target == {"X": 5.0, "Y": 2.5}
    c = prog.blocks[4].center
    assert math.hypot(5.0 - c["X"], 2.5 - c["Y"]) == pytest.approx(5.0)
    assert math.hypot(10.0 - c["X"], 10.0 - c["Y"]) == pytest.approx(5.0)
    assert prog.blocks[5].feed is None and prog.blocks[6].feed == 100.0  # FMAX is blockwise, F modal
    assert prog.blocks[8].center == {"X": 1.0, "Y": 10.0}  # CC without coordinates: the current position


def test_heidenhain_inch_programs():
    prog = parse_program("0 BEGIN PGM I INCH\n1 L X+1 R0 F10\n2 END PGM I INCH\n")
    assert prog.blocks[0].target == {"X": pytest.approx(25.4)}
    assert prog.blocks[0].feed == pytest.approx(25.4 * 10 / 60)


@pytest.mark.parametrize(
    "text, dialect, line, message",
    [
        ("G21\nG1 X1 F100\nG1 X2 Q5\n", "linuxcnc", 3, "word Q5 is not used"),
        ("G21\nG33 X1 K1\n", "linuxcnc", 2, "spindle-synchronised motion G33 is not supported"),
        ("G21\nG1 X1\n", "linuxcnc", 2, "without a programmed feed"),
        ("G0 X0 Y0\nG2 X10 Y0 I3 J0 F100\n", "linuxcnc", 2, "differs from start radius"),
        ("G0 X0 Y0\nG2 X10 Y0 R2 F100\n", "linuxcnc", 2, "shorter than half the chord"),
        ("G0 X1 (open comment\n", "linuxcnc", 1, "not closed"),
        ("O100 sub\n", "linuxcnc", 1, "o100 sub without endsub"),
        ("G0 X1\nX2 G1 G0\n", "linuxcnc", 2, "two motion G-codes"),
        ("X1\n", "linuxcnc", 1, "without a motion mode"),
        ("G0 X0 Y0\nG1 X1 I2 F100\n", "linuxcnc", 2, "word I2 is not used"),
        ("N10 G0 X0\nN20 M98\n", "iso", 2, "M98 is not supported"),
        ("G18\nG0 X0 Z0\nG81 R1 Z-1 F10 X1\n", "linuxcnc", 3, "outside the XY plane"),
        ("G1 X1 F0\n", "linuxcnc", 1, "feed must be positive"),
        ("G1 X1 X2 F10\n", "linuxcnc", 1, "appears twice"),
        ("G1 X$1\n", "linuxcnc", 1, "bad number or value"),
        ("0 BEGIN PGM A MM\n1 L X+1 RL F100\n", "heidenhain", 2, "radius compensation"),
        ("0 BEGIN PGM A MM\n1 L X+1 Y+0 F100\n2 C X+0 Y+1 DR+\n", "heidenhain", 3, "without a centre CC"),
        ("0 BEGIN PGM A MM\n1 L X+1 Y+0 F100\n2 CC X+0 Y+0\n3 C X+0 Y+1\n", "heidenhain", 4, "without a direction"),
        ("0 BEGIN PGM A MM\n1 LBL 1\n", "heidenhain", 2, "unsupported block 'LBL'"),
        ("0 BEGIN PGM A MM\n1 L X+1 F100\n200 L +0.009\n", "heidenhain", 3, "unknown word '\\+0.009'"),
        ("0 BEGIN PGM A CM\n", "heidenhain", 1, "unknown unit"),
        ("0 BEGIN PGM A MM\n1 L X+1 F100 M91\n", "heidenhain", 2, "M91"),
        ("0 BEGIN PGM A MM\n1 M30 X5\n", "heidenhain", 2, "unknown word"),
    ],
)
def test_errors_name_the_line(text, dialect, line, message):
    with pytest.raises(ProgramError, match=message) as err:
        parse_program(text, dialect=dialect, name="prog")
    assert err.value.line == line
    assert str(err.value).startswith(f"prog:{line}: ") or str(err.value).startswith(f"A:{line}: ")
    assert "\n" not in str(err.value)


def test_detects_dialects():
    assert detect_dialect(TABLE_4_3) == "heidenhain"
    assert detect_dialect(TABLE_3_2) == "iso"
    assert detect_dialect("G21 G90\nG0 X1\nM2\n") == "linuxcnc"
    assert detect_dialect("(dialect=iso)\nG0 X1\n") == "iso"
    assert detect_dialect("1 L X+1 R0 FMAX\n") == "heidenhain"
    # N-numbered LinuxCNC programs (LinuxCNC's own samples): by extension or by language
    assert detect_dialect("n10 G4 P0.5\n", name="cds.ngc") == "linuxcnc"
    assert detect_dialect("N10 #<x> = 1\nN20 G0 X#<x>\n") == "linuxcnc"
    assert detect_dialect("N10 o100 sub\nN20 o100 endsub\n") == "linuxcnc"
    assert detect_dialect("N10 G0 X[1+1]\n") == "linuxcnc"
    assert detect_dialect("N10 G04 P500\n", name="part.nc") == "iso"


def test_unknown_dialect_is_an_input_error():
    with pytest.raises(InputError, match="unknown dialect 'fanuc'"):
        parse_program("G0 X1\n", dialect="fanuc")


def test_read_program_uses_the_file_stem(tmp_path):
    path = tmp_path / "part7.ngc"
    path.write_text("G21\nG0 X3\nM2\n")
    prog = read_program(path)
    assert prog.name == "part7" and prog.blocks[0].target == {"X": 3.0}
    with pytest.raises(InputError, match="cannot read program"):
        read_program(tmp_path / "missing.ngc")
    bad = tmp_path / "bad.ngc"
    bad.write_text("G0 X1\nG1 X2\n")
    with pytest.raises(ProgramError, match=r"^bad:2: .*feed"):
        read_program(bad)

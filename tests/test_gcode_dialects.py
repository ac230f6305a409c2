"""Dialect writers: golden files, the layout of each dialect, and re-parsing to the same moves."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

from core.errors import InputError
from gcode_gen import dialects
from gcode_gen.excitation import identification_programs
from gcode_gen.interpreter import parse_program
from gcode_gen.toolpaths import circle, diamond

ROOT = Path(__file__).resolve().parent.parent
FIXTURES = ROOT / "fixtures" / "gcode"


def _golden_toolpaths():
    spec = importlib.util.spec_from_file_location("make_gcode_fixtures", ROOT / "scripts" / "make_gcode_fixtures.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.golden_toolpaths()


@pytest.mark.parametrize("dialect", sorted(dialects.DIALECTS))
def test_output_matches_golden_files(dialect):
    """Regenerate with scripts/make_gcode_fixtures.py after an intended change."""
    for tp in _golden_toolpaths():
        path = FIXTURES / dialect / dialects.file_name(tp, dialect)
        assert dialects.write(tp, dialect) == path.read_text(encoding="utf-8"), path.name


ALL = [*identification_programs(axes=("X", "Y"), center=(3.0, -1.0), n_low=50, n_high=50, seed=4),
       circle(size=12.0, feed=80.0, center=(1.0, 1.0)), circle(direction="cw"), diamond(size=7.0, feed=33.3)]


@pytest.mark.parametrize("dialect", sorted(dialects.DIALECTS))
@pytest.mark.parametrize("tp", ALL, ids=lambda tp: tp.name)
def test_reparsing_gives_the_same_targets_feeds_and_centres(dialect, tp):
    prog = parse_program(dialects.write(tp, dialect))  # dialect auto-detected
    assert prog.dialect == dialect
    assert len(prog.blocks) == len(tp.blocks)
    for got, want in zip(prog.blocks, tp.blocks):
        assert got.motion == want.motion
        assert got.target == want.target
        if want.motion == "G4":
            assert got.dwell_s == pytest.approx(want.dwell_s, abs=5e-4)
        elif want.motion == "G0":
            assert got.feed is None
        else:  # F written in mm/min rounded down to 0.001
            assert want.feed - 1e-5 / 60 <= got.feed <= want.feed
        if want.center:
            assert got.center == pytest.approx(want.center, abs=1e-9)
    for key, value in tp.header.items():
        assert prog.header[key] == value
    assert prog.header["dialect"] == dialect


def test_iso_looks_like_table_3_2():
    low, high = identification_programs(n_low=3, n_high=3)
    text = dialects.write(high, "iso")
    lines = text.splitlines()
    assert lines[0] == "%" and lines[-1] == "%"
    blocks = [ln for ln in lines if ln.startswith("N")]
    assert blocks[0] == "N0000 G21 G90 G17 G94" and blocks[1] == "N0010 G61"
    # positioning move at the maximum feed (not G00: SPEC §8 feed limit), then modal F
    assert re.fullmatch(r"N0020 G01 X0\.000 F12000", blocks[2])
    assert all(re.fullmatch(r"N\d{4} G01 X-?\d+\.\d{3}", b) for b in blocks[3:-1])
    assert blocks[-1].endswith("M30")
    assert "(seed=1)" in lines


def test_low_set_is_written_with_four_decimals():
    low, _ = identification_programs(n_low=5)
    for dialect in dialects.DIALECTS:
        moves = re.findall(r"X([+-]?\d+\.\d+)", dialects.write(low, dialect))
        assert moves and all(len(m.split(".")[1]) == 4 for m in moves)


def test_heidenhain_looks_like_tables_4_3_and_4_4():
    low, _ = identification_programs(n_low=3, feed=250.0)
    lines = dialects.write(low, "heidenhain").splitlines()
    numbers = [int(ln.split()[0]) for ln in lines]
    assert numbers == list(range(len(lines)))
    assert lines[0] == "0 BEGIN PGM ident_low MM" and lines[-1].endswith("END PGM ident_low MM")
    assert lines[-2].endswith("M30")
    moves = [ln.split(" ", 1)[1] for ln in lines if " L " in ln]
    assert moves[0] == "L X+0.0000 R0 F15000"  # positioning at the maximum feed, not FMAX
    assert all(re.fullmatch(r"L X[+-]\d\.\d{4}", m) for m in moves[1:])
    assert any(ln.endswith("; seed=1") for ln in lines)


def test_heidenhain_circle_uses_cc_and_c():
    text = dialects.write(circle(size=10.0, center=(2.0, 3.0)), "heidenhain")
    assert "CC X+2.0000 Y+3.0000" in text and "C X+7.0000 Y+3.0000 DR+ F12000" in text
    assert "DR-" in dialects.write(circle(direction="cw"), "heidenhain")


def test_linuxcnc_states_units_mode_path_control_and_end():
    low, _ = identification_programs(n_low=3)
    lines = dialects.write(low, "linuxcnc").splitlines()
    code = [ln for ln in lines if not ln.startswith("(")]
    assert code[0] == "%" and code[-1] == "%" and code[-2] == "M2"
    assert code[1].split()[:4] == ["G21", "G90", "G17", "G94"]
    assert code[2] == "G61.1"  # LinuxCNC exact stop (G61 there is exact *path*)
    assert not any(re.match(r"\((debug|print|msg|log)", ln, re.I) for ln in lines)
    assert not re.search(r"\bN\d", "\n".join(code))


def test_blending_is_written_explicitly():
    from dataclasses import replace

    low, _ = identification_programs(n_low=3)
    text = dialects.write(replace(low, blending=True), "linuxcnc")
    assert "G64 P0.01" in text and "G61" not in text
    assert "(blending=1)" in text


def test_feed_is_never_rounded_up():
    tp = diamond(feed=123.456789)
    for dialect in dialects.DIALECTS:
        f = float(re.search(r"F(\d+(?:\.\d+)?)", dialects.write(tp, dialect)).group(1))
        assert f <= 123.456789 * 60 and f > 123.456789 * 60 - 0.001


def test_unknown_dialect_is_an_input_error():
    with pytest.raises(InputError, match="unknown dialect 'fanuc'"):
        dialects.write(diamond(), "fanuc")

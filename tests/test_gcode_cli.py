"""``agent generate`` through the real typer app."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

import agent.cli
from gcode_gen.interpreter import read_program

agent.cli._register()
runner = CliRunner()


def _run(*args):
    return runner.invoke(agent.cli.app, ["generate", *args])


@pytest.mark.parametrize("dialect, ext", [("iso", ".nc"), ("linuxcnc", ".ngc"), ("heidenhain", ".h")])
def test_writes_both_identification_sets(tmp_path, dialect, ext):
    res = _run("--dialect", dialect, "-o", str(tmp_path / "out"), "--seed", "5", "--n-low", "30", "--n-high", "40")
    assert res.exit_code == 0, res.output
    paths = res.stdout.split()
    assert [p.rsplit("/", 1)[-1] for p in paths] == [f"ident_low{ext}", f"ident_high{ext}"]
    low, high = (read_program(p) for p in paths)
    assert low.dialect == high.dialect == dialect
    assert len(low.blocks) == 31 and len(high.blocks) == 42
    assert high.header["seed"] == "5" and high.header["n_low"] == "30" and high.header["set"] == "high"


def test_options_reach_the_programs(tmp_path):
    res = _run("--axes", "x,y", "--centre", "50,-20", "--range", "4", "--low-step", "0.01",
               "--feed", "100", "-o", str(tmp_path))
    assert res.exit_code == 0, res.output
    high = read_program(tmp_path / "ident_high.nc")
    xs = [b.target["X"] for b in high.blocks]
    ys = [b.target["Y"] for b in high.blocks]
    assert min(xs) == 46.0 and max(xs) == 54.0 and min(ys) == -24.0 and max(ys) == -16.0
    assert {b.feed for b in high.blocks[1:]} == {100.0}
    low = read_program(tmp_path / "ident_low.nc")
    assert low.header["low_step"] == "0.01" and low.header["center"] == "50,-20"


def test_blending_flag_writes_g64(tmp_path):
    assert _run("--dialect", "linuxcnc", "--blending", "-o", str(tmp_path)).exit_code == 0
    text = (tmp_path / "ident_low.ngc").read_text()
    assert "\nG64 P0.01\n" in text and "(blending=1)" in text


def test_same_seed_same_files(tmp_path):
    for d in ("a", "b"):
        assert _run("--seed", "9", "-o", str(tmp_path / d)).exit_code == 0
    assert (tmp_path / "a/ident_high.nc").read_text() == (tmp_path / "b/ident_high.nc").read_text()


@pytest.mark.parametrize("kind", ["circle", "diamond"])
def test_writes_a_validation_toolpath(tmp_path, kind):
    res = _run("--toolpath", kind, "--size", "30", "--feed", "150", "--dialect", "heidenhain", "-o", str(tmp_path))
    assert res.exit_code == 0, res.output
    prog = read_program(res.stdout.strip())
    assert prog.header["toolpath"] == kind and prog.header["size"] == "30"
    assert prog.name == kind
    # positioning rapid, a dwell so the drives settle, then the contour at the feed
    assert [b.motion for b in prog.blocks[:2]] == ["G0", "G4"] and prog.blocks[1].dwell_s == 0.2
    moves = [b for b in prog.blocks if b.motion not in ("G0", "G4")]
    assert all(b.feed == 150.0 for b in moves)
    assert {b.motion for b in moves} == ({"G3"} if kind == "circle" else {"G1"})


@pytest.mark.parametrize(
    "args, message",
    [
        (["--range", "-1"], "range must be a positive"),
        (["--feed", "0"], "--feed must be a positive"),
        (["--n-low", "0"], "n-low must be an integer >= 1"),
        (["--n-high", "0"], "n-high must be an integer >= 1"),
        (["--low-step", "11"], "low-step 11.0 mm is larger than the range"),
        (["--dialect", "fanuc"], "unknown dialect 'fanuc'"),
        (["--axes", "X,Q"], "unknown axis letter 'Q'"),
        (["--centre", "1,2"], "--centre has 2 values for 1 axes"),
        (["--centre", "abc"], "--centre needs numbers"),
        (["--center", "abc"], "--centre needs numbers"),  # the other spelling still works
        (["--toolpath", "star"], "unknown toolpath 'star'"),
        (["--toolpath", "circle", "--size", "0"], "circle size must be a positive"),
        (["--toolpath", "diamond", "--axes", "X"], "needs two different axes"),
    ],
)
def test_invalid_parameters_give_one_line_errors(tmp_path, args, message):
    res = _run(*args, "-o", str(tmp_path))
    assert res.exit_code == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0]
    assert list(tmp_path.iterdir()) == []


def test_output_path_that_is_a_file_is_an_error(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    res = _run("-o", str(f))
    assert res.exit_code == 2 and "not a directory" in res.stderr

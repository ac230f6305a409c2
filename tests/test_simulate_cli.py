"""`agent generate --dialect linuxcnc` then `agent simulate` on both sets: an MCAP the mcap library reads."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

from agent import cli
from core.reader import load_recording

cli._register()


def invoke(*args):
    return CliRunner().invoke(cli.app, [str(a) for a in args])


@pytest.fixture(scope="module")
def programs(tmp_path_factory):
    out = tmp_path_factory.mktemp("prog")
    res = invoke("generate", "--axes", "X,Y", "--dialect", "linuxcnc", "--n-low", 40, "--n-high", 20, "--seed", 3,
                 "-o", out)
    assert res.exit_code == 0, res.output
    return out / "ident_low.ngc", out / "ident_high.ngc"


def test_simulate_writes_mcap_with_commanded_actual_and_metadata(tmp_path, programs):
    log, csv = tmp_path / "run.mcap", tmp_path / "run.csv"
    res = invoke("simulate", *programs, "--machine", "fadal-pid", "--seed", 4, "-o", log, "--csv", csv)
    assert res.exit_code == 0, res.output
    with open(log, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        msgs = list(reader.iter_messages(topics=["/samples"]))
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    channel = msgs[0][1]
    assert channel.metadata["axes"] == "X,Y" and channel.metadata["transport"] == "simulation"
    programs_meta = json.loads(channel.metadata["programs"])
    assert [p["name"] for p in programs_meta] == ["ident_low.ngc", "ident_high.ngc"]
    assert all(len(p["sha256"]) == 64 for p in programs_meta)
    assert meta["rapid-ident.summary"]["dropped"] == "0"
    assert summary.statistics.channel_message_counts[channel.id] == len(msgs)
    first, last = json.loads(msgs[0][2].data), json.loads(msgs[-1][2].data)
    assert set(first["commanded"]) == {"X", "Y"} and last["segment"] == 1
    rec, rec_csv = load_recording(log), load_recording(csv)
    assert len(rec.segments()) == 2  # the low- and high-speed sets are separate segments
    np.testing.assert_allclose(rec.axes["Y"].actual, rec_csv.axes["Y"].actual, atol=1e-9)
    # the drive follows the command, with a tracking error of a drive, not a copy
    e = rec.axes["X"].tracking_error
    assert 0 < np.abs(e).max() < 0.5


def test_simulate_is_reproducible_and_effects_change_it(tmp_path, programs):
    runs = {}
    for name, extra in (("a", []), ("b", []), ("backlash", ["--effect", "backlash=0.02"])):
        log = tmp_path / f"{name}.mcap"
        assert invoke("simulate", *programs, "-o", log, "--seed", 1, *extra).exit_code == 0
        runs[name] = load_recording(log).axes["X"].actual
    np.testing.assert_array_equal(runs["a"], runs["b"])
    assert np.abs(runs["backlash"] - runs["a"]).max() > 0.005


@pytest.mark.parametrize(
    "args, message",
    [
        (["--machine", "no-such-preset"], "no-such-preset"),
        (["--effect", "gremlins=3"], "gremlins"),
        (["--effect", "backlash=abc"], "backlash"),
    ],
)
def test_simulate_bad_options_are_one_line_errors(tmp_path, programs, args, message):
    res = invoke("simulate", *programs, "-o", tmp_path / "x.mcap", *args)
    assert res.exit_code == 2
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and message in lines[0]


def test_simulate_missing_program_and_wrong_suffix(tmp_path, programs):
    res = invoke("simulate", tmp_path / "absent.ngc", "-o", tmp_path / "x.mcap")
    assert res.exit_code == 2 and "no such program file" in res.stderr
    res = invoke("simulate", *programs, "-o", tmp_path / "x.txt")
    assert res.exit_code == 2 and ".mcap" in res.stderr


def test_a_tool_length_offset_runs_with_the_tool_table_it_needs(tmp_path):
    """G43 H1 needs tool 1's length: without --tool-table one line says so; with a LinuxCNC
    tool table the program runs (a length offset moves only Z, which this program leaves)."""
    prog = tmp_path / "tool.ngc"
    prog.write_text("G21 G17 G90\nT1 M6\nG43 H1\nG0 X0 Y0\nG1 X10 Y0 F600\nG1 X10 Y10\nG49\nM2\n")
    table = tmp_path / "tools.tbl"
    table.write_text("T1 P1 Z25.0 D6.0 ;6 mm end mill\n")
    runner = CliRunner()
    res = runner.invoke(cli.app, ["simulate", str(prog), "-o", str(tmp_path / "a.mcap")])
    assert res.exit_code == 2 and "--tool-table" in res.output and "tool.ngc:3" in res.output
    assert not (tmp_path / "a.mcap").exists()
    res = runner.invoke(cli.app, ["simulate", str(prog), "-o", str(tmp_path / "b.mcap"), "--tool-table", str(table)])
    assert res.exit_code == 0, res.output
    rec = load_recording(tmp_path / "b.mcap")
    assert rec.axes["X"].commanded.max() == pytest.approx(10.0)


def test_an_axis_that_does_not_follow_its_command_is_warned_about_and_still_written(tmp_path, programs):
    # a 50 ms dead time in a loop of ~50 Hz bandwidth: the virtual CNC runs it, unstable
    log = tmp_path / "delayed.mcap"
    res = invoke("simulate", programs[1], "--effect", "time_delay=0.05", "-o", log)
    assert res.exit_code == 0, res.output
    warnings = [line for line in res.output.splitlines() if line.startswith("warning:")]
    assert [w.split(":")[1].strip() for w in warnings] == ["X", "Y"], res.output  # one line per axis
    assert all("does not follow the command" in w for w in warnings)
    assert load_recording(log).n_samples > 0
    ok = invoke("simulate", programs[1], "--effect", "time_delay=0.002", "-o", tmp_path / "ok.mcap")
    assert ok.exit_code == 0 and "warning" not in ok.output

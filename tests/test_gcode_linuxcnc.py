"""Cross-check with LinuxCNC's own interpreter (``rs274`` from the linuxcnc-uspace package).

Skipped when ``rs274`` is not installed.  Every generated LinuxCNC program must run through
LinuxCNC's interpreter without error, in exact-stop mode (or continuous with blending),
with the same end points, arc centres and feeds our interpreter reads.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from dataclasses import replace

import pytest

from gcode_gen import dialects
from gcode_gen.excitation import identification_programs
from gcode_gen.interpreter import parse_program
from gcode_gen.toolpaths import circle, diamond

RS274 = shutil.which("rs274")
pytestmark = pytest.mark.skipif(RS274 is None, reason="LinuxCNC rs274 interpreter not installed")

CALL = re.compile(r"^\s*\d+\s+N\.+\s+([A-Z_]+)\((.*)\)\s*$")


def _canon(path):
    res = subprocess.run([RS274, "-g", str(path)], capture_output=True, text=True, timeout=30)
    calls = []
    for line in res.stdout.splitlines():
        m = CALL.match(line)
        if m:
            calls.append((m.group(1), [a.strip() for a in m.group(2).split(",")] if m.group(2) else []))
    return res.returncode, calls, res.stdout + res.stderr


TOOLPATHS = [*identification_programs(axes=("X", "Y"), center=(12.0, -3.0), n_low=60, n_high=60, seed=3),
             circle(size=25.0, feed=150.0, center=(2.0, 1.0)), circle(direction="cw"), diamond(size=14.0, feed=90.5)]


@pytest.mark.parametrize("blending", [False, True])
@pytest.mark.parametrize("tp", TOOLPATHS, ids=lambda tp: tp.name)
def test_linuxcnc_runs_the_program_with_the_same_moves(tmp_path, tp, blending):
    tp = replace(tp, blending=blending)
    path = tmp_path / dialects.file_name(tp, "linuxcnc")
    path.write_text(dialects.write(tp, "linuxcnc"))
    rc, calls, output = _canon(path)
    assert rc == 0, output
    assert ("USE_LENGTH_UNITS", ["CANON_UNITS_MM"]) in calls
    mode = [args[0] for name, args in calls if name == "SET_MOTION_CONTROL_MODE"][-1]
    assert mode == ("CANON_CONTINUOUS" if blending else "CANON_EXACT_STOP")
    assert "PROGRAM_END" in [name for name, _ in calls]

    ours = parse_program(path.read_text())
    moves = [(n, [float(a) for a in args]) for n, args in calls
             if n in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED", "ARC_FEED", "DWELL")]
    assert len(moves) == len(ours.blocks)
    feed = None
    feeds = iter(float(args[0]) for n, args in calls if n == "SET_FEED_RATE" and float(args[0]) > 0)
    for (name, args), b in zip(moves, ours.blocks):
        kind = {"G0": "STRAIGHT_TRAVERSE", "G1": "STRAIGHT_FEED", "G2": "ARC_FEED", "G3": "ARC_FEED", "G4": "DWELL"}[b.motion]
        assert name == kind
        if name == "DWELL":
            assert args[0] == pytest.approx(b.dwell_s)
            continue
        assert args[0] == pytest.approx(b.target["X"], abs=5e-5)
        assert args[1] == pytest.approx(b.target["Y"], abs=5e-5)
        if name == "ARC_FEED":
            assert args[2:4] == pytest.approx([b.center["X"], b.center["Y"]], abs=5e-5)
            assert args[4] == (1 if b.motion == "G3" else -1)
        if b.feed is not None and b.feed != feed:
            feed = b.feed
            assert next(feeds) == pytest.approx(feed * 60, abs=1e-3)


def test_linuxcnc_and_our_interpreter_both_refuse_a_move_without_feed(tmp_path):
    path = tmp_path / "bad.ngc"
    path.write_text("G21 G90\nG1 X1\nM2\n")
    rc, _, output = _canon(path)
    assert rc != 0 and "feed" in output.lower()
    with pytest.raises(Exception, match="feed"):
        parse_program(path.read_text(), dialect="linuxcnc")

"""Regenerate the golden G-code files in fixtures/gcode/ (run after an intended format change).

    /work/venv/bin/python scripts/make_gcode_fixtures.py

Writes, for each dialect, a small identification pair (20 + 20 moves, two axes, seed 7)
and both validation contours.  tests/test_gcode_golden.py compares fresh output with
these files, so any change to the generated text shows up as a diff to review.
"""

from __future__ import annotations

from pathlib import Path

from gcode_gen import dialects
from gcode_gen.excitation import identification_programs
from gcode_gen.toolpaths import circle, diamond

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures" / "gcode"


def golden_toolpaths():
    """The toolpaths the golden files hold (shared with the test)."""
    low, high = identification_programs(axes=("X", "Y"), center=(5.0, -2.5), range_mm=8.0, low_step=0.03,
                                        n_low=20, n_high=20, feed=150.0, seed=7)
    return [low, high, circle(size=30.0, feed=200.0, center=(1.0, 2.0), direction="cw"),
            diamond(size=20.0, feed=120.0)]


def main() -> None:
    FIXTURES.mkdir(parents=True, exist_ok=True)
    for dialect in dialects.DIALECTS:
        for tp in golden_toolpaths():
            path = FIXTURES / dialect / dialects.file_name(tp, dialect)
            path.parent.mkdir(exist_ok=True)
            path.write_text(dialects.write(tp, dialect), encoding="utf-8")
            print(path.relative_to(FIXTURES.parent.parent))


if __name__ == "__main__":
    main()

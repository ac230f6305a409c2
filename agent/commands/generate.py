"""``agent generate``: write the identification programs or a validation contour.

Identification set (default): two files, ``ident_low<ext>`` (tiny random steps) and
``ident_high<ext>`` (random targets within centre ± range), see
:mod:`gcode_gen.excitation`.  ``--toolpath circle|diamond`` writes one validation
contour instead (:mod:`gcode_gen.toolpaths`).  The extension follows the dialect:
``.nc`` iso, ``.ngc`` linuxcnc, ``.h`` heidenhain.  Prints the paths written.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

import typer

from core.errors import InputError


def _floats(text: str, option: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise InputError(f"{option} needs numbers separated by commas, got {text!r}") from None
    if not values or not all(math.isfinite(v) for v in values):
        raise InputError(f"{option} needs finite numbers, got {text!r}")
    return values


def _axes(text: str) -> list[str]:
    axes = [a.strip().upper() for a in text.split(",") if a.strip()]
    if not axes:
        raise InputError(f"--axes needs axis letters such as X or X,Y, got {text!r}")
    return axes


def generate(
    axes: Optional[str] = typer.Option(None, "--axes", help="Axis letters, comma separated (default X; X,Y for a toolpath)."),
    centre: str = typer.Option("0", "--centre", help="Centre of the travel range, mm: one value or one per axis (comma list)."),
    center: Optional[str] = typer.Option(None, "--center", hidden=True),  # the other spelling, kept working
    range_mm: float = typer.Option(10.0, "--range", help="Half-width of the travel range, mm: no target leaves centre ± range."),
    low_step: float = typer.Option(0.03, "--low-step", help="Largest step of the low-speed set, mm."),
    n_low: int = typer.Option(200, "--n-low", help="Number of moves in the low-speed set."),
    n_high: int = typer.Option(200, "--n-high", help="Number of moves in the high-speed set."),
    feed: float = typer.Option(200.0, "--feed", help="Maximum (programmed) feed, mm/s."),
    seed: int = typer.Option(1, "--seed", help="Random seed; the same seed gives the same programs."),
    distribution: str = typer.Option("uniform", "--distribution", help="High-speed targets: uniform (thesis Table 3.2) or loguniform step lengths."),
    dialect: str = typer.Option("iso", "--dialect", help="iso, heidenhain or linuxcnc."),
    toolpath: Optional[str] = typer.Option(None, "--toolpath", help="Write a validation contour instead: circle or diamond (with --direction both --start-angle 45: the ballbar pair)."),
    size: float = typer.Option(20.0, "--size", help="Contour size, mm (circle diameter; diamond vertex-to-vertex)."),
    direction: str = typer.Option("ccw", "--direction", help="Contour sense: ccw, cw, or both (two programs: the ballbar test's pair)."),
    start_angle: float = typer.Option(0.0, "--start-angle", help="Where a circle starts and ends, degrees from the first axis (45 for a ballbar test)."),
    blending: bool = typer.Option(False, "--blending", help="Write path blending (G64 P0.01) instead of exact stop (G61; G61.1 in LinuxCNC)."),
    out: Path = typer.Option(Path("."), "-o", "--out", help="Output directory (created if missing)."),
) -> None:
    """Write identification programs (low- and high-speed sets) or a validation contour.

    Example: agent generate --axes X --dialect linuxcnc -o prog/
    """
    from agent.validation import check_seed
    from gcode_gen.generator import generate as make_programs
    from gcode_gen.generator import save_programs

    check_seed(seed)
    if not math.isfinite(feed) or feed <= 0:
        raise InputError(f"--feed must be a positive number of mm/s, got {feed}")
    default_axes = "X,Y" if toolpath is not None else "X"
    programs = make_programs(
        _axes(axes or default_axes), center=_floats(center or centre, "--centre"), range_mm=range_mm,
        low_step=low_step, n_low=n_low, n_high=n_high, feed=feed, seed=seed, distribution=distribution,
        toolpath=toolpath, size=size, blending=blending, direction=direction.strip().lower(), start_deg=start_angle,
    )
    for path in save_programs(programs, dialect, out):
        print(path)

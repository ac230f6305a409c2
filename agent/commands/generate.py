"""``agent generate``: write the identification programs or a validation contour.

Identification set (default): two files, ``ident_low<ext>`` (tiny random steps) and
``ident_high<ext>`` (random targets within centre ± range), see
:mod:`gcode_gen.excitation`.  ``--toolpath circle|diamond`` writes one validation
contour instead (:mod:`gcode_gen.toolpaths`).  The extension follows the dialect:
``.nc`` iso, ``.ngc`` linuxcnc, ``.h`` heidenhain.  Prints the paths written.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Optional

import typer

from core.errors import InputError
from gcode_gen import dialects
from gcode_gen.excitation import identification_programs
from gcode_gen.toolpaths import TOOLPATHS


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
    center: str = typer.Option("0", "--center", help="Centre of the travel range, mm: one value or one per axis (comma list)."),
    range_mm: float = typer.Option(10.0, "--range", help="Half-width of the travel range, mm: no target leaves centre ± range."),
    low_step: float = typer.Option(0.03, "--low-step", help="Largest step of the low-speed set, mm."),
    n_low: int = typer.Option(200, "--n-low", help="Number of moves in the low-speed set."),
    n_high: int = typer.Option(200, "--n-high", help="Number of moves in the high-speed set."),
    feed: float = typer.Option(200.0, "--feed", help="Maximum (programmed) feed, mm/s."),
    seed: int = typer.Option(1, "--seed", help="Random seed; the same seed gives the same programs."),
    distribution: str = typer.Option("uniform", "--distribution", help="High-speed targets: uniform (thesis Table 3.2) or loguniform step lengths."),
    dialect: str = typer.Option("iso", "--dialect", help="iso, heidenhain or linuxcnc."),
    toolpath: Optional[str] = typer.Option(None, "--toolpath", help="Write a validation contour instead: circle or diamond."),
    size: float = typer.Option(20.0, "--size", help="Contour size, mm (circle diameter; diamond vertex-to-vertex)."),
    blending: bool = typer.Option(False, "--blending", help="Write path blending (G64 P0.01) instead of exact stop (G61; G61.1 in LinuxCNC)."),
    out: Path = typer.Option(Path("."), "-o", "--out", help="Output directory (created if missing)."),
) -> None:
    """Write identification programs (low- and high-speed sets) or a validation contour."""
    dialect = dialect.strip().lower()
    if dialect not in dialects.DIALECTS:
        raise InputError(f"unknown dialect {dialect!r} (use one of {', '.join(dialects.DIALECTS)})")
    if not math.isfinite(feed) or feed <= 0:
        raise InputError(f"--feed must be a positive number of mm/s, got {feed}")
    centers = _floats(center, "--center")
    if toolpath is not None:
        kind = toolpath.strip().lower()
        if kind not in TOOLPATHS:
            raise InputError(f"unknown toolpath {toolpath!r} (use circle or diamond)")
        ax = _axes(axes or "X,Y")
        if len(centers) == 1:
            centers = centers * 2
        programs = [TOOLPATHS[kind](size=size, feed=feed, center=centers, axes=ax)]
    else:
        ax = _axes(axes or "X")
        if len(centers) not in (1, len(ax)):
            raise InputError(f"--center has {len(centers)} values for {len(ax)} axes")
        programs = list(identification_programs(
            axes=ax, center=centers, range_mm=range_mm, low_step=low_step,
            n_low=n_low, n_high=n_high, feed=feed, seed=seed, distribution=distribution,
        ))
    if blending:
        programs = [replace(tp, blending=True) for tp in programs]
    if out.exists() and not out.is_dir():
        raise InputError(f"output {out} exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
        for tp in programs:
            print(dialects.save(tp, dialect, out))
    except OSError as exc:
        raise InputError(f"cannot write to {out}: {exc.strerror or exc}") from exc

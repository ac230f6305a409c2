"""``generate``: the identification programs or a validation contour, ready to save or simulate.

What ``agent generate`` writes, as a function: :func:`generate` returns the
:class:`Toolpath` s, :func:`save_programs` writes them in a dialect.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Sequence

from core.errors import InputError
from gcode_gen.dialects import DIALECTS, save
from gcode_gen.excitation import identification_programs
from gcode_gen.program import Toolpath
from gcode_gen.toolpaths import TOOLPATHS

__all__ = ["generate", "save_programs"]


def generate(
    axes: Sequence[str] | None = None,
    *,
    center: Sequence[float] = (0.0,),
    range_mm: float = 10.0,
    low_step: float = 0.03,
    n_low: int = 200,
    n_high: int = 200,
    feed: float = 200.0,
    seed: int = 1,
    distribution: str = "uniform",
    toolpath: str | None = None,
    size: float = 20.0,
    blending: bool = False,
    direction: str = "ccw",
    start_deg: float = 0.0,
) -> list[Toolpath]:
    """The identification set (low- then high-speed program) or one validation contour.

    Parameters
    ----------
    axes : axis letters; default ``X`` (``X, Y`` for a toolpath).
    center : centre of the travel range, mm: one value or one per axis.
    range_mm : half-width of the travel range, mm; no target leaves centre ± range.
    low_step : largest step of the low-speed set, mm.
    n_low, n_high : number of moves in the low- and high-speed sets.
    feed : maximum (programmed) feed, mm/s.
    seed : random seed; the same seed gives the same programs.
    distribution : high-speed targets, ``uniform`` (thesis Table 3.2) or ``loguniform`` steps.
    toolpath : ``circle`` or ``diamond`` for a validation contour instead.
    size : contour size, mm (circle diameter; diamond vertex to vertex).
    blending : path blending (G64) instead of exact stop.
    direction : a contour's sense, ``ccw``, ``cw`` or ``both`` (two programs, ``<toolpath>_ccw`` and
        ``<toolpath>_cw``: the ballbar test's pair).
    start_deg : where a circle starts and ends, degrees from the first axis (45 for a ballbar test).
    """
    centers = [float(c) for c in center]
    if toolpath is not None:
        kind = toolpath.strip().lower()
        if kind not in TOOLPATHS:
            raise InputError.about("toolpath", f"unknown toolpath {toolpath!r} (use circle or diamond)")
        ax = [a.upper() for a in (axes or ("X", "Y"))]
        if len(centers) == 1:
            centers = centers * 2
        senses = ("ccw", "cw") if direction == "both" else (direction,)
        if any(d not in ("ccw", "cw") for d in senses):
            raise InputError.about("direction", f"direction {direction!r}: ccw, cw or both")
        extra = {"start_deg": start_deg} if kind == "circle" else {}
        programs = [TOOLPATHS[kind](size=size, feed=feed, center=centers, axes=ax, direction=d,
                                    name=f"{kind}_{d}" if len(senses) > 1 else kind, **extra) for d in senses]
    else:
        ax = [a.upper() for a in (axes or ("X",))]
        if len(centers) not in (1, len(ax)):
            raise InputError.about("center", f"center has {len(centers)} values for {len(ax)} axes")
        programs = list(identification_programs(
            axes=ax, center=centers, range_mm=range_mm, low_step=low_step,
            n_low=n_low, n_high=n_high, feed=feed, seed=seed, distribution=distribution,
        ))
    if blending:
        programs = [replace(tp, blending=True) for tp in programs]
    return programs


def save_programs(programs: Sequence[Toolpath], dialect: str, directory: str | Path) -> list[Path]:
    """Write each program in ``dialect`` (iso, heidenhain, linuxcnc) into ``directory``; the paths."""
    dialect = dialect.strip().lower()
    if dialect not in DIALECTS:
        raise InputError.about("dialect", f"unknown dialect {dialect!r} (use one of {', '.join(DIALECTS)})")
    out = Path(directory)
    if out.exists() and not out.is_dir():
        raise InputError.about("out", f"{out} exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
        return [save(tp, dialect, out) for tp in programs]
    except OSError as exc:
        raise InputError.about("out", f"cannot write to {out}: {exc.strerror or exc}") from exc

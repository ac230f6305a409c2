"""Validation contours on two axes: circle (G02/G03) and diamond (thesis §4.3.3, Figs. 4.9-4.10).

The identified drive models are checked by predicting the tracking and contouring errors
of contours the machine runs at a given feed (200 mm/s in the thesis).  Both contours fit
in a square of side ``size`` centred on ``center``:

* ``circle``: diameter ``size``; a rapid to the start point (centre + radius at
  ``start_deg``, 0° = along the first axis), then one full circle (G03 counter-clockwise
  or G02 clockwise, I/J centre offsets; ``CC``/``C DR±`` in Heidenhain), ending where it
  began.  The synthetic ballbar starts at 45° so that the exact-stop start and end of the
  circle fall between the four axis reversals (0°, 90°, 180°, 270°).
* ``diamond``: a square rotated 45°, vertices at centre ± size/2 on each axis; a rapid to
  the right-hand vertex, then four G01 sides counter-clockwise (or clockwise).

After the positioning rapid both dwell ``settle_s`` (G04) so the contour starts with the
drives at rest: its errors are then the contour's own, not the rapid's settling.
"""

from __future__ import annotations

import math
from typing import Sequence

from core.errors import InputError
from gcode_gen.program import AXIS_LETTERS, Block, Toolpath

__all__ = ["circle", "diamond", "TOOLPATHS"]

GENERATOR = "rapid-ident gcode_gen.toolpaths 1"


def _check(kind: str, size: float, feed: float, center: Sequence[float], axes: Sequence[str], direction: str) -> None:
    if not math.isfinite(size) or size <= 0:
        raise InputError(f"{kind} size must be a positive number of mm, got {size}")
    if not math.isfinite(feed) or feed <= 0:
        raise InputError(f"feed must be a positive number of mm/s, got {feed}")
    if len(axes) != 2 or len(set(axes)) != 2:
        raise InputError(f"a {kind} needs two different axes, got {','.join(axes)}")
    if tuple(axes) != ("X", "Y"):
        # Arcs are interpreted in the XY plane (G17) only; keep both contours consistent.
        raise InputError(f"validation contours run in the XY plane, got axes {','.join(axes)}")
    for ax in axes:
        if ax not in AXIS_LETTERS:
            raise InputError(f"unknown axis letter {ax!r}")
    if len(center) != 2 or not all(math.isfinite(c) for c in center):
        raise InputError(f"{kind} centre needs two finite values (mm), got {tuple(center)}")
    if direction not in ("ccw", "cw"):
        raise InputError(f"direction must be ccw or cw, got {direction!r}")


def _header(kind: str, size: float, feed: float, center: Sequence[float], axes: Sequence[str], direction: str,
            settle_s: float, **extra: float) -> dict[str, str]:
    return {
        "generator": GENERATOR,
        "program": f"validation {kind}",
        "toolpath": kind,
        "axes": ",".join(axes),
        "center": ",".join(format(float(c), ".12g") for c in center),
        "size": format(float(size), ".12g"),
        "feed": format(float(feed), ".12g"),
        "feed_units": "mm/s",
        "direction": direction,
        "settle_s": format(float(settle_s), ".12g"),
        **{k: format(float(v), ".12g") for k, v in extra.items()},
    }


def _settle(settle_s: float) -> tuple[Block, ...]:
    if not math.isfinite(settle_s) or settle_s < 0:
        raise InputError(f"settle time must be >= 0 s, got {settle_s}")
    return (Block(line=0, n=None, motion="G4", dwell_s=float(settle_s)),) if settle_s > 0 else ()


def _q(x: float, decimals: int) -> float:
    return round(float(x), decimals)


def circle(
    size: float = 20.0,
    feed: float = 200.0,
    center: Sequence[float] = (0.0, 0.0),
    axes: Sequence[str] = ("X", "Y"),
    direction: str = "ccw",
    name: str = "circle",
    decimals: int = 4,
    start_deg: float = 0.0,
    settle_s: float = 0.2,
) -> Toolpath:
    """A full circle of diameter ``size`` mm at ``feed`` mm/s around ``center`` (mm).

    ``direction`` "ccw" writes G03 (Heidenhain DR+), "cw" writes G02 (DR-); the circle
    starts and ends at ``start_deg`` (degrees from the first axis, counter-clockwise).
    """
    axes = tuple(a.upper() for a in axes)
    _check("circle", size, feed, center, axes, direction)
    if not math.isfinite(start_deg):
        raise InputError(f"start angle must be a number of degrees, got {start_deg}")
    cx, cy = (_q(c, decimals) for c in center)
    r = _q(size / 2.0, decimals)
    if r <= 0:
        raise InputError(f"circle size {size} mm is below the output resolution")
    phi = math.radians(start_deg)
    start = {axes[0]: _q(cx + r * math.cos(phi), decimals), axes[1]: _q(cy + r * math.sin(phi), decimals)}
    blocks = (
        Block(line=0, n=None, motion="G0", target=dict(start)),
        *_settle(settle_s),
        Block(line=1, n=None, motion="G3" if direction == "ccw" else "G2", target=dict(start),
              feed=float(feed), center={axes[0]: cx, axes[1]: cy}),
    )
    extra = {"start_deg": start_deg} if start_deg else {}
    return Toolpath(name=name, blocks=blocks, decimals=decimals,
                    header=_header("circle", size, feed, center, axes, direction, settle_s, **extra))


def diamond(
    size: float = 20.0,
    feed: float = 200.0,
    center: Sequence[float] = (0.0, 0.0),
    axes: Sequence[str] = ("X", "Y"),
    direction: str = "ccw",
    name: str = "diamond",
    decimals: int = 4,
    settle_s: float = 0.2,
) -> Toolpath:
    """A diamond (square turned 45°) with vertices at ``center`` ± ``size``/2 mm, at ``feed`` mm/s."""
    axes = tuple(a.upper() for a in axes)
    _check("diamond", size, feed, center, axes, direction)
    cx, cy = (_q(c, decimals) for c in center)
    h = _q(size / 2.0, decimals)
    if h <= 0:
        raise InputError(f"diamond size {size} mm is below the output resolution")
    a, b = axes
    right, top, left, bottom = ((cx + h, cy), (cx, cy + h), (cx - h, cy), (cx, cy - h))
    corners = [top, left, bottom, right] if direction == "ccw" else [bottom, left, top, right]
    blocks = [Block(line=0, n=None, motion="G0", target={a: _q(right[0], decimals), b: _q(right[1], decimals)}),
              *_settle(settle_s)]
    for k, (x, y) in enumerate(corners, start=1):
        blocks.append(Block(line=k, n=None, motion="G1", target={a: _q(x, decimals), b: _q(y, decimals)}, feed=float(feed)))
    return Toolpath(name=name, blocks=tuple(blocks), decimals=decimals,
                    header=_header("diamond", size, feed, center, axes, direction, settle_s))


#: name -> generator function, for the CLI.
TOOLPATHS = {"circle": circle, "diamond": diamond}

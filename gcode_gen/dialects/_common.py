"""Number formatting shared by the dialect writers."""

from __future__ import annotations

import math

from core.errors import InputError


def coord(value: float, decimals: int, *, plus: bool = False) -> str:
    """A coordinate in mm with ``decimals`` places; ``plus`` writes an explicit + (Heidenhain)."""
    text = f"{value:.{decimals}f}"
    if text.lstrip("-").strip("0.") == "":
        text = f"{0.0:.{decimals}f}"  # no "-0.0000"
    if plus and not text.startswith("-"):
        text = "+" + text
    return text


def feed_per_min(feed_mm_s: float) -> str:
    """Feed in mm/min for an ``F`` word, rounded *down* to 0.001 so it never exceeds the feed."""
    f = math.floor(feed_mm_s * 60.0 * 1000.0 + 1e-6) / 1000.0
    if f <= 0:
        raise InputError(f"feed {feed_mm_s} mm/s is below the 0.001 mm/min resolution")
    return str(int(f)) if float(f).is_integer() else f"{f:.3f}".rstrip("0")


def header_comment(key: str, value: str) -> str:
    """``key=value`` with characters that would end a comment replaced."""
    value = str(value).replace("(", "[").replace(")", "]").replace(";", ",")
    return f"{key}={value}"


def header_items(toolpath, dialect: str) -> list[tuple[str, str]]:  # noqa: ANN001
    """The toolpath header plus the dialect and path-mode entries the writer adds."""
    items = list(toolpath.header.items())
    items.append(("dialect", dialect))
    items.append(("blending", "1" if toolpath.blending else "0"))
    return items

"""Common writer for the two RS274 (G-code word address) dialects, ISO and LinuxCNC."""

from __future__ import annotations

from core.errors import InputError
from gcode_gen.dialects._common import coord, feed_per_min, header_comment, header_items
from gcode_gen.program import PLANE_CODES, Toolpath

BLEND_TOLERANCE_MM = 0.01  # G64 P tolerance written when blending is asked
_OFFSET_WORD = {"X": "I", "Y": "J", "Z": "K"}


def write_rs274(
    toolpath: Toolpath,
    *,
    dialect: str,
    numbered: bool,
    two_digit: bool,
    preamble: list[str],
    exact_stop: str,
    end: str,
) -> str:
    """Program text; ``numbered`` adds N0000, N0010, …; ``two_digit`` writes G00 instead of G0;
    ``exact_stop`` is the dialect's exact-stop mode code (written unless blending)."""
    d = toolpath.decimals
    lines: list[str] = ["%", f"({toolpath.name})"]
    lines += [f"({header_comment(k, v)})" for k, v in header_items(toolpath, dialect)]
    body: list[str] = list(preamble)
    body.append(f"G64 P{BLEND_TOLERANCE_MM}" if toolpath.blending else exact_stop)
    last_feed: float | None = None
    pos: dict[str, float] = {}  # current position, for the arc I/J/K offsets (relative to the arc start)
    plane = "XY"  # the preamble's G17
    for b in toolpath.blocks:
        g = b.motion if not two_digit else f"G{int(b.motion[1:]):02d}"
        words = [g]
        if b.motion == "G4":
            if b.dwell_s is None or b.dwell_s < 0:
                raise InputError(f"dwell block without a non-negative time in {toolpath.name}")
            # ISO/Fanuc G04 X is seconds; LinuxCNC G4 P is seconds.
            words.append(("P" if dialect == "linuxcnc" else "X") + f"{b.dwell_s:.3f}")
        else:
            words += [f"{ax}{coord(v, d)}" for ax, v in b.target.items()]
            if b.motion in ("G2", "G3"):
                if b.center is None:
                    raise InputError(f"arc block without a centre in {toolpath.name}")
                if any(a not in pos for a in b.center):
                    raise InputError(f"arc in {toolpath.name} starts from an unknown position")
                if b.plane != plane:
                    words.insert(0, PLANE_CODES[b.plane])
                    plane = b.plane
                # I, J, K: the centre's offset from the arc's start along X, Y, Z, in any plane
                words += [f"{_OFFSET_WORD[a]}{coord(b.center[a] - pos[a], d)}" for a in ("X", "Y", "Z")
                          if a in b.center]
            pos.update(b.target)
            if b.motion != "G0" and b.feed is not None and b.feed != last_feed:
                words.append(f"F{feed_per_min(b.feed)}")
                last_feed = b.feed
        body.append(" ".join(words))
    body.append(end)
    if numbered:
        width = max(4, len(str(10 * (len(body) - 1))))
        body = [f"N{10 * k:0{width}d} {text}" for k, text in enumerate(body)]
    lines += body
    lines.append("%")
    return "\n".join(lines) + "\n"

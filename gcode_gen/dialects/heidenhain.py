"""Heidenhain TNC conversational (Klartext) writer, as thesis Tables 4.3/4.4.

Layout (every line carries its block number, starting at 0, as on the TNC)::

    0 BEGIN PGM ident_low MM
    1 ; generator=rapid-ident ...        <- header, one ``key=value`` per comment line
    ...
    k L X+0.0000 R0 FMAX                 <- rapid to the start point
    k L X+0.0123 R0 F12000               <- F in mm/min, modal; FMAX is blockwise
    k L X-0.0050
    k CC X+0.0000 Y+0.0000               <- arc centre (circle pole)
    k C X+10.0000 Y+0.0000 DR+ F12000    <- arc to end point, DR+ counter-clockwise
    k M30
    k END PGM ident_low MM

Dwells use cycle 9 (``CYCL DEF 9.0 DWELL TIME`` / ``CYCL DEF 9.1 DWELL 1.5``).  No tool
call, spindle or coolant words are written (a ``TOOL CALL`` could start a tool change);
the TNC's own path mode applies, so ``blending`` is recorded in the header only.
"""

from __future__ import annotations

import re

from core.errors import InputError
from gcode_gen.dialects._common import coord, feed_per_min, header_comment, header_items
from gcode_gen.program import Toolpath

__all__ = ["write", "pgm_name"]


def pgm_name(name: str) -> str:
    """A TNC program name: letters, digits and underscores only."""
    clean = re.sub(r"[^A-Za-z0-9_]", "_", name)
    if not clean:
        raise InputError(f"program name {name!r} has no usable character")
    return clean


def write(toolpath: Toolpath) -> str:
    """Heidenhain conversational text of ``toolpath``."""
    d = toolpath.decimals
    name = pgm_name(toolpath.name)
    body: list[str] = [f"BEGIN PGM {name} MM"]
    body += [f"; {header_comment(k, v)}" for k, v in header_items(toolpath, "heidenhain")]
    last_feed: float | None = None
    first_move = True
    for b in toolpath.blocks:
        if b.motion == "G4":
            if b.dwell_s is None or b.dwell_s < 0:
                raise InputError(f"dwell block without a non-negative time in {toolpath.name}")
            body += ["CYCL DEF 9.0 DWELL TIME", f"CYCL DEF 9.1 DWELL {b.dwell_s:.3f}"]
            continue
        xyz = " ".join(f"{ax}{coord(v, d, plus=True)}" for ax, v in b.target.items())
        if b.motion in ("G2", "G3"):
            if b.center is None:
                raise InputError(f"arc block without a centre in {toolpath.name}")
            if b.plane != "XY":  # the working plane follows the TOOL CALL's axis, which we do not write
                raise InputError(f"{toolpath.name}: the Heidenhain writer writes arcs in the XY plane only, "
                                 f"this one lies in {b.plane}; write it in the iso or linuxcnc dialect")
            body.append("CC " + " ".join(f"{ax}{coord(v, d, plus=True)}" for ax, v in b.center.items()))
            words = ["C", xyz, "DR+" if b.motion == "G3" else "DR-"]
        else:
            words = ["L", xyz]
            if first_move:
                words.append("R0")  # no radius compensation, stated once as in Table 4.3
                first_move = False
        if b.motion == "G0":
            words.append("FMAX")
        elif b.feed is not None and b.feed != last_feed:
            words.append(f"F{feed_per_min(b.feed)}")
            last_feed = b.feed
        body.append(" ".join(words))
    body.append("M30")
    body.append(f"END PGM {name} MM")
    return "\n".join(f"{k} {text}" for k, text in enumerate(body)) + "\n"

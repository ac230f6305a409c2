"""Canned cycles G73, G81–G83, G85, G86, G89 in the XY plane, expanded into moves.

The expansion is LinuxCNC's (interp_cycles.cc, ``convert_cycle_xy`` and ``CYCLE_MACRO``),
in program coordinates of the active system:

* the first block of a series needs Z and R; R, Z, P, Q then stay (sticky), L does not;
* G90: X, Y, R, Z absolute; G91: X, Y increments per repeat, R from the current Z, Z from R;
  polar ``@``/``^`` in G91 add a radius/an angle about the origin per repeat;
* if the current Z is below R, first a rapid up to R;
* the retract height is R (G99) or the initial level (G98: the Z where the series of cycle
  blocks began, or R when that is higher); G91 R is relative to the initial level;
* each of the L repeats: rapid in XY — the first from above R at the current height, the
  others at the retract height — and down to R, then the cycle: G81 feed to Z, rapid out; G82 the same with a dwell P at the bottom;
  G73 pecks of Q with a rapid back-off of 0.010 in (0.254 mm); G83 pecks of Q, rapid out to
  R and back down to 0.010 in above the last depth; G85 feed in, feed out to R, rapid to the retract height;
  G86 feed in, dwell P, rapid out (spindle stopped); G89 feed in, dwell P, feed out.

G84 (tapping), G87 (back boring) and G88 (manual retract) need the spindle or the
operator and are refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["CycleMove", "CycleState", "expand_cycle", "SUPPORTED_CYCLES", "G83_RAPID_DELTA_IN"]

SUPPORTED_CYCLES = ("G73", "G81", "G82", "G83", "G85", "G86", "G89")
#: Back-off of G73/G83 pecks, inch (LinuxCNC's G83_RAPID_DELTA).
G83_RAPID_DELTA_IN = 0.010


@dataclass(frozen=True)
class CycleMove:
    """One move of an expanded cycle: kind "G0", "G1" or "G4"; x, y, z in program units."""

    kind: str
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    dwell_s: float = 0.0


@dataclass
class CycleState:
    """The sticky cycle words (program units / s): R, Z, P, Q; the initial level and the
    cycle of the current series (None when the last motion mode was not a cycle)."""

    r: float | None = None
    z: float | None = None
    p: float | None = None
    q: float | None = None
    initial: float | None = None
    series: str | None = None


def expand_cycle(motion: str, first: bool, words: dict[str, float], state: CycleState, current: tuple[float, float, float],
                 incremental: bool, g98: bool, inch: bool, error) -> tuple[list[CycleMove], tuple[float, float, float]]:  # noqa: ANN001
    """Moves of one cycle block and the end position (program coordinates).

    ``words`` holds the block's values (lower-case letters; ``@``/``^`` the polar radius and
    angle increments, G91 only); ``current`` the position before it.  The initial level
    (``state.initial``, the G98 retract height and the G91 base of R) is the Z where the
    series of cycle blocks started (LinuxCNC's ``cycle_il``).
    """
    if state.series is None:  # a new series: its initial level is here
        state.initial = current[2]
    x0, y0, z0 = current
    if first and "z" not in words:
        raise error(f"{motion} canned cycle without Z (the first block of a cycle series needs Z)")
    if "r" in words:
        state.r = words["r"]
    if state.r is None:
        raise error(f"{motion} canned cycle without R (the retract plane)")
    if "z" in words:
        state.z = words["z"]
    if motion in ("G82", "G86", "G89"):
        if "p" in words:
            state.p = words["p"]
        elif first or state.p is None:
            raise error(f"{motion} canned cycle without a dwell time P")
    if motion in ("G73", "G83"):
        if "q" in words:
            state.q = words["q"]
        elif first or state.q is None:
            raise error(f"{motion} canned cycle without a peck depth Q")
        if state.q <= 0:
            raise error(f"{motion} peck depth Q{state.q:g} must be positive")
    repeats = words.get("l", 1.0)
    if repeats != int(repeats) or repeats < 0:
        raise error(f"L{repeats:g}: the number of repeats must be a whole number >= 0")
    old_cc = state.initial
    current_cc = z0
    if incremental:
        r = state.r + old_cc
        cc = r + state.z
        aa, bb = x0, y0
        da, db = words.get("x", 0.0), words.get("y", 0.0)
    else:
        r, cc = state.r, state.z
        aa, bb = words.get("x", x0), words.get("y", y0)
        da = db = 0.0
    if r < cc:
        raise error(f"{motion}: the R plane {r:g} is below the bottom Z {cc:g}")
    moves: list[CycleMove] = []
    if old_cc < r:
        moves.append(CycleMove("G0", x0, y0, r))
        old_cc = current_cc = r
    clear_cc = old_cc if g98 else r
    delta = G83_RAPID_DELTA_IN * (1.0 if inch else 25.4)
    dr, dtheta = words.get("@", 0.0), math.radians(words.get("^", 0.0))
    for k in range(int(repeats)):
        aa, bb = aa + da, bb + db
        if dr or dtheta:
            if aa == 0 and bb == 0:
                raise error("incremental polar motion is undefined at the origin")
            radius, theta = math.hypot(aa, bb) + dr, math.atan2(bb, aa) + dtheta
            aa, bb = radius * math.cos(theta), radius * math.sin(theta)
        if k == 0 and current_cc > r:  # from above R: across at the current height, down to R
            moves += [CycleMove("G0", aa, bb, current_cc), CycleMove("G0", aa, bb, r)]
        else:  # otherwise across at the retract height (then down to R)
            moves.append(CycleMove("G0", aa, bb, clear_cc))
            if clear_cc > r:
                moves.append(CycleMove("G0", aa, bb, r))
        moves.extend(_cycle_body(motion, aa, bb, r, clear_cc, cc, state, delta))
    return moves, (aa, bb, clear_cc)


def _cycle_body(motion: str, x: float, y: float, r: float, clear: float, bottom: float, state: CycleState,
                delta: float) -> list[CycleMove]:
    feed = lambda z: CycleMove("G1", x, y, z)  # noqa: E731
    rapid = lambda z: CycleMove("G0", x, y, z)  # noqa: E731
    if motion == "G81":
        return [feed(bottom), rapid(clear)]
    if motion == "G82":
        return [feed(bottom), CycleMove("G4", dwell_s=state.p), rapid(clear)]
    if motion in ("G73", "G83"):
        out: list[CycleMove] = []
        depth = r - state.q
        while depth > bottom:
            out.append(feed(depth))
            if motion == "G83":
                out.append(rapid(r))
            out.append(rapid(depth + delta))
            depth -= state.q
        return out + [feed(bottom), rapid(clear)]
    if motion == "G85":
        return [feed(bottom), feed(r), rapid(clear)]
    if motion == "G86":
        return [feed(bottom), CycleMove("G4", dwell_s=state.p), rapid(clear)]
    if motion == "G89":
        return [feed(bottom), CycleMove("G4", dwell_s=state.p), feed(clear)]
    raise AssertionError(motion)

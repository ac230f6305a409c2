"""The G- and M-codes of one block: which are known, refused, and in which modal group.

:func:`split_block` sorts a block's evaluated words into G-codes, M-codes and the other
values and checks them the way LinuxCNC does before anything runs: one code per modal
group (M7 with M8 is allowed), one motion code, one non-modal code (G53 may join one),
each other letter at most once, M-codes whole numbers; unsupported codes are refused by
name (splines, probing, lathe cycles, user M-codes M100–M199 …).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["BlockCodes", "split_block", "COORD_SYSTEMS", "MOTION", "CodeError"]


class CodeError(Exception):
    """A block's codes are wrong or unsupported; the caller adds the line."""


COORD_SYSTEMS = {54.0: 1, 55.0: 2, 56.0: 3, 57.0: 4, 58.0: 5, 59.0: 6, 59.1: 7, 59.2: 8, 59.3: 9}
MOTION = {0.0: "G0", 1.0: "G1", 2.0: "G2", 3.0: "G3", 73.0: "G73", 80.0: "G80", 81.0: "G81", 82.0: "G82",
           83.0: "G83", 84.0: "G84", 85.0: "G85", 86.0: "G86", 87.0: "G87", 88.0: "G88", 89.0: "G89"}
#: G-codes that only set a mode this interpreter does not need (or that is its only mode).
_NO_EFFECT_G = {40.0, 94.0, 97.0, 96.0}
#: M-codes without motion: stops, spindle, coolant, overrides, digital/analog I/O.
_NO_MOTION_M = {0, 1, 3, 4, 5, 7, 8, 9, 48, 49, 50, 51, 52, 53, 60, 62, 63, 64, 65}
#: LinuxCNC's modal groups (one code of each per block); motion and non-modal are checked apart.
_MODAL_GROUPS = (
    {17.0, 18.0, 19.0, 17.1, 18.1, 19.1}, {90.0, 91.0}, {90.1, 91.1}, {93.0, 94.0, 95.0}, {20.0, 21.0},
    {40.0, 41.0, 42.0, 41.1, 42.1}, {43.0, 43.1, 43.2, 49.0}, {98.0, 99.0}, set(COORD_SYSTEMS),
    {61.0, 61.1, 64.0}, {96.0, 97.0}, {7.0, 8.0},
)
_M_GROUPS = ({0, 1, 2, 30, 60}, {6, 61}, {3, 4, 5}, {7, 8, 9}, {48, 49, 50, 51, 52, 53}, {70, 71, 72, 73})
_REFUSED_G = {
    5.0: "cubic spline G5", 5.1: "quadratic B-spline G5.1", 5.2: "NURBS G5.2", 5.3: "NURBS G5.3",
    7.0: "lathe diameter mode G7", 8.0: "lathe radius mode G8", 33.0: "spindle-synchronised motion G33",
    33.1: "rigid tapping G33.1", 38.2: "probing G38.2", 38.3: "probing G38.3", 38.4: "probing G38.4",
    38.5: "probing G38.5", 41.1: "dynamic cutter compensation G41.1", 42.1: "dynamic cutter compensation G42.1",
    43.2: "additional tool length offset G43.2", 70.0: "lathe finishing cycle G70", 71.0: "lathe roughing cycle G71",
    72.0: "lathe roughing cycle G72", 74.0: "left-hand tapping G74", 76.0: "lathe threading cycle G76",
    84.0: "tapping cycle G84", 87.0: "back-boring cycle G87", 88.0: "manual-retract boring cycle G88",
    95.0: "feed per revolution G95", 52.0: "local offset G52",
}


_NON_MODAL = (4.0, 10.0, 28.0, 28.1, 30.0, 30.1, 53.0, 92.0, 92.1, 92.2, 92.3)
_OTHER_G = {17.0, 18.0, 19.0, 20.0, 21.0, 41.0, 42.0, 43.0, 43.1, 49.0, 61.0, 61.1, 64.0, 90.0, 91.0, 90.1, 91.1,
            93.0, 98.0, 99.0}
_KNOWN_M = _NO_MOTION_M | {2, 30, 6, 61, 70, 71, 72, 73, 66, 67, 68, 19}


@dataclass
class BlockCodes:
    """G-codes (rounded to 0.1), M-codes, the other words by lower-case letter, and the
    motion code of the block (or None)."""

    gs: list[float]
    ms: list[int]
    vals: dict[str, float]
    motion: str | None


def split_block(words: list[tuple[str, float]]) -> BlockCodes:
    """Sort and check one block's evaluated words (letters lower case)."""
    gs: list[float] = []
    ms: list[int] = []
    vals: dict[str, float] = {}
    for letter, value in words:
        if letter == "g":
            gs.append(round(value, 1))
        elif letter == "m":
            if value != int(value):
                raise CodeError(f"M{value:g}: M-codes are whole numbers")
            ms.append(int(value))
        else:
            if letter in vals:
                raise CodeError(f"word {letter.upper()} appears twice in one block")
            vals[letter] = value
    for g in gs:
        if g in _REFUSED_G:
            raise CodeError(f"{_REFUSED_G[g]} is not supported")
    for m in ms:
        if 100 <= m <= 199:
            raise CodeError(f"user-defined M-code M{m} is not supported (it runs an external program)")
        if m in (98, 99):
            raise CodeError(f"Fanuc subprogram call M{m} is not supported (use O-word subroutines)")
        if m not in _NO_MOTION_M and m not in (2, 30, 6, 61, 70, 71, 72, 73, 66, 67, 68, 19):
            raise CodeError(f"unknown or unsupported M-code M{m}")

    for group in _MODAL_GROUPS:
        same = [g for g in gs if g in group]
        if len(same) > 1:
            raise CodeError(f"two G-codes of one modal group in a block: G{same[0]:g} and G{same[1]:g}")
    for group in _M_GROUPS:
        same = [m for m in ms if m in group]
        if len(same) > 1 and set(same) != {7, 8}:
            raise CodeError(f"two M-codes of one modal group in a block: M{same[0]} and M{same[1]}")
    motions = [g for g in gs if g in MOTION]
    non_modal = [g for g in gs if g in _NON_MODAL]
    if len(motions) > 1:
        raise CodeError("two motion G-codes in one block")
    if len([g for g in non_modal if g != 53.0]) > 1:
        raise CodeError("two non-modal G-codes (G4, G10, G28, G30, G92…) in one block")
    known = set(MOTION) | set(non_modal) | _NO_EFFECT_G | set(COORD_SYSTEMS) | _OTHER_G
    for g in gs:
        if g not in known:
            raise CodeError(f"unknown or unsupported G-code G{g:g}")
    return BlockCodes(gs, ms, vals, MOTION[motions[0]] if motions else None)

"""LinuxCNC INI: the pid gains of each joint, and the exact lines a tuning changes.

A LinuxCNC machine's position loops are its ``pid`` instances, whose gains the HAL file
sets from ``[JOINT_n]`` (``setp pid.x.Pgain [JOINT_0]P`` …, fixtures/linuxcnc/machine.hal):
P, I, D, FF0, FF1, FF2, BIAS, DEADBAND, BACKLASH, MAX_OUTPUT.  Joint n drives the axis
letter at position n of ``[TRAJ]COORDINATES`` (trivkins' identity mapping).  The tuner
only reads the file; :func:`ini_diff` is the unified diff a user applies by hand.
"""

from __future__ import annotations

import difflib
import math
from pathlib import Path
from typing import Mapping

from core.errors import InputError
from core.linuxcnc_ini import KEY_LINE, joint_unit, sections
from ident.tuning.controllers import GAIN_NAMES, Gains

__all__ = ["read_joint_gains", "ini_diff", "format_value", "in_mm", "in_machine_units"]

#: The power of the length unit in each pid gain: a gain per unit of error (P, I, D and the
#: feed-forwards, per unit of command) scales as 1/length, a length (DEADBAND, BACKLASH) as
#: length; BIAS and MAX_OUTPUT are in the output's units.
_LENGTH_POWER = {"P": -1, "I": -1, "D": -1, "FF0": -1, "FF1": -1, "FF2": -1, "DEADBAND": 1, "BACKLASH": 1,
                 "BIAS": 0, "MAX_OUTPUT": 0}


def in_mm(g: Gains, mm: float) -> Gains:
    """LinuxCNC pid gains of a joint whose unit is ``mm`` mm (25.4: inch) → the same gains per mm."""
    return Gains(g.form, {k: v * mm ** _LENGTH_POWER[k] for k, v in g.values.items()}, g.u_max)


def in_machine_units(g: Gains, mm: float) -> Gains:
    """The inverse of :func:`in_mm`: gains per mm → per machine unit of ``mm`` mm."""
    return in_mm(g, 1.0 / mm)

def read_joint_gains(path: str | Path, axes: list[str]) -> dict[str, tuple[int, Gains, float]]:
    """{axis: (joint number, Gains("linuxcnc-pid"), mm per unit)} for the ``axes`` of a result,
    from the INI.  The gains are as the INI gives them, per machine unit: ``[TRAJ]
    LINEAR_UNITS`` for a linear joint (mm per unit 25.4 on an inch machine), degrees for a
    joint of ``TYPE = ANGULAR`` (1); :func:`in_mm` converts them."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise InputError.about("ini", f"{path}: cannot read ({exc.strerror or exc})") from None
    secs = sections(lines)
    coords = (secs.get("TRAJ", {}).get("COORDINATES", (0, ""))[1]).replace(" ", "").upper()
    if not coords:
        raise InputError.about("ini", f"{path}: no [TRAJ]COORDINATES: which joint drives which axis?")
    out = {}
    for a in axes:
        if a not in coords:
            raise InputError.about("ini", f"{path}: axis {a} is not in [TRAJ]COORDINATES = {coords}")
        j = coords.index(a)
        sec = secs.get(f"JOINT_{j}")
        if sec is None:
            raise InputError.about("ini", f"{path}: no [JOINT_{j}] section for axis {a}")
        vals = {}
        for k in GAIN_NAMES["linuxcnc-pid"]:
            if k in sec:
                try:
                    vals[k] = float(sec[k][1])
                except ValueError:
                    raise InputError.about("ini", f"{path}:{sec[k][0] + 1}: [JOINT_{j}]{k} = {sec[k][1]!r} "
                                                  f"is not a number") from None
        if "P" not in vals:
            raise InputError.about("ini", f"{path}: [JOINT_{j}] has no P gain (is the loop a pid?)")
        mo = vals.get("MAX_OUTPUT", 0.0)
        out[a] = (j, Gains("linuxcnc-pid", vals, u_max=mo if mo > 0 else math.inf), joint_unit(secs, j, path)[0])
    return out


def format_value(v: float) -> str:
    """A gain as written to the INI: 6 significant digits, no exponent for ordinary sizes."""
    if v == 0:
        return "0.0"
    text = f"{v:.6g}"
    return text if ("e" in text or "." in text) else text + ".0"


def ini_diff(path: str | Path, changes: Mapping[int, Mapping[str, float]]) -> list[str]:
    """Unified diff lines (``---``/``+++``/``@@``/``-``/``+``) setting ``changes`` {joint: {KEY: value}}.

    A key missing from its section is added after the section's last key.
    """
    path = Path(path)
    lines = path.read_text().splitlines()
    new = list(lines)
    secs = sections(lines)
    inserts: dict[int, list[str]] = {}
    for j, kv in sorted(changes.items()):
        sec = secs.get(f"JOINT_{j}", {})
        last = max((i for i, _ in sec.values()), default=None)
        for k, v in kv.items():
            if k in sec:
                i = sec[k][0]
                m = KEY_LINE.match(lines[i])
                new[i] = f"{m.group(1)}{k}{m.group(3)}{format_value(v)}"
            elif last is not None:
                inserts.setdefault(last, []).append(f"{k} = {format_value(v)}")
    for i in sorted(inserts, reverse=True):
        new[i + 1:i + 1] = inserts[i]
    name = path.name
    return list(difflib.unified_diff(lines, new, fromfile=f"a/{name}", tofile=f"b/{name}", lineterm="", n=0))

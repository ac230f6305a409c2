"""The limits a controller's trajectory planner works to, read from its configuration.

LinuxCNC plans every move with the limits of each axis (``[AXIS_x]`` MAX_VELOCITY and
MAX_ACCELERATION, bounded by those of the joint that drives it, ``[JOINT_n]``, with trivial
kinematics joint n drives the n-th coordinate letter) and caps the path speed at
``[TRAJ]`` MAX_LINEAR_VELOCITY, which is also the speed of a rapid.  :class:`PlannerLimits`
carries those figures and where they came from, for :func:`gcode_gen.interpolator.interpolate`
(``axis_limits``) and for the words and JSON of a prediction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from core.errors import InputError
from core.linuxcnc_ini import linear_units_mm, read_sections
from gcode_gen.program import ROTARY_AXES

__all__ = ["PlannerLimits", "read_linuxcnc_ini"]


@dataclass(frozen=True)
class PlannerLimits:
    """Per-axis (max velocity mm/s, max acceleration mm/s²; deg/s, deg/s² for A, B, C), the path
    speed cap (mm/s), and their source."""

    axes: dict[str, tuple[float, float]]
    max_linear_velocity: float | None
    source: str

    def describe(self) -> str:
        """One line: the planner and its limits."""
        unit = {a: "deg" if a in ROTARY_AXES else "mm" for a in self.axes}
        axes = ", ".join(f"{a} {v:g} {unit[a]}/s {acc:g} {unit[a]}/s²" for a, (v, acc) in self.axes.items())
        cap = f", path ≤ {self.max_linear_velocity:g} mm/s" if self.max_linear_velocity else ""
        return f"LinuxCNC planner, per-axis limits from {self.source}: {axes}{cap}"

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "per-axis", "source": self.source, "max_linear_velocity_mm_s": self.max_linear_velocity,
                "axes": {a: {"max_velocity_mm_s": v, "max_acceleration_mm_s2": acc} for a, (v, acc) in self.axes.items()}}


def _number(secs: dict, section: str, key: str, path: Path) -> float | None:
    if key not in secs.get(section, {}):
        return None
    line, value = secs[section][key]
    text = value.split("#")[0].strip()
    try:
        number = float(text)
    except ValueError:
        raise InputError(f"{path}:{line + 1}: [{section}] {key} = {text!r} is not a number") from None
    if not (math.isfinite(number) and number > 0):
        raise InputError(f"{path}:{line + 1}: [{section}] {key} = {text} must be a positive number")
    return number


def read_linuxcnc_ini(path: str | Path) -> PlannerLimits:
    """The planner limits of a LinuxCNC INI file (module docstring), in mm; one line naming what is missing.

    Read as LinuxCNC reads it (:mod:`core.linuxcnc_ini`: ``#INCLUDE`` expanded, indented
    keys, the first of equal keys); velocities and accelerations are in the machine's units,
    ``[TRAJ] LINEAR_UNITS``, and converted to mm (an inch machine's 4 in/s is 101.6 mm/s).
    Line numbers in messages are those of the INI with its includes expanded.
    """
    path = Path(path)
    secs = read_sections(path)
    mm = linear_units_mm(secs, path)
    coords = ""
    if "COORDINATES" in secs.get("TRAJ", {}):
        coords = secs["TRAJ"]["COORDINATES"][1]
    elif "coordinates=" in secs.get("KINS", {}).get("KINEMATICS", (0, ""))[1]:
        coords = secs["KINS"]["KINEMATICS"][1].split("coordinates=")[1].split()[0]
    letters = [c.upper() for c in coords.split("#")[0] if c.isalpha()]
    if not letters:
        raise InputError(f"{path}: no [TRAJ] COORDINATES (or [KINS] KINEMATICS coordinates=): which axes?")
    axes: dict[str, tuple[float, float]] = {}
    for j, letter in enumerate(letters):
        found = []  # a gantry's second joint (the letter again) limits the axis too
        for section in (f"AXIS_{letter}", f"JOINT_{j}"):
            found.append((_number(secs, section, "MAX_VELOCITY", path), _number(secs, section, "MAX_ACCELERATION", path)))
        v = [x for x, _ in found if x is not None]
        a = [x for _, x in found if x is not None]
        if not v or not a:
            raise InputError(f"{path}: axis {letter} has no MAX_VELOCITY/MAX_ACCELERATION in [AXIS_{letter}] or [JOINT_{j}]")
        old = axes.get(letter, (math.inf, math.inf))
        k = 1.0 if letter in ROTARY_AXES else mm  # a rotary axis is in ANGULAR_UNITS
        axes[letter] = (min(k * min(v), old[0]), min(k * min(a), old[1]))
    cap = _number(secs, "TRAJ", "MAX_LINEAR_VELOCITY", path)
    return PlannerLimits(axes, None if cap is None else mm * cap, path.name)

"""The limits a controller's trajectory planner works to, read from its configuration.

LinuxCNC plans every move with the limits of each axis (``[AXIS_x]`` MAX_VELOCITY and
MAX_ACCELERATION, bounded by those of the joint that drives it, ``[JOINT_n]``, with trivial
kinematics joint n drives the n-th coordinate letter) and caps the path speed at
``[TRAJ]`` MAX_LINEAR_VELOCITY, which is also the speed of a rapid.  :class:`PlannerLimits`
carries those figures and where they came from, for :func:`gcode_gen.interpolator.interpolate`
(``axis_limits``) and for the words and JSON of a prediction.
"""

from __future__ import annotations

import configparser
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from core.errors import InputError

__all__ = ["PlannerLimits", "read_linuxcnc_ini"]


@dataclass(frozen=True)
class PlannerLimits:
    """Per-axis (max velocity mm/s, max acceleration mm/s²), the path speed cap (mm/s), and their source."""

    axes: dict[str, tuple[float, float]]
    max_linear_velocity: float | None
    source: str

    def describe(self) -> str:
        """One line: the planner and its limits."""
        axes = ", ".join(f"{a} {v:g} mm/s {acc:g} mm/s²" for a, (v, acc) in self.axes.items())
        cap = f", path ≤ {self.max_linear_velocity:g} mm/s" if self.max_linear_velocity else ""
        return f"LinuxCNC planner, per-axis limits from {self.source}: {axes}{cap}"

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "per-axis", "source": self.source, "max_linear_velocity_mm_s": self.max_linear_velocity,
                "axes": {a: {"max_velocity_mm_s": v, "max_acceleration_mm_s2": acc} for a, (v, acc) in self.axes.items()}}


def _number(cp: configparser.ConfigParser, section: str, key: str, path: Path) -> float | None:
    if not cp.has_option(section, key):
        return None
    text = cp.get(section, key).split("#")[0].strip()
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{path}: [{section}] {key} = {text!r} is not a number") from None
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"{path}: [{section}] {key} = {text} must be a positive number")
    return value


def read_linuxcnc_ini(path: str | Path) -> PlannerLimits:
    """The planner limits of a LinuxCNC INI file (module docstring); one line naming what is missing."""
    path = Path(path)
    cp = configparser.ConfigParser(strict=False, interpolation=None, comment_prefixes=("#", ";"),
                                   inline_comment_prefixes=None)
    cp.optionxform = str
    try:
        if not cp.read(path):
            raise InputError(f"{path}: no such INI file")
    except (configparser.Error, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not a LinuxCNC INI file ({str(exc).splitlines()[0]})") from None
    coords = ""
    if cp.has_option("TRAJ", "COORDINATES"):
        coords = cp.get("TRAJ", "COORDINATES")
    elif cp.has_option("KINS", "KINEMATICS") and "coordinates=" in cp.get("KINS", "KINEMATICS"):
        coords = cp.get("KINS", "KINEMATICS").split("coordinates=")[1].split()[0]
    letters = [c.upper() for c in coords if c.isalpha()]
    if not letters:
        raise InputError(f"{path}: no [TRAJ] COORDINATES (or [KINS] KINEMATICS coordinates=): which axes?")
    axes: dict[str, tuple[float, float]] = {}
    for j, letter in enumerate(letters):
        found = []  # a gantry's second joint (the letter again) limits the axis too
        for section in (f"AXIS_{letter}", f"JOINT_{j}"):
            found.append((_number(cp, section, "MAX_VELOCITY", path), _number(cp, section, "MAX_ACCELERATION", path)))
        v = [x for x, _ in found if x is not None]
        a = [x for _, x in found if x is not None]
        if not v or not a:
            raise InputError(f"{path}: axis {letter} has no MAX_VELOCITY/MAX_ACCELERATION in [AXIS_{letter}] or [JOINT_{j}]")
        old = axes.get(letter, (math.inf, math.inf))
        axes[letter] = (min(min(v), old[0]), min(min(a), old[1]))
    return PlannerLimits(axes, _number(cp, "TRAJ", "MAX_LINEAR_VELOCITY", path), path.name)

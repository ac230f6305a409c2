"""The allowed range of every effect parameter (SPEC §7 effects): one check for every way in.

An effect reaches a model three ways — ``agent simulate --effect backlash=0.01`` (the
virtual CNC, :mod:`virtual_cnc.effects`), a result JSON's accepted effects and
``agent predict --set X.backlash.gap_mm=0.01`` (the identified model,
:class:`ident.axis_model.AxisModel`).  All three check a value here, so a gap of −1 mm is
refused the same way whichever way it came.  Bottom layer: both packages use it.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

from core.errors import InputError

__all__ = ["LIMITS", "TEXT_KEYS", "REQUIRED", "check_effect_parameter", "check_effect_parameters"]

#: effect -> parameter -> (lower, lower excluded, upper, upper excluded); None: unbounded.
LIMITS: dict[str, dict[str, tuple[float | None, bool, float | None, bool]]] = {
    "backlash": {"gap_mm": (0.0, True, None, False), "motor_fraction": (0.0, True, 1.0, True),
                 "contact_freq_hz": (0.0, True, None, False), "position_motor_share": (0.0, False, 1.0, False)},
    "stribeck": {"static_to_coulomb_ratio": (1.0, False, None, False),
                 "stribeck_velocity_mm_s": (0.0, True, None, False)},
    "resonance": {"freq_hz": (0.0, True, None, False), "damping": (0.0, False, None, False),
                  "motor_fraction": (0.0, True, 1.0, True), "position_motor_share": (0.0, False, 1.0, False),
                  "locked_motor_hz": (0.0, False, None, False)},
    "time_delay": {"delay_s": (0.0, False, 1.0, False), "sampling_lag_s": (0.0, False, 1.0, False)},
    "cyclic_error": {"period_mm": (0.0, True, None, False), "amplitude": (0.0, False, None, False)},
    "saturation": {"limit": (0.0, True, None, False)},
}

#: Parameters an identified model's effect cannot do without (the virtual CNC has defaults).
REQUIRED: dict[str, tuple[str, ...]] = {
    "backlash": ("gap_mm",), "stribeck": ("static_to_coulomb_ratio", "stribeck_velocity_mm_s"),
    "resonance": ("freq_hz", "damping"), "time_delay": ("delay_s",), "cyclic_error": ("period_mm", "amplitude"),
    "saturation": ("limit",),
}

#: Parameters that hold words or flags rather than numbers (which loop, which kind, where).
TEXT_KEYS = frozenset({"axis", "at", "loop", "kind", "where", "amplitude_unit", "anti_windup"})


def check_effect_parameter(effect: str, key: str, value: Any) -> None:
    """One-line :class:`InputError` ("backlash gap_mm must be > 0, got -1.0") unless ``value`` is allowed."""
    name = f"{effect} {key}"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"{name} must be a finite number, got {value!r}")
    lo, lo_open, hi, hi_open = LIMITS.get(effect, {}).get(key, (None, False, None, False))
    if lo is not None and (value < lo or (lo_open and value == lo)):
        raise InputError(f"{name} must be {'>' if lo_open else '>='} {lo:g}, got {value!r}")
    if hi is not None and (value > hi or (hi_open and value == hi)):
        raise InputError(f"{name} must be {'<' if hi_open else '<='} {hi:g}, got {value!r}")


def check_effect_parameters(effect: str, params: Any, *, complete: bool = False) -> None:
    """Every parameter of one effect: a mapping of names to numbers (words only for :data:`TEXT_KEYS`);
    ``complete``: also the :data:`REQUIRED` ones present."""
    if not isinstance(params, Mapping):
        raise InputError(f"effect {effect}: parameters must be name: value pairs, got {params!r}")
    missing = [k for k in REQUIRED.get(effect, ()) if complete and k not in params]
    if missing:
        raise InputError(f"effect {effect} has no {missing[0]} (it needs {', '.join(REQUIRED[effect])})")
    for key, value in params.items():
        if key not in TEXT_KEYS:
            check_effect_parameter(effect, str(key), value)

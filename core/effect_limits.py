"""The allowed range of every effect parameter (SPEC §7 effects): one check for every way in.

An effect reaches a model three ways — ``agent simulate --effect backlash=0.01`` (the
virtual CNC, :mod:`virtual_cnc.effects`), a result JSON's accepted effects and
``agent predict --set X.backlash.gap_mm=0.01`` (the identified model,
:class:`ident.axis_model.AxisModel`).  All three check a value here, so a gap of −1 mm is
refused the same way whichever way it came.  The ranges, the required parameters and
which parameters are words are those of the effect registry (:mod:`core.effects`).
"""

from __future__ import annotations

import math
from typing import Any, Mapping

from core.effects import EFFECTS, MODEL, Parameter
from core.errors import InputError

__all__ = ["LIMITS", "TEXT_KEYS", "REQUIRED", "check_effect_parameter", "check_effect_parameters"]

#: effect -> parameter -> (lower, lower excluded, upper, upper excluded); None: unbounded.
LIMITS: dict[str, dict[str, tuple[float | None, bool, float | None, bool]]] = {
    e.name: {p.name: p.limits for p in e.parameters if not p.text} for e in EFFECTS.values()}

#: Parameters an identified model's effect cannot do without (the virtual CNC has defaults).
REQUIRED: dict[str, tuple[str, ...]] = {
    e.name: tuple(p.name for p in e.parameters if p.required and MODEL in p.places) for e in EFFECTS.values()}

#: Parameters that hold words or flags rather than numbers (which loop, which kind, where).
TEXT_KEYS = frozenset(p.name for e in EFFECTS.values() for p in e.parameters if p.text)


def _declared(effect: str, key: str) -> Parameter | None:
    e = EFFECTS.get(effect)
    return next((p for p in e.parameters if p.name == key), None) if e else None


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


def _check_value(effect: str, key: str, value: Any) -> None:
    """One parameter in the form the registry gives it (a number, a word, an interval, time windows)."""
    p = _declared(effect, key)
    form = p.form if p else ("word" if key in TEXT_KEYS else "number")
    if form == "word":
        if p and p.choices and value is not None and value not in p.choices:
            raise InputError(f"{effect} {key} must be one of {', '.join(p.choices)}, got {value!r}")
    elif form == "flag":
        if not isinstance(value, bool):
            raise InputError(f"{effect} {key} must be true or false, got {value!r}")
    elif form in ("interval", "windows"):
        items = [value] if form == "interval" else value
        if not isinstance(items, (list, tuple)) or not all(isinstance(w, (list, tuple)) and len(w) == 2
                                                           for w in items):
            shape = "[low, high]" if form == "interval" else "a list of [start, end]"
            raise InputError(f"{effect} {key} must be {shape}, got {value!r}")
        for w in items:
            for v in w:
                check_effect_parameter(effect, key, v)
    else:
        check_effect_parameter(effect, key, value)


def check_effect_parameters(effect: str, params: Any, *, complete: bool = False, place: str | None = None) -> None:
    """Every parameter of one effect: a mapping of names to values in the registry's forms (numbers,
    and words, flags or intervals where :mod:`core.effects` says so); ``complete``: also the
    :data:`REQUIRED` ones present; ``place`` (:data:`core.effects.MODEL` …): only the names
    the registry gives that place (a model's saturation has a ``limit``, not the virtual
    CNC's ``limit_v``)."""
    if not isinstance(params, Mapping):
        raise InputError(f"effect {effect}: parameters must be name: value pairs, got {params!r}")
    if place is not None and effect in EFFECTS:
        known = EFFECTS[effect].names(place)
        unknown = [k for k in params if k not in known]
        if unknown:
            raise InputError(f"effect {effect}: unknown parameter {unknown[0]!r}; known: {', '.join(known)}")
    missing = [k for k in REQUIRED.get(effect, ()) if complete and k not in params]
    if missing:
        raise InputError(f"effect {effect} has no {missing[0]} (it needs {', '.join(REQUIRED[effect])})")
    for key, value in params.items():
        _check_value(effect, str(key), value)

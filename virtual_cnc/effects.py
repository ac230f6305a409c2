"""Optional drive physics the base model of thesis eq. 3.3 leaves out (SPEC §7).

Each effect is a frozen dataclass; :func:`parse_effect` reads the command-line form

    NAME=VALUE                 the primary parameter, the others at their defaults
    NAME=key:value,key:value   any parameters by name

e.g. ``backlash=0.012``, ``resonance=freq_hz:40,damping:0.05``.  Every effect also takes
``axis:X`` to act on one axis only (default: all axes).

How each is simulated (see :mod:`virtual_cnc.servo`):

* ``backlash`` — the drive becomes two masses (motor with a fraction ``motor_fraction`` of
  the inertia, table with the rest) coupled through a dead zone of width ``gap_mm`` with a
  stiff, well-damped contact (``contact_freq_hz``, damping 0.5).  The position loop reads
  the table (load-side scale), the velocity/derivative term reads the motor encoder, as in
  a full-closed-loop CNC axis.  Coulomb/Stribeck friction acts on the table (guideways).
* ``stribeck`` — friction magnitude d(v) = d_c·[1 + (r − 1)·exp(−(v/v_s)²)] with breakaway
  r·d_c; a stick/slip state machine holds the axis exactly at rest while the applied force
  is below breakaway (no chattering at zero speed).
* ``resonance`` — two-mass mode: motor and table coupled by a spring-damper whose free-free
  mode has ``freq_hz`` and ``damping``; the table is measured, the velocity loop reads the
  motor.  In closed loop the vibration seen in the tracking error lies between
  freq_hz·√motor_fraction (motor held by a stiff loop) and freq_hz — at freq_hz (±5 %) for
  modes well above the servo bandwidth (≥ 150 Hz with the presets).  As on a real machine,
  a lightly damped mode near or below the velocity-loop bandwidth (≲ 60 Hz) can make the
  loop unstable.  With backlash as well, this spring is the backlash contact.
* ``time_delay`` — dead time ``delay_s``, by default on the actuation (the plant sees
  u(t − delay)); ``at:feedback`` delays the encoder readings the controller uses,
  ``at:capture`` only the recorded actual.  Resolved to the plant integration step
  (fractions of a servo period allowed).
* ``cyclic_error`` — a disturbance acceleration −amplitude·sin(2π·x/period_mm + phase) on
  the motor side; ``amplitude`` is in mm/s² (control equivalent: amplitude/(K/J) volts),
  like lead-screw pitch-error or cogging forces.
* ``saturation`` — actuator limit ``limit`` [V] replacing the axis's u_max when lower; the
  integrators stop integrating while saturated (anti-windup).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import ClassVar, Union

from core.effect_limits import check_effect_parameters
from core.errors import InputError

__all__ = [
    "Backlash",
    "Stribeck",
    "Resonance",
    "TimeDelay",
    "CyclicError",
    "Saturation",
    "Effect",
    "EFFECTS",
    "parse_effect",
    "format_effect",
]


def _check_fields(effect) -> None:
    """Every numeric parameter against the one table of allowed ranges (core.effect_limits)."""
    check_effect_parameters(effect.name, {f.name: getattr(effect, f.name) for f in fields(effect)})


@dataclass(frozen=True)
class Backlash:
    """Lost motion ``gap_mm`` [mm] between motor and table (load-side position feedback).

    motor_fraction : share of the total inertia J on the motor side [-], in (0, 1).
    contact_freq_hz : frequency of the motor–table contact mode when engaged [Hz].
    """

    gap_mm: float = 0.01
    motor_fraction: float = 0.8
    contact_freq_hz: float = 400.0
    axis: str | None = None
    name: ClassVar[str] = "backlash"
    primary: ClassVar[str] = "gap_mm"

    def __post_init__(self) -> None:
        _check_fields(self)


@dataclass(frozen=True)
class Stribeck:
    """Stiction + Stribeck curve on top of the axis's Coulomb friction d⁺/d⁻.

    static_to_coulomb_ratio : breakaway / Coulomb friction [-], >= 1.
    stribeck_velocity_mm_s : speed over which friction falls to Coulomb [mm/s], > 0.
    """

    static_to_coulomb_ratio: float = 1.5
    stribeck_velocity_mm_s: float = 1.0
    axis: str | None = None
    name: ClassVar[str] = "stribeck"
    primary: ClassVar[str] = "static_to_coulomb_ratio"

    def __post_init__(self) -> None:
        _check_fields(self)


@dataclass(frozen=True)
class Resonance:
    """Two-mass structural mode at ``freq_hz`` [Hz] with modal ``damping`` [-].

    motor_fraction : share of the total inertia J on the motor side [-], in (0, 1).
    """

    freq_hz: float = 150.0
    damping: float = 0.03
    motor_fraction: float = 0.8
    axis: str | None = None
    name: ClassVar[str] = "resonance"
    primary: ClassVar[str] = "freq_hz"

    def __post_init__(self) -> None:
        _check_fields(self)


#: Where a time_delay acts.
DELAY_LOCATIONS = ("actuation", "feedback", "capture")


@dataclass(frozen=True)
class TimeDelay:
    """Dead time ``delay_s`` [s], resolved to the plant integration step.

    at : "actuation" (default; the plant sees u(t − delay)), "feedback" (the controller
        reads the encoders delay_s late; the recording shows the same late reading) or
        "capture" (only the recorded actual is delay_s old; the loop is unaffected).
    """

    delay_s: float = 0.002
    at: str = "actuation"
    axis: str | None = None
    name: ClassVar[str] = "time_delay"
    primary: ClassVar[str] = "delay_s"

    def __post_init__(self) -> None:
        _check_fields(self)
        if self.at not in DELAY_LOCATIONS:
            raise InputError(f"time_delay at must be one of {', '.join(DELAY_LOCATIONS)}, got {self.at!r}")


@dataclass(frozen=True)
class CyclicError:
    """Position-periodic disturbance: period ``period_mm`` [mm], ``amplitude`` [mm/s²].

    phase_deg : phase of the sine at x = 0 [deg].
    """

    period_mm: float = 5.0
    amplitude: float = 200.0
    phase_deg: float = 0.0
    axis: str | None = None
    name: ClassVar[str] = "cyclic_error"
    primary: ClassVar[str] = "period_mm"

    def __post_init__(self) -> None:
        _check_fields(self)


@dataclass(frozen=True)
class Saturation:
    """Actuator limit ``limit`` [V] (clips u to ±limit; anti-windup on the integrators)."""

    limit: float = 2.0
    axis: str | None = None
    name: ClassVar[str] = "saturation"
    primary: ClassVar[str] = "limit"

    def __post_init__(self) -> None:
        _check_fields(self)


Effect = Union[Backlash, Stribeck, Resonance, TimeDelay, CyclicError, Saturation]

#: name → effect class, in SPEC §7 order.
EFFECTS: dict[str, type] = {
    cls.name: cls for cls in (Backlash, Stribeck, Resonance, TimeDelay, CyclicError, Saturation)
}


#: Parameters that take text rather than a number.
_TEXT_KEYS = ("axis", "at")


def _param_names(cls: type) -> list[str]:
    return [f.name for f in fields(cls)]


def _number(text: str, what: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"{what}: {text!r} is not a number") from None
    if not math.isfinite(v):
        raise InputError(f"{what}: {text!r} is not a finite number")
    return v


def parse_effect(text: str) -> Effect:
    """Parse ``NAME=VALUE`` or ``NAME=key:value,...`` into an effect; InputError if invalid."""
    s = text.strip()
    name, sep, rest = s.partition("=")
    name = name.strip().lower().replace("-", "_")
    if name not in EFFECTS:
        raise InputError(f"unknown effect {name or s!r}; known: {', '.join(EFFECTS)}")
    cls = EFFECTS[name]
    keys = _param_names(cls)
    rest = rest.strip()
    if not sep or not rest:
        raise InputError(f"effect {name!r} needs a value, e.g. {name}={_example(cls)}")
    kwargs: dict[str, object] = {}
    if ":" not in rest:
        kwargs[cls.primary] = _number(rest, f"effect {name} {cls.primary}")
    else:
        for item in rest.split(","):
            key, colon, value = item.partition(":")
            key, value = key.strip(), value.strip()
            if not colon or not key or not value:
                raise InputError(f"effect {name}: expected key:value, got {item.strip()!r}")
            if key not in keys:
                raise InputError(f"effect {name}: unknown parameter {key!r}; known: {', '.join(keys)}")
            if key in kwargs:
                raise InputError(f"effect {name}: parameter {key!r} given twice")
            kwargs[key] = value if key in _TEXT_KEYS else _number(value, f"effect {name} {key}")
    return cls(**kwargs)


def _example(cls: type) -> str:
    return f"{getattr(cls(), cls.primary):g}"


def format_effect(effect: Effect) -> str:
    """The ``NAME=key:value,...`` text that :func:`parse_effect` reads back to ``effect``."""
    parts = []
    for f in fields(effect):
        v = getattr(effect, f.name)
        if v is None:
            continue
        parts.append(f"{f.name}:{v}" if f.name in _TEXT_KEYS else f"{f.name}:{float(v)!r}")
    return f"{effect.name}=" + ",".join(parts)

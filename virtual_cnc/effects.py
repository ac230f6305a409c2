"""Optional drive physics the base model of thesis eq. 3.3 leaves out (SPEC §7).

Each effect is a frozen dataclass; :func:`parse_effect` reads the command-line form

    NAME=VALUE                 the primary parameter, the others at their defaults
    NAME=key:value,key:value   any parameters by name

e.g. ``backlash=0.012``, ``resonance=freq_hz:40,damping:0.05``.  Every effect also takes
``axis:X`` to act on one axis only (default: all axes).  Names, units, admissible ranges and
the older spellings still read (``at:`` for ``where:``, ``limit:`` for ``limit_v:``,
``phase_deg:`` for ``phase_rad:``) are those of the effect registry, :mod:`core.effects`;
the dataclasses below hold the simulator's defaults.

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
  u(t − delay)); ``where:feedback`` delays the encoder readings the controller uses,
  ``where:capture`` only the recorded actual.  Resolved to the plant integration step
  (fractions of a servo period allowed).
* ``cyclic_error`` — a disturbance acceleration −amplitude·sin(2π·x/period_mm + phase_rad)
  on the motor side; ``amplitude`` is in mm/s² (control equivalent: amplitude/(K/J) volts),
  like lead-screw pitch-error or cogging forces — the identified model's ``kind:
  disturbance`` with the same amplitude and phase.
* ``saturation`` — amplifier output limit ``limit_v`` [V] replacing the axis's u_max when
  lower; the integrators stop integrating while saturated (anti-windup).  The identified
  model states its ``limit`` as the control-equivalent acceleration, (K/J)·limit_v mm/s².
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import ClassVar, Union

from core.effect_limits import check_effect_parameters
from core.effects import EFFECTS as REGISTRY
from core.effects import SIMULATOR
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
    "model_equivalent",
]


def _check_fields(effect) -> None:
    """Every parameter against the registry's admissible ranges (core.effect_limits)."""
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
    name: ClassVar[str] = REGISTRY["backlash"].name
    primary: ClassVar[str] = REGISTRY["backlash"].primary

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
    name: ClassVar[str] = REGISTRY["stribeck"].name
    primary: ClassVar[str] = REGISTRY["stribeck"].primary

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
    name: ClassVar[str] = REGISTRY["resonance"].name
    primary: ClassVar[str] = REGISTRY["resonance"].primary

    def __post_init__(self) -> None:
        _check_fields(self)


#: Where a time_delay acts (the registry's places the virtual CNC simulates).
DELAY_LOCATIONS = REGISTRY["time_delay"].choices("where", SIMULATOR)


@dataclass(frozen=True)
class TimeDelay:
    """Dead time ``delay_s`` [s], resolved to the plant integration step.

    where : "actuation" (default; the plant sees u(t − delay)), "feedback" (the controller
        reads the encoders delay_s late; the recording shows the same late reading) or
        "capture" (only the recorded actual is delay_s old; the loop is unaffected).
    """

    delay_s: float = 0.002
    where: str = "actuation"
    axis: str | None = None
    name: ClassVar[str] = REGISTRY["time_delay"].name
    primary: ClassVar[str] = REGISTRY["time_delay"].primary

    def __post_init__(self) -> None:
        _check_fields(self)


@dataclass(frozen=True)
class CyclicError:
    """Position-periodic disturbance: period ``period_mm`` [mm], ``amplitude`` [mm/s²].

    phase_rad : phase φ of −amplitude·sin(2π·x/period_mm + φ) at x = 0 [rad].
    """

    period_mm: float = 5.0
    amplitude: float = 200.0
    phase_rad: float = 0.0
    axis: str | None = None
    name: ClassVar[str] = REGISTRY["cyclic_error"].name
    primary: ClassVar[str] = REGISTRY["cyclic_error"].primary

    def __post_init__(self) -> None:
        _check_fields(self)


@dataclass(frozen=True)
class Saturation:
    """Amplifier output limit ``limit_v`` [V] (clips u to ±limit_v; anti-windup on the integrators)."""

    limit_v: float = 2.0
    axis: str | None = None
    name: ClassVar[str] = REGISTRY["saturation"].name
    primary: ClassVar[str] = REGISTRY["saturation"].primary

    def __post_init__(self) -> None:
        _check_fields(self)


Effect = Union[Backlash, Stribeck, Resonance, TimeDelay, CyclicError, Saturation]

#: name → effect class, in SPEC §7 order (the registry's simulated effects).
EFFECTS: dict[str, type] = {
    cls.name: cls for cls in (Backlash, Stribeck, Resonance, TimeDelay, CyclicError, Saturation)
}


def _number(text: str, what: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"{what}: {text!r} is not a number") from None
    if not math.isfinite(v):
        raise InputError(f"{what}: {text!r} is not a finite number")
    return v


def parse_effect(text: str) -> Effect:
    """Parse ``NAME=VALUE`` or ``NAME=key:value,...`` into an effect; InputError if invalid.

    Keys are the registry's names of the simulator's parameters or their older spellings
    (:attr:`core.effects.Parameter.aliases`, converted to the registry's unit)."""
    s = text.strip()
    name, sep, rest = s.partition("=")
    name = name.strip().lower().replace("-", "_")
    if name not in EFFECTS:
        raise InputError(f"unknown effect {name or s!r}; known: {', '.join(EFFECTS)}")
    cls, entry = EFFECTS[name], REGISTRY[name]
    keys = [f.name for f in fields(cls)]
    rest = rest.strip()
    if not sep or not rest:
        raise InputError(f"effect {name!r} needs a value, e.g. {name}={_example(cls)}")
    kwargs: dict[str, object] = {}
    if ":" not in rest:
        kwargs[cls.primary] = _number(rest, f"effect {name} {cls.primary}")
    else:
        for item in rest.split(","):
            given, colon, value = item.partition(":")
            given, value = given.strip(), value.strip()
            if not colon or not given or not value:
                raise InputError(f"effect {name}: expected key:value, got {item.strip()!r}")
            key, convert = entry.alias(given) or (given, None)
            if key not in keys:
                raise InputError(f"effect {name}: unknown parameter {given!r}; known: {', '.join(keys)}")
            if key in kwargs:
                raise InputError(f"effect {name}: parameter {key!r} given twice")
            if entry.parameter(key).text:
                kwargs[key] = value
            else:
                v = _number(value, f"effect {name} {given}")
                kwargs[key] = convert(v) if convert else v
    return cls(**kwargs)


def _example(cls: type) -> str:
    return f"{getattr(cls(), cls.primary):g}"


def format_effect(effect: Effect) -> str:
    """The ``NAME=key:value,...`` text that :func:`parse_effect` reads back to ``effect``."""
    entry = REGISTRY[effect.name]
    parts = []
    for f in fields(effect):
        v = getattr(effect, f.name)
        if v is None:
            continue
        parts.append(f"{f.name}:{v}" if entry.parameter(f.name).text else f"{f.name}:{float(v)!r}")
    return f"{effect.name}=" + ",".join(parts)


def model_equivalent(effect: Effect, k_over_j: float, b_over_j: float = 0.0) -> dict:
    """The simulator's ``effect`` in the identified model's parameters (SPEC §7 words, the
    registry's :data:`~core.effects.MODEL` names): what a diagnosis that recovered it exactly
    would report.  ``k_over_j`` [mm/(V·s²)] is the axis's control-to-acceleration gain K/J,
    which turns the amplifier limit ``limit_v`` [V] into the control-equivalent acceleration
    ``limit`` [mm/s²] the identified model clips; ``b_over_j`` [1/s], the plant's viscous
    pole B/J, is the model's ``limit_slope``: eq. 3.3's u is the amplifier's output less the
    viscous share B/J·ẋ that a1 holds, so the clip of u falls by B/J per mm/s of speed in the
    direction it pushes.  The virtual CNC's forms: a full-closed
    two-mass backlash and mode, a disturbance cyclic error; a feedback delay acts inside the
    loop, which the model tells as actuation."""
    entry = REGISTRY[effect.name]
    if isinstance(effect, Backlash):
        return {"gap_mm": effect.gap_mm, "loop": "table_fed_back", "motor_fraction": effect.motor_fraction}
    if isinstance(effect, Stribeck):
        return {"static_to_coulomb_ratio": effect.static_to_coulomb_ratio,
                "stribeck_velocity_mm_s": effect.stribeck_velocity_mm_s}
    if isinstance(effect, Resonance):
        return {"freq_hz": effect.freq_hz, "damping": effect.damping, "motor_fraction": effect.motor_fraction,
                "kind": "two_mass", "loop": "table"}
    if isinstance(effect, TimeDelay):
        return {"delay_s": effect.delay_s, "where": "capture" if effect.where == "capture" else "actuation"}
    if isinstance(effect, CyclicError):
        return {"period_mm": effect.period_mm, "amplitude": effect.amplitude, "phase_rad": effect.phase_rad,
                "kind": "disturbance", "amplitude_unit": entry.parameter("amplitude").unit_by_variant["disturbance"]}
    if isinstance(effect, Saturation):
        return {"limit": k_over_j * effect.limit_v, "limit_unit": entry.parameter("limit").unit,
                "limit_slope": b_over_j, "anti_windup": True}
    raise TypeError(f"not an effect of the virtual CNC: {effect!r}")

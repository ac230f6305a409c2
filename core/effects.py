"""The one registry of the effects of SPEC §7: names, parameters, units, bounds, variants, words.

Every place a user meets an effect reads it from here:

* the virtual CNC's truth (``agent simulate --effect NAME=…``, machine files:
  :mod:`virtual_cnc.effects`) — place :data:`SIMULATOR`;
* the identified model (the diagnosis's fits, words and JSON, :mod:`ident.diagnosis.effects`;
  the virtual machine's :class:`ident.axis_model.AxisModel`, ``agent predict --set
  X.backlash.gap_mm=…``) — place :data:`MODEL`;
* the one check of every value (:mod:`core.effect_limits`).

A parameter has one name and one unit wherever it appears.  Where the simulator and the
identified model hold genuinely different quantities, they have different names and the
entry says how one converts to the other:

* saturation: the virtual CNC clips its amplifier output, ``limit_v`` [V]; the identified
  model (eq. 3.3 has no volts) clips the control-equivalent acceleration, ``limit``
  [mm/s²].  ``limit = (K/J)·limit_v`` with K/J the axis's control-to-acceleration gain
  [mm/(V·s²)] (:attr:`virtual_cnc.drive.Plant.K_over_J`).
* cyclic_error: ``amplitude`` is mm/s² for ``kind`` = ``disturbance`` (the only form the
  virtual CNC simulates, −amplitude·sin(2π·x/period_mm + phase_rad) added to the
  acceleration, the same sign in both simulators) and mm for ``kind`` = ``position_error``
  (an error of the recorded position); ``amplitude_unit`` in the JSON says which.

Older spellings the ``--effect`` parser still reads (``at:`` for ``where:``, ``limit:``
for ``limit_v:``, ``phase_deg:`` for ``phase_rad:``) are :attr:`Parameter.aliases`.
This module holds words and numbers only: no simulation, no fitting (bottom layer, imported
by ``ident`` and ``virtual_cnc``, which never import each other).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

__all__ = ["SIMULATOR", "MODEL", "Parameter", "Variant", "EffectEntry", "EFFECTS", "EFFECT_NAMES",
           "DESCRIBED_ONLY", "effect", "parameter", "unit", "shown_unit", "parameter_units"]

#: The virtual CNC's truth (``--effect``, machine files).
SIMULATOR = "virtual_cnc"
#: The identified model (diagnosis, axis model, virtual machine, result JSON).
MODEL = "model"
_BOTH = (SIMULATOR, MODEL)


@dataclass(frozen=True)
class Parameter:
    """One parameter of an effect.

    name : the key in ``--effect``, machine files, the result JSON and ``--set``.
    unit : unit of the value ("mm", "mm/s", "mm/s^2", "s", "Hz", "V", "rad", "-"), "" for
        a word or flag.
    meaning : what it is, in one line.
    form : "number"; "word" (one of ``choices``); "flag" (true/false); "interval" ([low,
        high] in ``unit``); "windows" (a list of [start, end] in ``unit``).
    lower, upper : admissible range (None: unbounded); ``lower_open``/``upper_open``: the
        bound itself excluded.  A fit's search box lies inside it.
    places : where it exists (:data:`SIMULATOR`, :data:`MODEL`).
    required : an identified model's effect cannot do without it.
    aliases : older names the ``--effect`` parser reads, each with its conversion to this unit.
    unit_by_variant : the unit when a variant of the effect holds another quantity
        (variant value → unit); the JSON then carries it beside the value.
    """

    name: str
    unit: str
    meaning: str
    lower: float | None = None
    lower_open: bool = False
    upper: float | None = None
    upper_open: bool = False
    places: tuple[str, ...] = _BOTH
    required: bool = False
    choices: tuple[str, ...] = ()
    form: str = "number"
    aliases: dict[str, Callable[[float], float]] = field(default_factory=dict)
    unit_by_variant: dict[str, str] = field(default_factory=dict)

    @property
    def text(self) -> bool:
        """A word or flag rather than a number."""
        return self.form in ("word", "flag")

    @property
    def limits(self) -> tuple[float | None, bool, float | None, bool]:
        return self.lower, self.lower_open, self.upper, self.upper_open


@dataclass(frozen=True)
class Variant:
    """One place or form of an effect: the value ``value`` of its word parameter ``key``."""

    key: str
    value: str | bool
    meaning: str
    places: tuple[str, ...] = (MODEL,)


@dataclass(frozen=True)
class EffectEntry:
    """One effect of SPEC §7.

    name : the verdict and JSON name.
    words : how a sentence names it ("time delay").
    meaning : SPEC §7's line.
    primary : the parameter ``--effect NAME=VALUE`` sets.
    parameters : every parameter, user-facing (:class:`Parameter`).
    variants : the places/forms the simulators know.
    coordinates : internal fit coordinates of the identified model that are not reported
        as such (name → meaning), e.g. the cyclic error's sine and cosine amplitudes.
    """

    name: str
    words: str
    meaning: str
    primary: str
    parameters: tuple[Parameter, ...]
    variants: tuple[Variant, ...] = ()
    coordinates: dict[str, str] = field(default_factory=dict)
    simulated: bool = True

    def parameter(self, name: str) -> Parameter:
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(f"effect {self.name} has no parameter {name!r}")

    def names(self, place: str) -> tuple[str, ...]:
        """The parameter names that exist at ``place``."""
        return tuple(p.name for p in self.parameters if place in p.places)

    def choices(self, key: str, place: str) -> tuple[str | bool, ...]:
        """The values of word parameter ``key`` known at ``place``, in the simulators' mode order."""
        return tuple(v.value for v in self.variants if v.key == key and place in v.places)

    def alias(self, name: str) -> tuple[str, Callable[[float], float]] | None:
        """(registry name, conversion) of an older spelling ``name``; None if it is not one."""
        for p in self.parameters:
            if name in p.aliases:
                return p.name, p.aliases[name]
        return None


def _same(v: float) -> float:
    return v


_FRACTION = Parameter("motor_fraction", "-", "share of the total inertia on the motor side", 0.0, True, 1.0, True)
_PSI = Parameter("position_motor_share", "-",
                 "share ψ of the position feedback that reads the motor (0: PID on the table scale, "
                 "≈ 0.8: P-PI cascade whose velocity integral is the motor position)",
                 0.0, False, 1.0, False, places=(MODEL,))
_AXIS = Parameter("axis", "", "the one axis the effect acts on (default: every axis)", places=(SIMULATOR,),
                  form="word")

EFFECTS: dict[str, EffectEntry] = {e.name: e for e in (
    EffectEntry(
        "backlash", "backlash", "lost motion between motor and table at reversals", "gap_mm",
        (Parameter("gap_mm", "mm", "width of the dead band between motor and table", 0.0, True, required=True),
         _FRACTION,
         Parameter("contact_freq_hz", "Hz", "frequency of the motor–table contact when engaged", 0.0, True,
                   places=(SIMULATOR,)),
         _PSI,
         Parameter("loop", "", "which side the loop reads and which is recorded", places=(MODEL,),
                   choices=("table_recorded", "table_fed_back", "table_recorded_two_mass"), form="word"),
         _AXIS),
        (Variant("loop", "table_recorded", "loop and friction on the motor, a massless table recorded"),
         Variant("loop", "table_fed_back", "two masses across a stiff contact, the loop reading the table "
                 "(full-closed loop; the virtual CNC's form)", _BOTH),
         Variant("loop", "table_recorded_two_mass", "two masses, every loop term on the motor, the table recorded"))),
    EffectEntry(
        "stribeck", "Stribeck friction",
        "breakaway friction above Coulomb, falling with speed; stick-slip at low speed", "static_to_coulomb_ratio",
        (Parameter("static_to_coulomb_ratio", "-", "breakaway / Coulomb friction", 1.0, required=True),
         Parameter("stribeck_velocity_mm_s", "mm/s", "speed over which friction falls to Coulomb", 0.0, True,
                   required=True),
         _AXIS)),
    EffectEntry(
        "resonance", "resonance", "a lightly damped structural mode excited by acceleration changes", "freq_hz",
        (Parameter("freq_hz", "Hz", "frequency of the mode (free-free for a two-mass mode)", 0.0, True, required=True),
         Parameter("damping", "-", "modal damping ratio ζ", 0.0, required=True),
         _FRACTION,
         _PSI,
         Parameter("gain", "-", "gain κ of the filter on the recorded position (kind output_filter)", places=(MODEL,)),
         Parameter("locked_motor_hz", "Hz",
                   "frequency the table rings at with the motor held, freq_hz·√motor_fraction",
                   0.0, places=(MODEL,)),
         Parameter("kind", "", "a filter on the recorded position or a two-mass mode inside the loop",
                   places=(MODEL,), choices=("output_filter", "two_mass"), form="word"),
         Parameter("loop", "", "which mass a two-mass mode's loop reads (and which is recorded)", places=(MODEL,),
                   choices=("table", "motor", "motor_recorded"), form="word"),
         _AXIS),
        (Variant("kind", "output_filter", "a pole pair filtering the recorded position"),
         Variant("kind", "two_mass", "motor and table coupled by a spring-damper of that mode "
                 "(the virtual CNC's form)", _BOTH),
         Variant("loop", "table", "the loop reads the table (full-closed)", _BOTH),
         Variant("loop", "motor", "the loop reads the motor, the table recorded (semi-closed)"),
         Variant("loop", "motor_recorded", "the loop reads the motor and the motor encoder is recorded "
                 "(semi-closed): the mode shows only through the table's reaction on the motor"))),
    EffectEntry(
        "time_delay", "time delay", "pure dead time in actuation, feedback or capture", "delay_s",
        (Parameter("delay_s", "s", "the drive's dead time", 0.0, False, 1.0, required=True),
         Parameter("sampling_lag_s", "s", "lag of sampling a continuous-loop model's delay carries besides delay_s",
                   0.0, False, 1.0, places=(MODEL,)),
         Parameter("delay_range_s", "s", "dead times that fit as well, [low, high]", 0.0, False, 1.0,
                   places=(MODEL,), form="interval"),
         Parameter("where", "", "where the dead time sits", choices=("actuation", "feedback", "capture"),
                   form="word", aliases={"at": _same}),
         _AXIS),
        (Variant("where", "capture", "the recorded position only (capture or transport); the loop is unaffected",
                 _BOTH),
         Variant("where", "actuation", "the control output inside the loop (the plant sees u(t − delay))", _BOTH),
         Variant("where", "feedback", "the encoder readings the controller uses (inside the loop; the identified "
                 "model tells it as actuation)", (SIMULATOR,)))),
    EffectEntry(
        "cyclic_error", "cyclic error",
        "disturbance or error periodic in position (lead-screw pitch error, cogging)", "period_mm",
        (Parameter("period_mm", "mm", "period in position", 0.0, True, required=True),
         Parameter("amplitude", "mm/s^2", "amplitude: mm/s² of a disturbance, mm of a position error "
                   "(amplitude_unit says which)", 0.0, required=True,
                   unit_by_variant={"position_error": "mm", "disturbance": "mm/s^2"}),
         Parameter("phase_rad", "rad", "phase φ of amplitude·sin(2π·x/period_mm + φ) at x = 0",
                   aliases={"phase_deg": math.radians}),
         Parameter("amplitude_unit", "", "unit of amplitude for this kind", places=(MODEL,),
                   choices=("mm", "mm/s^2"), form="word"),
         Parameter("kind", "", "an error of the recorded position or a disturbance acceleration", places=(MODEL,),
                   choices=("position_error", "disturbance"), form="word"),
         _AXIS),
        (Variant("kind", "position_error", "an error of the recorded position, amplitude in mm"),
         Variant("kind", "disturbance", "a disturbance acceleration −amplitude·sin(2π·x/period_mm + phase_rad), "
                 "amplitude in mm/s² (the virtual CNC's form)", _BOTH)),
        coordinates={"amplitude_sin": "amplitude·cos(phase_rad), the sine's coefficient",
                     "amplitude_cos": "amplitude·sin(phase_rad), the cosine's coefficient"}),
    EffectEntry(
        "saturation", "saturation", "actuator/current limit reached in the fastest accelerations", "limit_v",
        (Parameter("limit_v", "V", "the virtual CNC's amplifier output limit (replaces the axis's u_max when lower)",
                   0.0, True, places=(SIMULATOR,), aliases={"limit": _same}),
         Parameter("limit", "mm/s^2", "the identified model's limit of the control-equivalent acceleration "
                   "(= K/J · limit_v)", 0.0, True, places=(MODEL,), required=True),
         Parameter("limit_unit", "", "unit of limit", places=(MODEL,), choices=("mm/s^2",),
                   form="word"),
         Parameter("limit_slope", "1/s", "the limit falls by this much per mm/s of speed in the direction it "
                   "pushes: the drive's output also carries the plant's viscous friction (or a voltage limit's "
                   "back-EMF), which eq. 3.3 folds into a1", 0.0, places=(MODEL,)),
         _PSI,
         Parameter("anti_windup", "", "the integrators stop while the output is clipped", places=(MODEL,),
                   form="flag"),
         _AXIS),
        (Variant("anti_windup", True, "integrators frozen while clipped (the virtual CNC's form)", _BOTH),
         Variant("anti_windup", False, "the integral runs on while clipped and overshoots once released"))),
    EffectEntry(
        "external_force", "external force",
        "a load not caused by the drive's own motion (time-localised, independent of position and speed)",
        "force",
        (Parameter("force", "mm/s^2", "size of the load, control-equivalent acceleration", places=(MODEL,)),
         Parameter("force_unit", "", "unit of force", places=(MODEL,), choices=("mm/s^2",), form="word"),
         Parameter("times", "s", "time windows [start, end] the load acts in", 0.0, places=(MODEL,),
                   form="windows"),
         Parameter("recording", "", "the recording the load was found on", places=(MODEL,),
                   choices=("identification", "validation"), form="word")),
        simulated=False),
)}

#: Effects an axis model carries and the simulators simulate, in SPEC §7 order (the
#: augmented simulator's flag vector follows it).
EFFECT_NAMES: tuple[str, ...] = tuple(n for n, e in EFFECTS.items() if e.simulated)
#: Effects the diagnosis describes but no model simulates.
DESCRIBED_ONLY: tuple[str, ...] = tuple(n for n, e in EFFECTS.items() if not e.simulated)


def effect(name: str) -> EffectEntry:
    """The registry entry of ``name``; KeyError names the known effects."""
    try:
        return EFFECTS[name]
    except KeyError:
        raise KeyError(f"unknown effect {name!r}; known: {', '.join(EFFECTS)}") from None


def parameter(effect_name: str, name: str) -> Parameter:
    return effect(effect_name).parameter(name)


def unit(effect_name: str, name: str) -> str:
    """The unit of one parameter as the registry states it ("mm", "mm/s^2" …)."""
    return parameter(effect_name, name).unit


def shown_unit(u: str) -> str:
    """A registry unit as a sentence prints it ("mm/s^2" → "mm/s²")."""
    return u.replace("^2", "²").replace("^3", "³")


def parameter_units(effect_name: str, params: dict) -> dict[str, str]:
    """The unit of every numeric parameter in ``params`` (an effect's parameters as a model
    or the JSON holds them), the variant the words in ``params`` name resolved (a cyclic
    error's amplitude: mm of a position error, mm/s² of a disturbance)."""
    e = effect(effect_name)
    words = {v for v in params.values() if isinstance(v, str)}
    out = {}
    for key in params:
        try:
            p = e.parameter(key)
        except KeyError:
            continue
        if not p.text:
            out[key] = next((u for v, u in p.unit_by_variant.items() if v in words), p.unit)
    return out

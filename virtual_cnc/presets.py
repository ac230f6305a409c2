"""Named virtual machines (thesis §3.4.1) and TOML machine files.

Presets reproduce the virtual Fadal VMC 2216 drives of thesis §3.4.1.  All use
K/J = 1000 mm/(V·s²) (J = 0.0035 kg·m², K = 3.5 N·m/V in mm/rad), so the 2000 mm/s²
interpolator limit needs about 2 V plus friction, well inside the ±10 V actuator limit.
B/J = 2.55 1/s (X) and 2.90 1/s (Y); the gains are chosen so that eq. 3.4 / 3.5 give the
tables' "Actual" columns (checked to 1 % by tests/test_sim_presets.py):

* ``fadal-ppi`` — P-PI cascade, Table 3.3: Kp = 30 1/s; X: Kd = 0.3702 V/(mm/s),
  Ki = 50.90 V/mm; Y: Kd = 0.36986, Ki = 50.90.
* ``fadal-pid`` — PID, Table 3.4: X: Kp = 44.356 V/mm, Ki = 316.83 V/(mm·s),
  Kd = 0.1901 V/(mm/s); Y: Kp = 41.032, Ki = 293.09, Kd = 0.17585.
* ``fadal-smc`` — sliding-mode-like law, Table 3.5: λ = 200 rad/s, K·Ks/J = 190.10 (X) /
  293.09 (Y) 1/s, K·ρ/J = 19009.8 (X) / 29308.6 (Y) 1/s², with full velocity and
  acceleration feedforward (b0 = 1, b1 = a1, b2 = a2).

Friction (control-equivalent, Tables 3.3–3.5 d0/d1 divided by K/J): X d⁺ = 0.441 V,
d⁻ = −0.302 V; Y d⁺ = 0.409 V, d⁻ = −0.388 V.  Encoder: 0.1 µm resolution, 0.05 µm noise;
DAC 16 bit over ±10 V; servo period 1 ms, 20 plant substeps (20 kHz).

Machine file (TOML), keys (units in the names; every key optional unless marked)::

    name = "my-vmc"                    # default: the file stem
    description = "..."
    base = "fadal-ppi"                 # start from a preset; axes/keys below override it
    servo_period_s = 0.001
    a_max_mm_s2 = 2000.0               # interpolator acceleration limit
    j_max_mm_s3 = 0.0                  # jerk limit, 0 = none (trapezoidal)
    rapid_feed_mm_s = 200.0            # G00 feed
    effects = ["backlash=0.005"]       # drive physics, as for --effect

    [axes.X]                           # one table per axis (required without base)
    controller = "ppi"                 # ppi | pid | smc
    Kp = 30.0                          # gains in the units of virtual_cnc/drive.py
    Ki = 50.9
    Kd = 0.3702
    Kv = 0.0
    Ka = 0.0
    J = 0.0035                         # kg·m² (only K/J and B/J matter)
    B = 0.008925                       # kg·m²/s
    K = 3.5                            # N·m/V (mm/rad)
    d_plus_V = 0.441                   # Coulomb friction, control equivalent
    d_minus_V = -0.302
    u_max_V = 10.0                     # actuator limit
    dac_resolution_V = 0.0
    encoder_resolution_mm = 0.0001
    encoder_noise_mm = 0.00005
    substeps = 20                      # plant steps per servo period (>= 10)

See docs/machine-file.md.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

try:  # Python 3.11+
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - 3.10
    import tomli as tomllib  # type: ignore[no-redef]

from core.errors import InputError, MachineError
from virtual_cnc.drive import AxisDrive, Controller, Encoder, Plant, smc_gains
from virtual_cnc.effects import Effect, format_effect, parse_effect

__all__ = [
    "Machine",
    "PRESETS",
    "DEFAULT_MACHINE",
    "load_machine",
    "machine_to_toml",
    "preset_names",
]

DEFAULT_MACHINE = "fadal-ppi"


@dataclass(frozen=True)
class Machine:
    """A virtual CNC: its axes and the interpolator limits.

    Parameters
    ----------
    name, description : identification for logs and metadata.
    axes : {axis name: AxisDrive}, e.g. {"X": ..., "Y": ...}.
    a_max : interpolator acceleration limit [mm/s²].
    j_max : interpolator jerk limit [mm/s³]; None = trapezoidal velocity (no S-curve).
    rapid_feed : G00 feed [mm/s].
    Ts : servo / interpolation period [s]; every axis runs at it.
    effects : drive physics built into the machine (applied before any --effect).
    """

    name: str
    description: str
    axes: Mapping[str, AxisDrive]
    a_max: float = 2000.0
    j_max: float | None = None
    rapid_feed: float = 200.0
    Ts: float = 0.001
    effects: tuple[Effect, ...] = field(default=())

    def __post_init__(self) -> None:
        if not self.axes:
            raise MachineError(f"machine {self.name!r} has no axes")
        for attr, unit in (("a_max", "mm/s²"), ("rapid_feed", "mm/s"), ("Ts", "s")):
            v = getattr(self, attr)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise MachineError(f"machine {self.name!r}: {attr} must be > 0 {unit}, got {v!r}")
        if self.j_max is not None and not (math.isfinite(self.j_max) and self.j_max > 0):
            raise MachineError(f"machine {self.name!r}: j_max must be > 0 mm/s³ or None, got {self.j_max!r}")
        # every axis runs at the machine's servo period
        axes = {str(k): (a if a.Ts == self.Ts else replace(a, Ts=self.Ts)) for k, a in self.axes.items()}
        object.__setattr__(self, "axes", axes)
        object.__setattr__(self, "effects", tuple(self.effects))


# ----------------------------------------------------------------------------- presets

_KJ = 1000.0  # K/J [mm/(V·s²)]
_J = 0.0035
_K = _KJ * _J
_ENCODER = Encoder(resolution=0.0001, noise_std=0.00005)
_DAC = 20.0 / 65536


def _plant(b_over_j: float, d_plus: float, d_minus: float) -> Plant:
    return Plant(J=_J, B=b_over_j * _J, K=_K, d_plus=d_plus, d_minus=d_minus, u_max=10.0)


_PLANT_X = _plant(2.55, 0.441, -0.302)
_PLANT_Y = _plant(2.90, 0.409, -0.388)


def _axis(controller: Controller, plant: Plant) -> AxisDrive:
    return AxisDrive(controller=controller, plant=plant, encoder=_ENCODER, Ts=0.001,
                     substeps=20, dac_resolution=_DAC)


def _fadal(name: str, description: str, x: AxisDrive, y: AxisDrive) -> Machine:
    return Machine(name=name, description=description, axes={"X": x, "Y": y},
                   a_max=2000.0, j_max=None, rapid_feed=200.0, Ts=0.001)


PRESETS: dict[str, Machine] = {
    m.name: m
    for m in (
        _fadal(
            "fadal-ppi",
            "Fadal VMC 2216 virtual drives, P-PI cascade control (thesis Table 3.3)",
            _axis(Controller("ppi", Kp=30.0, Ki=50.90, Kd=0.3702), _PLANT_X),
            _axis(Controller("ppi", Kp=30.0, Ki=50.90, Kd=0.36986), _PLANT_Y),
        ),
        _fadal(
            "fadal-pid",
            "Fadal VMC 2216 virtual drives, PID control (thesis Table 3.4)",
            _axis(Controller("pid", Kp=44.356, Ki=316.83, Kd=0.1901), _PLANT_X),
            _axis(Controller("pid", Kp=41.032, Ki=293.09, Kd=0.17585), _PLANT_Y),
        ),
        _fadal(
            "fadal-smc",
            "Fadal VMC 2216 virtual drives, adaptive sliding-mode-like control with "
            "velocity/acceleration feedforward (thesis Table 3.5)",
            _axis(smc_gains(lam=200.0, Ks=0.19010, rho=19.0098, plant=_PLANT_X), _PLANT_X),
            _axis(smc_gains(lam=200.0, Ks=0.29309, rho=29.3086, plant=_PLANT_Y), _PLANT_Y),
        ),
    )
}


def preset_names() -> list[str]:
    """Names of the built-in machines."""
    return list(PRESETS)


# ----------------------------------------------------------------------------- TOML

_TOP_KEYS = {"name", "description", "base", "servo_period_s", "a_max_mm_s2", "j_max_mm_s3",
             "rapid_feed_mm_s", "effects", "axes"}
_AXIS_KEYS = {"controller", "Kp", "Ki", "Kd", "Kv", "Ka", "J", "B", "K", "d_plus_V", "d_minus_V",
              "u_max_V", "dac_resolution_V", "encoder_resolution_mm", "encoder_noise_mm", "substeps"}


def _axis_to_dict(a: AxisDrive) -> dict[str, Any]:
    c, p, e = a.controller, a.plant, a.encoder
    return {
        "controller": c.kind, "Kp": c.Kp, "Ki": c.Ki, "Kd": c.Kd, "Kv": c.Kv, "Ka": c.Ka,
        "J": p.J, "B": p.B, "K": p.K, "d_plus_V": p.d_plus, "d_minus_V": p.d_minus,
        "u_max_V": p.u_max, "dac_resolution_V": a.dac_resolution,
        "encoder_resolution_mm": e.resolution, "encoder_noise_mm": e.noise_std,
        "substeps": a.substeps,
    }


def _axis_from_dict(where: str, d: Mapping[str, Any], base: AxisDrive | None, Ts: float) -> AxisDrive:
    unknown = sorted(set(d) - _AXIS_KEYS)
    if unknown:
        raise MachineError(f"{where}: unknown key {unknown[0]!r}; known: {', '.join(sorted(_AXIS_KEYS))}")
    values = _axis_to_dict(base) if base is not None else {}
    values.update(d)
    required = ("controller", "Kp", "Ki", "Kd", "J", "B", "K")
    missing = [k for k in required if k not in values]
    if missing:
        raise MachineError(f"{where}: missing key {missing[0]!r}")
    for key, v in values.items():
        if key == "controller":
            if not isinstance(v, str):
                raise MachineError(f"{where}: controller must be a string, got {v!r}")
        elif isinstance(v, bool) or not isinstance(v, (int, float)):
            raise MachineError(f"{where}: {key} must be a number, got {v!r}")
    try:
        return AxisDrive(
            controller=Controller(values["controller"], Kp=values["Kp"], Ki=values["Ki"],
                                  Kd=values["Kd"], Kv=values.get("Kv", 0.0), Ka=values.get("Ka", 0.0)),
            plant=Plant(J=values["J"], B=values["B"], K=values["K"],
                        d_plus=values.get("d_plus_V", 0.0), d_minus=values.get("d_minus_V", 0.0),
                        u_max=values.get("u_max_V", 10.0)),
            encoder=Encoder(resolution=values.get("encoder_resolution_mm", 0.0),
                            noise_std=values.get("encoder_noise_mm", 0.0)),
            Ts=Ts,
            substeps=values.get("substeps", 20),
            dac_resolution=values.get("dac_resolution_V", 0.0),
        )
    except MachineError as exc:
        raise MachineError(f"{where}: {exc}") from None


def _machine_from_toml(path: Path) -> Machine:
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise MachineError(f"cannot read machine file {str(path)!r}: {exc.strerror or exc}") from exc
    except UnicodeDecodeError:
        raise MachineError(f"machine file {str(path)!r} is not UTF-8 text") from None
    except tomllib.TOMLDecodeError as exc:
        raise MachineError(f"machine file {str(path)!r} is not valid TOML: {exc}") from None
    where = str(path)
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise MachineError(f"{where}: unknown key {unknown[0]!r}; known: {', '.join(sorted(_TOP_KEYS))}")
    base: Machine | None = None
    if "base" in data:
        if data["base"] not in PRESETS:
            raise MachineError(f"{where}: unknown base preset {data['base']!r}; known: {', '.join(PRESETS)}")
        base = PRESETS[data["base"]]

    def num(key: str, default: float | None) -> float | None:
        v = data.get(key, default)
        if v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise MachineError(f"{where}: {key} must be a number, got {v!r}")
        return float(v)

    Ts = num("servo_period_s", base.Ts if base else 0.001)
    axes_in = data.get("axes", {})
    if not isinstance(axes_in, dict) or any(not isinstance(v, dict) for v in axes_in.values()):
        raise MachineError(f"{where}: 'axes' must be tables [axes.X], [axes.Y], ...")
    axes: dict[str, AxisDrive] = {}
    if base is not None:
        axes.update(base.axes)
    for name, d in axes_in.items():
        axes[name] = _axis_from_dict(f"{where}: axis {name}", d, axes.get(name), Ts)
    if not axes:
        raise MachineError(f"{where}: no axes; add [axes.X] tables or a base preset")
    effects_in = data.get("effects", [])
    if not isinstance(effects_in, list) or any(not isinstance(e, str) for e in effects_in):
        raise MachineError(f"{where}: effects must be a list of strings like \"backlash=0.01\"")
    effects: list[Effect] = list(base.effects) if base else []
    for text in effects_in:
        try:
            effects.append(parse_effect(text))
        except InputError as exc:
            raise MachineError(f"{where}: {exc}") from None
    jmax = num("j_max_mm_s3", (base.j_max if base else None) or 0.0)
    return Machine(
        name=str(data.get("name", path.stem)),
        description=str(data.get("description", base.description if base else f"machine file {path.name}")),
        axes=axes,
        a_max=num("a_max_mm_s2", base.a_max if base else 2000.0),
        j_max=jmax if jmax else None,
        rapid_feed=num("rapid_feed_mm_s", base.rapid_feed if base else 200.0),
        Ts=Ts,
        effects=tuple(effects),
    )


def load_machine(name_or_path: str | Path) -> Machine:
    """A preset by name, or a machine read from a TOML file (path or name ending .toml).

    Raises MachineError (one line) for an unknown preset, a missing/invalid file or bad keys.
    """
    text = str(name_or_path)
    if text in PRESETS:
        return PRESETS[text]
    path = Path(text)
    if path.suffix.lower() == ".toml" or path.exists():
        if not path.is_file():
            raise MachineError(f"machine file {text!r} not found")
        return _machine_from_toml(path)
    raise MachineError(f"unknown machine {text!r}; known presets: {', '.join(PRESETS)} (or a .toml file)")


def _toml_value(v: Any) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} to TOML")


def machine_to_toml(machine: Machine) -> str:
    """The TOML machine file that :func:`load_machine` reads back to ``machine``."""
    lines = [
        f"name = {_toml_value(machine.name)}",
        f"description = {_toml_value(machine.description)}",
        f"servo_period_s = {_toml_value(float(machine.Ts))}",
        f"a_max_mm_s2 = {_toml_value(float(machine.a_max))}",
        f"j_max_mm_s3 = {_toml_value(float(machine.j_max or 0.0))}",
        f"rapid_feed_mm_s = {_toml_value(float(machine.rapid_feed))}",
        f"effects = {_toml_value([format_effect(e) for e in machine.effects])}",
    ]
    for name, axis in machine.axes.items():
        lines.append("")
        lines.append(f"[axes.{name}]")
        for key, v in _axis_to_dict(axis).items():
            lines.append(f"{key} = {_toml_value(v if isinstance(v, (str, int)) else float(v))}")
    return "\n".join(lines) + "\n"

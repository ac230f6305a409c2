"""One feed-drive axis of the virtual CNC: controller, rigid-body plant, encoder.

The structures are those of thesis Fig. 3.2 and §3.2:

* **P-PI cascade** (``kind="ppi"``, Fig. 3.2a).  The position loop is a P controller with
  feedforward of the commanded velocity and acceleration; it produces the velocity command

      v_cmd = Kp·(x_r + Kv·ẋ_r + Ka·ẍ_r − x)                         [mm/s]

  and the velocity loop is a PI controller on the velocity error e_v = v_cmd − ẋ:

      u = Kd·e_v + Ki·∫e_v dt                                       [V]

  With the plant below this gives exactly thesis eq. 3.4 (derivation: substitute u into
  J s² x + B s x = K u and collect powers of s):
  a1=(B+K·Kd)/J, a2=K(Kd·Kp+Ki)/J, a3=K·Kp·Ki/J, b0=K·Kp·Kd·Ka/J, b1=K·Kp(Kd·Kv+Ka·Ki)/J,
  b2=K·Kp(Kd+Kv·Ki)/J.  Units: Kp [1/s], Kd [V/(mm/s)], Ki [V/mm] (= V/(mm/s) per s),
  Kv [s], Ka [s²] (so full velocity feedforward is Kv = 1/Kp).

* **PID** (``kind="pid"``, Fig. 3.2b) with optional velocity/acceleration feedforward,
  e = x_r − x:

      u = Kp·e + Ki·∫e dt + Kd·ė + Kv·ẋ_r + Ka·ẍ_r                   [V]

  giving thesis eq. 3.5: a1=(B+K·Kd)/J, a2=b2=K·Kp/J, a3=K·Ki/J, b0=K·Ka/J, b1=K(Kd+Kv)/J.
  Units: Kp [V/mm], Ki [V/(mm·s)], Kd [V/(mm/s)], Kv [V/(mm/s)], Ka [V/(mm/s²)].

* **Sliding-mode-like** (``kind="smc"``, thesis §3.4.1 "Adaptive Sliding Mode", ref. [13]).
  With adaptation of the disturbance only, the law is a PID with velocity and
  acceleration feedforward, so it is stored and simulated in the PID form above;
  :func:`smc_gains` converts the sliding-surface design (λ, Ks, ρ) to those gains, and
  with Kv = B/K, Ka = J/K the tracking transfer function is 1 (b0=1, b1=a1, b2=a2).

Plant (rigid body, thesis §3.2 and eq. 3.2), x in mm:

    J·ẍ = K·(u − d(ẋ)) − B·ẋ,      d = d⁺ when ẋ > 0, d⁻ when ẋ < 0

d⁺ ≥ 0 ≥ d⁻ are the control-signal-equivalent Coulomb friction values [V]; at ẋ = 0 the
axis sticks while d⁻ ≤ u ≤ d⁺.  J, B, K are in the thesis's units (J [kg·m²],
B [kg·m²/s], K [N·m/V] including the screw transmission in mm/rad); only K/J
[mm/(V·s²)] and B/J [1/s] enter the dynamics.

The closed-loop model of eq. 3.3 uses d0 = (K/J)·d⁺ and d1 = (K/J)·d⁻ [mm/s²].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from core.errors import MachineError

__all__ = [
    "CONTROLLER_KINDS",
    "Controller",
    "Plant",
    "Encoder",
    "AxisDrive",
    "closed_loop_parameters",
    "smc_gains",
]

#: Controller structures the simulator implements.
CONTROLLER_KINDS = ("ppi", "pid", "smc")


def _finite(name: str, value: float, *, positive: bool = False, nonneg: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise MachineError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise MachineError(f"{name} must be finite, got {value!r}")
    if positive and v <= 0:
        raise MachineError(f"{name} must be > 0, got {value!r}")
    if nonneg and v < 0:
        raise MachineError(f"{name} must be >= 0, got {value!r}")
    return v


@dataclass(frozen=True)
class Controller:
    """Servo controller of one axis; gain units depend on ``kind`` (see module docstring).

    Parameters
    ----------
    kind : "ppi" | "pid" | "smc"
    Kp, Ki, Kd : feedback gains.  P-PI: Kp [1/s] position gain, Kd [V/(mm/s)] and
        Ki [V/mm] the velocity-loop PI.  PID/SMC: Kp [V/mm], Ki [V/(mm·s)], Kd [V/(mm/s)].
    Kv, Ka : velocity and acceleration feedforward (P-PI: [s], [s²]; PID: [V/(mm/s)],
        [V/(mm/s²)]); 0 disables them.
    """

    kind: str
    Kp: float
    Ki: float
    Kd: float
    Kv: float = 0.0
    Ka: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in CONTROLLER_KINDS:
            raise MachineError(
                f"unknown controller kind {self.kind!r}; known: {', '.join(CONTROLLER_KINDS)}"
            )
        for name in ("Kp", "Ki", "Kd", "Kv", "Ka"):
            object.__setattr__(self, name, _finite(name, getattr(self, name), nonneg=True))
        if self.Kp <= 0:
            raise MachineError(f"Kp must be > 0 for a closed position loop, got {self.Kp!r}")


@dataclass(frozen=True)
class Plant:
    """Rigid-body drive J·ẍ = K·(u − d) − B·ẋ with Coulomb friction d⁺/d⁻ and actuator limit.

    Parameters
    ----------
    J : equivalent inertia [kg·m²] (thesis units; only ratios matter), > 0.
    B : viscous damping [kg·m²/s], >= 0.
    K : amplifier·torque-constant·screw gain [N·m/V in mm/rad], > 0.
    d_plus : control-equivalent Coulomb friction for positive motion [V], >= 0.
    d_minus : same for negative motion [V], <= 0.
    u_max : actuator (DAC/amplifier) limit [V]; the command is clipped to ±u_max.
    """

    J: float
    B: float
    K: float
    d_plus: float = 0.0
    d_minus: float = 0.0
    u_max: float = 10.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "J", _finite("J", self.J, positive=True))
        object.__setattr__(self, "B", _finite("B", self.B, nonneg=True))
        object.__setattr__(self, "K", _finite("K", self.K, positive=True))
        object.__setattr__(self, "d_plus", _finite("d_plus", self.d_plus, nonneg=True))
        dm = _finite("d_minus", self.d_minus)
        if dm > 0:
            raise MachineError(f"d_minus must be <= 0 (friction opposes negative motion), got {dm!r}")
        object.__setattr__(self, "d_minus", dm)
        object.__setattr__(self, "u_max", _finite("u_max", self.u_max, positive=True))

    @property
    def K_over_J(self) -> float:
        """Control-to-acceleration gain K/J [mm/(V·s²)]."""
        return self.K / self.J

    @property
    def B_over_J(self) -> float:
        """Viscous pole B/J [1/s]."""
        return self.B / self.J


@dataclass(frozen=True)
class Encoder:
    """Position measurement: quantisation step [mm] (0 = ideal) and white noise std [mm]."""

    resolution: float = 0.0
    noise_std: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "resolution", _finite("encoder resolution", self.resolution, nonneg=True))
        object.__setattr__(self, "noise_std", _finite("encoder noise", self.noise_std, nonneg=True))


@dataclass(frozen=True)
class AxisDrive:
    """A complete simulated axis.

    Parameters
    ----------
    controller, plant, encoder : see the classes.
    Ts : servo (controller) period [s]; the command u is held constant (ZOH) over it.
    substeps : plant integration steps per servo period (step = Ts/substeps; ≥ 10).
    dac_resolution : quantisation step of u [V] (0 = ideal), e.g. 20/65536 for a 16-bit ±10 V DAC.
    """

    controller: Controller
    plant: Plant
    encoder: Encoder = field(default_factory=Encoder)
    Ts: float = 0.001
    substeps: int = 20
    dac_resolution: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "Ts", _finite("Ts", self.Ts, positive=True))
        if int(self.substeps) != self.substeps or self.substeps < 10:
            raise MachineError(f"substeps must be an integer >= 10 (step <= Ts/10), got {self.substeps!r}")
        object.__setattr__(self, "substeps", int(self.substeps))
        object.__setattr__(self, "dac_resolution", _finite("dac_resolution", self.dac_resolution, nonneg=True))


def closed_loop_parameters(axis: AxisDrive) -> dict[str, float]:
    """The closed-loop model parameters of thesis eq. 3.3 for ``axis``.

    P-PI: eq. 3.4; PID and SMC (PID with feedforward): eq. 3.5 extended with the
    feedforward terms (b0 = K·Ka/J, b1 = K(Kd+Kv)/J).  Returns a1 [1/s], a2 [1/s²],
    a3 [1/s³], b0 [-], b1 [1/s], b2 [1/s²], d0, d1 [mm/s²].
    """
    c, p = axis.controller, axis.plant
    kj, bj = p.K_over_J, p.B_over_J
    Kp, Ki, Kd, Kv, Ka = c.Kp, c.Ki, c.Kd, c.Kv, c.Ka
    if c.kind == "ppi":
        out = dict(
            a1=bj + kj * Kd,
            a2=kj * (Kd * Kp + Ki),
            a3=kj * Kp * Ki,
            b0=kj * Kp * Kd * Ka,
            b1=kj * Kp * (Kd * Kv + Ka * Ki),
            b2=kj * Kp * (Kd + Kv * Ki),
        )
    else:
        out = dict(
            a1=bj + kj * Kd,
            a2=kj * Kp,
            a3=kj * Ki,
            b0=kj * Ka,
            b1=kj * (Kd + Kv),
            b2=kj * Kp,
        )
    out["d0"] = kj * p.d_plus
    out["d1"] = kj * p.d_minus
    return out


def smc_gains(lam: float, Ks: float, rho: float, plant: Plant) -> Controller:
    """PID+feedforward gains equivalent to the adaptive sliding-mode law (thesis §3.4.1, [13]).

    Sliding surface S = λ·e + ė (e = x_r − x); control law with disturbance adaptation

        u = (J/K)(ẍ_r + λ·ė) + (B/K)·ẋ + Ks·S + ρ·∫S dt

    makes J·Ṡ + K·Ks·S + K·ρ·∫S = 0, i.e. closed-loop poles at −λ and the roots of
    s² + (K·Ks/J)s + K·ρ/J, cancelled by the zeros (G_track = 1).  Expanded into the PID
    form: Kp = Ks·λ + ρ, Ki = ρ·λ, Kd = J·λ/K + Ks − B/K, Kv = B/K, Ka = J/K.

    Parameters
    ----------
    lam : sliding-surface bandwidth λ [rad/s].
    Ks : feedback gain on S [V/(mm/s)].
    rho : disturbance-adaptation gain [V/mm].
    plant : the drive, for J, B, K.
    """
    J, B, K = plant.J, plant.B, plant.K
    return Controller(
        kind="smc",
        Kp=Ks * lam + rho,
        Ki=rho * lam,
        Kd=J * lam / K + Ks - B / K,
        Kv=B / K,
        Ka=J / K,
    )

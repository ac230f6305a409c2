"""The controller forms the tuner knows, their gains, and eq. 3.4 / 3.5 with a plant.

Two forms (thesis Fig. 3.2), each with its gains in the units the machine uses:

* ``p-pi`` — P-PI cascade: position gain Kp [1/s], velocity PI Kd [V/(mm/s)], Ki [V/mm],
  velocity and acceleration feed-forward Kv [s], Ka [s²] (full feed-forward Kv = 1/Kp);
* ``linuxcnc-pid`` — LinuxCNC's ``pid`` component: P [V/mm], I [V/(mm·s)], D [V/(mm/s)],
  FF1 [V/(mm/s)], FF2 [V/(mm/s²)] (and FF0, BIAS, DEADBAND, BACKLASH, MAX_OUTPUT, which
  the tuner reads, reports and keeps).  The same law as the virtual CNC's ``pid``.

:class:`Gains` holds either, by name; :meth:`Gains.law` gives the (kind, Kp, Ki, Kd, Kv,
Ka) of :mod:`ident.tuning.loop`.  :func:`closed_loop` is eq. 3.4 (P-PI) or eq. 3.5 (PID,
with its feed-forward terms) for a plant kj = K/J, bj = B/J — the coefficients of eq. 3.3
such a loop has in continuous time, and :func:`coefficient_rows` the same equations written
as rows linear in (kj, kj·bj/kj = bj): the over-determined set the plant is matched on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Mapping

import numpy as np

from core.errors import InputError
from ident.model import BASE_KEYS
from ident.tuning.loop import Timing

__all__ = ["CONTROLLER_FORMS", "Gains", "closed_loop", "coefficient_rows", "TIMINGS"]

#: Controller forms and the loop law each is simulated with.
CONTROLLER_FORMS = ("linuxcnc-pid", "p-pi", "pid")

#: Names of the gains per form, in the order they are printed; the first five are tuned.
GAIN_NAMES = {
    "p-pi": ("Kp", "Kd", "Ki", "Kv", "Ka"),
    "pid": ("Kp", "Ki", "Kd", "Kv", "Ka"),
    "linuxcnc-pid": ("P", "I", "D", "FF1", "FF2", "FF0", "BIAS", "DEADBAND", "BACKLASH", "MAX_OUTPUT"),
}

#: How each form samples (ident.tuning.loop.Timing): the virtual CNC's laws take the
#: reference derivatives by central differences and the feedback velocity by a backward
#: difference; LinuxCNC's pid differentiates the command backwards and reads the drive's
#: velocity (feedback-deriv).  Both hold u over the next period (the servo thread runs the
#: plant before pid, so pid's output of period k drives period k+1: a ZOH, no more delay).
#: LinuxCNC's pid takes its position error against the previous period's command
#: (error-previous-target) and its derivatives from the current one: with the true plant
#: this loop reproduces a capture of fixtures/linuxcnc to 0.000 µm rms (60 µm without).
TIMINGS = {
    "p-pi": Timing(central_reference=True, measured_velocity=False, delay=0),
    "pid": Timing(central_reference=True, measured_velocity=False, delay=0),
    "linuxcnc-pid": Timing(central_reference=False, measured_velocity=True, delay=0, previous_target=True),
}


@dataclass(frozen=True)
class Gains:
    """One axis's controller: its form and gains by name (module docstring for units).

    ``u_max`` is the output limit, V (inf: none; LinuxCNC MAX_OUTPUT = 0 means none).
    """

    form: str
    values: Mapping[str, float] = field(default_factory=dict)
    u_max: float = math.inf

    def __post_init__(self) -> None:
        if self.form not in CONTROLLER_FORMS:
            raise InputError.about("controller", f"controller {self.form!r}: one of {', '.join(CONTROLLER_FORMS)}")
        known = GAIN_NAMES[self.form]
        vals = {k: 0.0 for k in known}
        for k, v in dict(self.values).items():
            if k not in known:
                raise InputError(f"{self.form} has no gain {k!r} (gains: {', '.join(known)})")
            try:
                vals[k] = float(v)
            except (TypeError, ValueError):
                raise InputError(f"gain {k} must be a number, got {v!r}") from None
            if not math.isfinite(vals[k]):
                raise InputError(f"gain {k} must be finite, got {v!r}")
        object.__setattr__(self, "values", vals)
        if self.law()[1] <= 0:
            raise InputError(f"{self.form}: the position gain must be > 0 for a closed loop, got {self.law()[1]}")

    def law(self) -> tuple[str, float, float, float, float, float]:
        """(kind, Kp, Ki, Kd, Kv, Ka) of the loop law (ident.tuning.loop)."""
        v = self.values
        if self.form == "linuxcnc-pid":
            return "pid", v["P"], v["I"], v["D"], v["FF1"], v["FF2"]
        kind = "ppi" if self.form == "p-pi" else "pid"
        return kind, v["Kp"], v["Ki"], v["Kd"], v["Kv"], v["Ka"]

    @property
    def ff0(self) -> float:
        """Position feed-forward FF0 [V/mm] (LinuxCNC pid only; 0 for the other forms)."""
        return self.values.get("FF0", 0.0) if self.form == "linuxcnc-pid" else 0.0

    @property
    def timing(self) -> Timing:
        return TIMINGS[self.form]

    def with_law(self, Kp: float, Ki: float, Kd: float, Kv: float, Ka: float, Kf0: float = 0.0) -> "Gains":
        """A copy with the loop law's gains replaced (names mapped back to the form's; Kf0 = FF0)."""
        v = dict(self.values)
        if self.form == "linuxcnc-pid":
            v.update(P=Kp, I=Ki, D=Kd, FF0=Kf0, FF1=Kv, FF2=Ka)
        else:
            v.update(Kp=Kp, Ki=Ki, Kd=Kd, Kv=Kv, Ka=Ka)
        return replace(self, values=v)

    def to_dict(self) -> dict[str, float]:
        return {k: float(self.values[k]) for k in GAIN_NAMES[self.form]}


def closed_loop(gains: Gains, kj: float, bj: float) -> dict[str, float]:
    """Eq. 3.3 coefficients of ``gains`` around the plant ẍ = kj·u − bj·ẋ (eq. 3.4 / 3.5).

    P-PI (eq. 3.4): a1 = bj + kj·Kd, a2 = kj(Kd·Kp + Ki), a3 = kj·Kp·Ki, b0 = kj·Kp·Kd·Ka,
    b1 = kj·Kp(Kd·Kv + Ka·Ki), b2 = kj·Kp(Kd + Kv·Ki).
    PID (eq. 3.5 with feed-forward): a1 = bj + kj·Kd, a2 = b2 = kj·Kp, a3 = kj·Ki,
    b0 = kj·Ka, b1 = kj(Kd + Kv).
    """
    A, c = coefficient_rows(gains)
    theta = np.array([kj, bj])
    return {k: float(A[i] @ theta + c[i]) for i, k in enumerate(BASE_KEYS[:6])}


def coefficient_rows(gains: Gains) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 3.4 / 3.5 as rows: (a1, a2, a3, b0, b1, b2) = A·(kj, bj) + c, A (6, 2), c (6,)."""
    kind, Kp, Ki, Kd, Kv, Ka = gains.law()
    if kind == "ppi":
        k = [Kd, Kd * Kp + Ki, Kp * Ki, Kp * Kd * Ka, Kp * (Kd * Kv + Ka * Ki), Kp * (Kd + Kv * Ki)]
    else:
        k = [Kd, Kp, Ki, Ka, Kd + Kv, Kp]
    A = np.column_stack([k, [1.0, 0, 0, 0, 0, 0]])
    return A, np.zeros(6)

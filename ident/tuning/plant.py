"""From the identified closed loop to the plant: kj = K/J, bj = B/J, Coulomb friction, gap.

Given an axis's identified eq. 3.3 model (:class:`ident.axis_model.AxisModel`) and its
controller (:class:`ident.tuning.controllers.Gains`), the plant

    ẍ = kj·(u − d(ẋ)) − bj·ẋ,   d = d⁺ (ẋ > 0), d⁻ (ẋ < 0)        (thesis §3.2, eq. 3.2)

is found in two steps (docs/tuning.md derives both):

1. **Coefficient matching** (eq. 3.4 for P-PI, eq. 3.5 for PID).  With the gains known,
   the six coefficients a1, a2, a3, b0, b1, b2 are linear in (kj, bj): an over-determined
   set solved by least squares, each equation divided by its identified value (relative
   residuals; an identified coefficient that is ~0 is weighted by the size of its row),
   and d⁺ = d0/kj, d⁻ = d1/kj.
2. **Response matching.**  The continuous-time equations ignore the servo's sampling
   (ZOH, differences of the command and of the feedback), which the identification absorbs
   into a preview shift and coefficients biased by tens of percent (docs/linuxcnc.md:
   +9 %; the P-PI presets more, thesis Table 3.3).  So (kj, bj, d⁺, d⁻) are refined by
   bounded Levenberg–Marquardt until the controller's *sampled* loop
   (:func:`ident.tuning.loop.simulate_loop`) reproduces the identified model's own
   prediction of a fixed identification program (gcode_gen.generate, seed
   :data:`EXCITATION_SEED`): the model is trusted where it was validated — its response —
   not in its coefficients.

The accepted effects carry over as they are: ``backlash.gap_mm`` (the gap) and
``time_delay.delay_s`` (dead time beyond the form's own sampling).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from core.errors import IdentificationError
from ident.axis_model import AxisModel
from ident.least_squares import bounded_lm
from ident.tuning.controllers import Gains, coefficient_rows
from ident.tuning.loop import simulate_loop

__all__ = ["Plant", "match_coefficients", "derive_plant", "excitation", "EXCITATION_SEED"]

#: Seed of the identification program whose predicted response the plant is matched to.
EXCITATION_SEED = 1


@dataclass(frozen=True)
class Plant:
    """One axis's drive seen from the controller output (units as in the module docstring).

    kj : K/J, mm/(V·s²) — the inverse of the mass (inertia) equivalent per volt.
    bj : B/J, 1/s — viscous friction per unit mass.
    d_plus, d_minus : Coulomb friction, control-equivalent V (d⁺ ≥ 0 ≥ d⁻); as forces
        per unit mass kj·d, mm/s².
    gap_mm : backlash the diagnosis accepted (0: none).
    delay_s : accepted dead time beyond the controller's sampling (0: none).
    integration : how the drive moves between samples: "continuous" (a real drive) or
        "euler" (one semi-implicit Euler step per period: the headless LinuxCNC test
        machine's HAL plant, whose x responds half a period earlier than a continuous one).
    """

    kj: float
    bj: float
    d_plus: float
    d_minus: float
    gap_mm: float = 0.0
    delay_s: float = 0.0
    integration: str = "continuous"

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["mass_V_s2_per_mm"] = 1.0 / self.kj  # J/K: volts per mm/s² of acceleration
        return d


def match_coefficients(model: AxisModel, gains: Gains) -> Plant:
    """Step 1: (kj, bj) by least squares over eq. 3.4 / 3.5; d± = d0/kj, d1/kj."""
    m = model.model
    y = np.array([m.a1, m.a2, m.a3, m.b0, m.b1, m.b2])
    A, c = coefficient_rows(gains)
    scale = np.maximum(np.abs(y), np.abs(A[:, 0]) * max(abs(m.a2 / max(A[1, 0], 1e-300)), 1e-12))
    keep = np.abs(A).sum(axis=1) > 0
    sol = np.linalg.lstsq((A / scale[:, None])[keep], ((y - c) / scale)[keep], rcond=None)[0]
    kj, bj = float(sol[0]), float(sol[1])
    if not kj > 0:
        raise IdentificationError(f"the identified model and the {gains.form} gains give K/J = {kj:.4g} <= 0: "
                                  f"are these the gains the machine ran with?")
    return Plant(kj, max(bj, 0.0), max(m.d0, 0.0) / kj, min(m.d1, 0.0) / kj, *_effects(model))


def _effects(model: AxisModel) -> tuple[float, float]:
    gap = float((model.effects.get("backlash") or {}).get("gap_mm", 0.0))
    delay = float((model.effects.get("time_delay") or {}).get("delay_s", 0.0))
    return gap, delay


def excitation(axis: str, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """The command of the identification programs (seed EXCITATION_SEED) for one axis: (x_r, segment)."""
    import gcode_gen
    from gcode_gen.commands import command_programs

    run = command_programs(gcode_gen.generate([axis], seed=EXCITATION_SEED), [axis], Ts=Ts, a_max=2000.0)
    return run.commanded[axis], run.segment


def derive_plant(model: AxisModel, gains: Gains, axis: str = "X", integration: str = "continuous") -> Plant:
    """The plant of one axis (module docstring): coefficient matching, then response matching."""
    start = match_coefficients(model, gains)
    Ts = model.sample_period
    x_r, segment = excitation(axis, Ts)
    target = model.simulate(x_r, segment=segment)
    starts = np.flatnonzero(np.r_[True, segment[1:] != segment[:-1]])
    bounds = np.r_[starts, segment.size]
    kind, Kp, Ki, Kd, Kv, Ka = gains.law()
    delay_periods = int(round(start.delay_s / Ts))
    timing = gains.timing
    if delay_periods:
        from dataclasses import replace

        timing = replace(timing, delay=timing.delay + delay_periods)
    # the fit metric's scale (SPEC §5): rms of the predicted tracking error
    norm = float(np.sqrt(np.mean((x_r - target) ** 2))) or 1.0

    # Friction as the identification saw it: d0/d1 over the coefficient-matched kj.  The
    # continuous model's gain bias scales d0, d1 and the gains alike (docs/linuxcnc.md), so
    # the ratio is unbiased; only a model whose friction has the wrong signs (d0 <= 0 or
    # d1 >= 0: it did not resolve the friction) has the friction fitted with kj and bj.
    fixed = model.model.d0 > 0 > model.model.d1

    def simulate(z: np.ndarray) -> np.ndarray:
        kj, bj = math.exp(z[0]), z[1]
        dp, dm = (start.d_plus, start.d_minus) if fixed else (z[2], z[3])
        out = []
        for a, b in zip(bounds[:-1], bounds[1:]):
            x, _ = simulate_loop(x_r[a:b], Ts, kind=kind, Kp=Kp, Ki=Ki, Kd=Kd, Kv=Kv, Ka=Ka, Kf0=gains.ff0, kj=kj, bj=bj,
                                 d_plus=dp, d_minus=dm, u_max=gains.u_max, timing=timing,
                                 integration=integration)
            out.append(x)
        return np.concatenate(out)

    def resid(z: np.ndarray) -> np.ndarray:
        return (simulate(z) - target) / norm

    z0 = np.array([math.log(start.kj), start.bj, start.d_plus, start.d_minus])
    dscale = max(abs(start.d_plus), abs(start.d_minus), 0.01)
    lb = np.array([z0[0] - math.log(4.0), 0.0, 0.0, -10 * dscale])
    ub = np.array([z0[0] + math.log(4.0), max(10 * start.bj, 0.2 * start.kj * max(Kd, 1e-6), 50.0),
                   10 * dscale, 0.0])
    z0 = np.clip(z0, lb, ub)
    n = 2 if fixed else 4
    z = bounded_lm(resid, z0[:n], lb[:n], ub[:n], max_iter=40).z
    dp, dm = (start.d_plus, start.d_minus) if fixed else (float(z[2]), float(z[3]))
    return Plant(math.exp(z[0]), float(z[1]), dp, dm, start.gap_mm, start.delay_s, integration)

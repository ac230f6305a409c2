"""From the identified closed loop to the plant: kj = K/J, bj = B/J, Coulomb friction, gap.

Given an axis's identified eq. 3.3 model (:class:`ident.axis_model.AxisModel`) and its
controller (:class:`ident.tuning.controllers.Gains`), the plant

    ẍ = kj·(u − d(ẋ)) − bj·ẋ,   d = d⁺ (ẋ > 0), d⁻ (ẋ < 0)        (thesis §3.2, eq. 3.2)

is found in two steps (docs/tuning.md derives both); with the recording the model was
identified from, step 2 is the output-error fit of :mod:`ident.tuning.plant_fit` instead:

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
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from core.errors import IdentificationError
from core.recording import Recording
from ident.axis_model import AxisModel
from ident.least_squares import bounded_lm
from ident.tuning.controllers import Gains, coefficient_rows
from ident.tuning.loop import Timing, simulate_loop

__all__ = ["Plant", "match_coefficients", "derive_plant", "excitation", "EXCITATION_SEED", "form_timing", "loop_response"]

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
    derivation : how it was found: "recording" (the sampled loop fitted to the recorded
        actual positions, :mod:`ident.tuning.plant_fit`) or "model response" (matched to the
        identified model's coefficients and prediction).
    fit_pct : with "recording", the tracking-error fit % (SPEC §5) of the sampled loop around
        this plant on that recording; None otherwise.
    """

    kj: float
    bj: float
    d_plus: float
    d_minus: float
    gap_mm: float = 0.0
    delay_s: float = 0.0
    integration: str = "continuous"
    derivation: str = "model response"
    fit_pct: float | None = None

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


def form_timing(gains: Gains, delay_s: float, Ts: float) -> Timing:
    """The form's sampling with an accepted dead time added as whole periods of delay."""
    periods = int(round(delay_s / Ts))
    return replace(gains.timing, delay=gains.timing.delay + periods) if periods else gains.timing


def loop_response(x_r: np.ndarray, bounds: np.ndarray, Ts: float, gains: Gains, timing: Timing, kj: float, bj: float,
                  d_plus: float, d_minus: float, integration: str) -> np.ndarray:
    """Actual position [mm] of the form's sampled loop around the plant, following ``x_r``
    piece by piece (``bounds``: the start index of each piece and the end), each from rest."""
    kind, Kp, Ki, Kd, Kv, Ka = gains.law()
    out = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        x, _ = simulate_loop(x_r[a:b], Ts, kind=kind, Kp=Kp, Ki=Ki, Kd=Kd, Kv=Kv, Ka=Ka, Kf0=gains.ff0, kj=kj, bj=bj,
                             d_plus=d_plus, d_minus=d_minus, u_max=gains.u_max, timing=timing,
                             integration=integration)
        out.append(x)
    return np.concatenate(out)


def derive_plant(model: AxisModel, gains: Gains, axis: str = "X", integration: str = "continuous",
                 recording: Recording | None = None) -> Plant:
    """The plant of one axis (module docstring).

    Without ``recording``: coefficient matching, then response matching to the identified
    model.  With the recording the model was identified from: coefficient matching, then
    the output-error fit of the sampled loop to that recording
    (:func:`ident.tuning.plant_fit.fit_plant`), which does not go through the model.
    """
    start = match_coefficients(model, gains)
    if recording is not None:
        from ident.tuning.plant_fit import fit_plant  # imports this module

        return fit_plant(recording, axis, gains, start, model.sample_period, integration)
    Ts = model.sample_period
    x_r, segment = excitation(axis, Ts)
    target = model.simulate(x_r, segment=segment)
    starts = np.flatnonzero(np.r_[True, segment[1:] != segment[:-1]])
    bounds = np.r_[starts, segment.size]
    Kd = gains.law()[3]
    timing = form_timing(gains, start.delay_s, Ts)
    # the fit metric's scale (SPEC §5): rms of the predicted tracking error
    norm = float(np.sqrt(np.mean((x_r - target) ** 2))) or 1.0

    # Friction as the identification saw it: d0/d1 over the coefficient-matched kj.  The
    # continuous model's gain bias scales d0, d1 and the gains alike (docs/linuxcnc.md), so
    # the ratio is unbiased; only a model whose friction has the wrong signs (d0 <= 0 or
    # d1 >= 0: it did not resolve the friction) has the friction fitted with kj and bj.
    fixed = model.model.d0 > 0 > model.model.d1

    def resid(z: np.ndarray) -> np.ndarray:
        dp, dm = (start.d_plus, start.d_minus) if fixed else (z[2], z[3])
        x = loop_response(x_r, bounds, Ts, gains, timing, math.exp(z[0]), z[1], dp, dm, integration)
        return (x - target) / norm

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

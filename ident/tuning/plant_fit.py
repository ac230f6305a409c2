"""The plant fitted to the recording: an output-error fit of the sampled closed loop.

With the controller's structure and gains known (:class:`ident.tuning.controllers.Gains`),
the closed loop of the sampled controller around the rigid plant of thesis §3.2

    ẍ = kj·(u − d(ẋ)) − bj·ẋ,   d = d⁺ (ẋ > 0), d⁻ (ẋ < 0)                     (eq. 3.2)

(:func:`ident.tuning.loop.simulate_loop`) has only the plant's four parameters
θ = (kj, bj, d⁺, d⁻) free.  Driven by the *recorded* commanded positions x_r, it is fitted
to the *recorded* actual positions x by bounded Levenberg–Marquardt
(:func:`ident.least_squares.bounded_lm`):

    min_θ  Σ_k (x̂_k(θ; x_r) − x_k)² / σ_e²,   σ_e = std(x_r − x)   (SPEC §5's scale)

started from the coefficient-matching estimate (:func:`ident.tuning.plant.match_coefficients`),
kj searched as log kj.  The identified eq. 3.3 model is not in the loop: where it is only an
*equivalent* model (a pole at its bound, friction of the wrong sign — the P-PI presets, thesis
Table 3.3), its coefficients and its response do not hold the plant, but the recording does.

The loop is simulated continuously where the recording's clock is continuous (a capture of
a controller that kept running between programs) and restarted from rest after a gap in
time.  Accepted effects carry over from the identified model as in the model derivation:
the gap (not simulated here) and the dead time (added to the form's delay).
"""

from __future__ import annotations

import math

import numpy as np

from core.errors import InputError
from core.recording import Recording
from ident.least_squares import bounded_lm
from ident.metrics import tracking_error_fit_pct
from ident.tuning.controllers import Gains
from ident.tuning.plant import Plant, form_timing, loop_response

__all__ = ["fit_plant", "FIT_MIN_PCT"]

#: Below this tracking-error fit % the recording is not one of this controller with these
#: gains (or has physics the rigid plant lacks): the fit is refused rather than used.
FIT_MIN_PCT = 90.0

#: A step of the clock longer than this many periods is a gap: the loop restarts from rest.
GAP_PERIODS = 1.5


def fit_plant(recording: Recording, axis: str, gains: Gains, start: Plant, Ts: float,
              integration: str = "continuous") -> Plant:
    """Fit (kj, bj, d⁺, d⁻) of ``axis`` to ``recording`` through the sampled loop (module docstring).

    Parameters
    ----------
    recording : the capture the axis was identified from (commanded and actual, mm).
    gains : the controller it ran with.
    start : the coefficient-matching plant (the starting point; its gap and delay carry over).
    Ts : the identified model's sample period, s; the recording's must equal it.
    integration : "continuous" or "euler" (:class:`ident.tuning.plant.Plant`).

    Raises InputError (one line) when the recording lacks the axis, has another sample
    period, does not move the axis both ways, or the fitted loop reproduces it to less than
    :data:`FIT_MIN_PCT` %.
    """
    source = recording.metadata.get("source")
    name = f"recording {source}" if source else "the recording"
    if axis not in recording.axes:
        raise InputError.about("recording", f"{name}: no axis {axis} (it has "
                                            f"{', '.join(recording.axis_names)})")
    if not np.isclose(recording.sample_period, Ts, rtol=1e-6):
        raise InputError.about("recording", f"{name}: sample period {recording.sample_period * 1e3:.4g} ms, "
                                            f"the identified model's {Ts * 1e3:.4g} ms: not the recording it was "
                                            f"identified from")
    trace = recording.axes[axis]
    x_r, x = np.asarray(trace.commanded, float), np.asarray(trace.actual, float)
    step = np.diff(x_r)
    for sign, word, what in ((1, "+", "d⁺"), (-1, "−", "d⁻")):
        if not np.any(sign * step > 0):
            raise InputError.about("recording", f"{name}: axis {axis} is never commanded in the {word} "
                                                f"direction: its Coulomb friction {what} cannot be fitted")
    gaps = np.flatnonzero(np.diff(recording.t) > GAP_PERIODS * Ts) + 1
    bounds = np.r_[0, gaps, x_r.size]
    timing = form_timing(gains, start.delay_s, Ts)
    e = x_r - x
    norm = float(np.sqrt(np.mean((e - e.mean()) ** 2))) or 1.0

    def response(z: np.ndarray) -> np.ndarray:
        return loop_response(x_r, bounds, Ts, gains, timing, math.exp(z[0]), z[1], z[2], z[3], integration)

    def resid(z: np.ndarray) -> np.ndarray:
        return (response(z) - x) / norm

    # The box: kj within ×/÷ 4 of the coefficient match (which sets the gains' scale); the
    # friction within the output limit (a drive whose friction exceeds it cannot move).
    d_max = gains.u_max if math.isfinite(gains.u_max) else max(10 * max(abs(start.d_plus), abs(start.d_minus)), 1.0)
    Kd = gains.law()[3]
    lb = np.array([math.log(start.kj) - math.log(4.0), 0.0, 0.0, -d_max])
    ub = np.array([math.log(start.kj) + math.log(4.0), max(2 * start.bj, start.kj * max(Kd, 1e-6), 50.0), d_max, 0.0])
    z0 = np.clip([math.log(start.kj), start.bj, start.d_plus, start.d_minus], lb, ub)
    z = bounded_lm(resid, z0, lb, ub, max_iter=40).z
    fit = tracking_error_fit_pct(e, x_r - response(z))
    if not fit >= FIT_MIN_PCT:
        raise InputError.about("recording", f"{name}: the {gains.form} loop with the fitted plant reproduces "
                                            f"axis {axis}'s tracking error to {fit:.1f} % (< {FIT_MIN_PCT:.0f} %): "
                                            f"are these the gains it ran with?")
    return Plant(math.exp(z[0]), float(z[1]), float(z[2]), float(z[3]), start.gap_mm, start.delay_s, integration,
                 derivation="recording", fit_pct=fit)

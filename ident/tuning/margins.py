"""Stability margins and step response of one axis's sampled loop (docs/tuning.md, "Margins").

The loop is broken at the controller output u.  With the plant ẍ = kj·u − bj·ẋ held by
a ZOH over each period Ts, its sampled position and velocity responses are
(z = e^{jωTs}, a = e^{−bj·Ts})::

    P_x(z) = kj/bj · [ (Ts − (1−a)/bj)·z + ((1−a)/bj − a·Ts) ] / ((z − 1)(z − a))
    P_v(z) = kj/bj · (1 − a) / (z − a)                      (bj → 0: limits taken)

(with the headless LinuxCNC machine's semi-implicit Euler plant, ``integration="euler"``:
P_v = kj·Ts/(z − (1 − bj·Ts)), P_x = Ts·z/(z − 1)·P_v) and the loop gain of each form (e the position error, the feed-forwards outside the loop)::

    PID:   L = z^−d · [ (Kp + Ki·Ts·z/(z−1))·P_x + Kd·V ]
    P-PI:  L = z^−d · (Kd + Ki·Ts·z/(z−1)) · (Kp·P_x + V)

with V = P_v (measured velocity) or (1 − z^−1)/Ts·P_x (backward difference), d the
form's computation delay in periods; an accepted dead time multiplies L by e^{−jω·delay}
and an accepted resonance (freq f_r, damping ζ_r) by ω_r²/(ω_r² − ω² + 2jζ_rω_rω).

Phase margin: 180° + ∠L at the lowest |L| = 1 crossing; gain margin: −20·log10|L| at the
−180° crossings where |L| < 1 (the smallest; inf when there is none below Nyquist).
:func:`loop_margins` takes any L(f) (the analytic tests use a continuous loop).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ident.tuning.controllers import Gains
from ident.tuning.loop import simulate_loop
from ident.tuning.plant import Plant

__all__ = ["Margins", "loop_margins", "open_loop", "margins", "step_overshoot", "PHASE_MARGIN_DEG",
           "GAIN_MARGIN_DB", "OVERSHOOT_LIMIT"]

#: The margins a proposal must keep (issue 42).
PHASE_MARGIN_DEG = 45.0
GAIN_MARGIN_DB = 6.0
#: "No overshoot on a step": a 1 mm move may pass its target by at most this fraction
#: (1 µm: an encoder count or two on a machine tool).
OVERSHOOT_LIMIT = 0.001


@dataclass(frozen=True)
class Margins:
    """Phase margin [deg] at crossover [Hz], gain margin [dB] at the phase crossing [Hz]."""

    phase_margin_deg: float
    crossover_hz: float
    gain_margin_db: float
    phase_crossover_hz: float

    def to_dict(self) -> dict[str, float | None]:
        return {k: (float(v) if math.isfinite(v) else None) for k, v in self.__dict__.items()}


def loop_margins(f_hz: np.ndarray, L: np.ndarray) -> Margins:
    """Margins of a loop gain L sampled at increasing frequencies ``f_hz`` (module docstring).

    The phase is taken in (−180°, 180°]: a loop with two integrators starts near −180° at
    low frequency, which is not a gain-margin crossing (|L| ≫ 1 there, conditionally
    stable); only crossings of −180° where |L| < 1 count for the gain margin, the smallest
    margin over them is reported.  PM = 180° + ∠L at the first |L| = 1 crossing, negative
    when the phase there is beyond −180°.
    """
    f = np.asarray(f_hz, float)
    L = np.asarray(L, complex)
    lm = np.log(np.abs(L))
    pm, fc = math.inf, math.nan
    k = np.flatnonzero((lm[:-1] >= 0) & (lm[1:] < 0))
    if k.size:
        i = k[0]
        w = lm[i] / (lm[i] - lm[i + 1])
        fc = f[i] + w * (f[i + 1] - f[i])
        Lc = L[i] + w * (L[i + 1] - L[i])
        pm = (math.degrees(np.angle(Lc)) + 180.0) % 360.0
        pm = pm - 360.0 if pm > 180.0 else pm
    gm, fp = math.inf, math.nan
    im = L.imag
    for i in np.flatnonzero((np.sign(im[:-1]) != np.sign(im[1:])) & (L.real[:-1] < 0) & (L.real[1:] < 0)):
        w = im[i] / (im[i] - im[i + 1])
        mag = abs(L[i] + w * (L[i + 1] - L[i]))
        if mag < 1.0 and -20.0 * math.log10(mag) < gm:
            gm, fp = -20.0 * math.log10(mag), f[i] + w * (f[i + 1] - f[i])
    return Margins(pm, float(fc), gm, float(fp))


def open_loop(gains: Gains, plant: Plant, Ts: float, f_hz: np.ndarray,
              resonance: tuple[float, float] | None = None) -> np.ndarray:
    """Loop gain L(e^{j2πf·Ts}) of ``gains`` around ``plant`` (module docstring)."""
    kind, Kp, Ki, Kd, _, _ = gains.law()
    f = np.asarray(f_hz, float)
    z = np.exp(2j * math.pi * f * Ts)
    kj, bj = plant.kj, plant.bj
    if plant.integration == "euler":  # v(k) = (1 − bj·Ts)·v(k−1) + kj·Ts·u(k−1), x(k) = x(k−1) + Ts·v(k)
        Pv = kj * Ts / (z - (1 - bj * Ts))
        Px = Ts * z / (z - 1) * Pv
    elif bj * Ts > 1e-9:
        a = math.exp(-bj * Ts)
        Px = kj / bj * ((Ts - (1 - a) / bj) * z + ((1 - a) / bj - a * Ts)) / ((z - 1) * (z - a))
        Pv = kj / bj * (1 - a) / (z - a)
    else:  # double integrator
        Px = kj * Ts * Ts / 2 * (z + 1) / (z - 1) ** 2
        Pv = kj * Ts / (z - 1)
    V = Pv if gains.timing.measured_velocity else (1 - 1 / z) / Ts * Px
    integ = Ki * Ts * z / (z - 1)
    if kind == "ppi":
        L = (Kd + integ) * (Kp * Px + V)
    else:
        L = (Kp + integ) * Px + Kd * V
    L = L * z ** (-gains.timing.delay) * np.exp(-2j * math.pi * f * plant.delay_s)
    if resonance is not None:
        wr, zr = 2 * math.pi * resonance[0], resonance[1]
        w = 2 * math.pi * f
        L = L * wr * wr / (wr * wr - w * w + 2j * zr * wr * w)
    return L


def margins(gains: Gains, plant: Plant, Ts: float, resonance: tuple[float, float] | None = None) -> Margins:
    """Margins of one axis, on 4000 log-spaced frequencies from 0.01 Hz to Nyquist.

    At Nyquist a sampled loop is real: when it is negative there (phase −180°, e.g. with a
    measured velocity) the gain margin is read there too.
    """
    f = np.geomspace(0.01, 0.999 / (2 * Ts), 4000)
    m = loop_margins(f, open_loop(gains, plant, Ts, f, resonance))
    L_ny = complex(open_loop(gains, plant, Ts, np.array([0.5 / Ts]), resonance)[0])
    if L_ny.real < 0 and abs(L_ny.imag) <= 1e-6 * abs(L_ny):
        gm = -20.0 * math.log10(abs(L_ny))
        if gm < m.gain_margin_db:
            m = Margins(m.phase_margin_deg, m.crossover_hz, gm, 0.5 / Ts)
    return m


def move_profile(distance_mm: float, feed: float, a_max: float, Ts: float, hold_s: float) -> np.ndarray:
    """A point-to-point move as an interpolator sends it: trapezoidal (or triangular) velocity, then held."""
    v = min(feed, math.sqrt(a_max * distance_mm))
    t_a = v / a_max
    t_c = distance_mm / v - t_a
    t = np.arange(int(round((2 * t_a + t_c + hold_s) / Ts))) * Ts
    s = np.where(t < t_a, 0.5 * a_max * t * t,
                 np.where(t < t_a + t_c, 0.5 * v * t_a + v * (t - t_a),
                          distance_mm - 0.5 * a_max * np.clip(2 * t_a + t_c - t, 0, None) ** 2))
    return np.r_[np.zeros(int(round(0.01 / Ts))), s]


#: The step a proposal is checked on: 1 mm at 50 mm/s and 2000 mm/s², then held 4 s.
STEP_MM, STEP_FEED, STEP_ACCEL, STEP_HOLD_S = 1.0, 50.0, 2000.0, 4.0


def step_overshoot(gains: Gains, plant: Plant, Ts: float) -> float:
    """Overshoot of a 1 mm point-to-point move past its target, as a fraction of the move.

    The move is what a controller commands for a step (:func:`move_profile`, the
    interpolator's trapezoid), the loop as tuned (feed-forwards included), without friction
    or output limit: the linear loop.  inf when the response does not settle (unstable).
    """
    kind, Kp, Ki, Kd, Kv, Ka = gains.law()
    xr = move_profile(STEP_MM, STEP_FEED, STEP_ACCEL, Ts, STEP_HOLD_S)
    timing = gains.timing
    if plant.delay_s:
        from dataclasses import replace

        timing = replace(timing, delay=timing.delay + int(round(plant.delay_s / Ts)))
    x, _ = simulate_loop(xr, Ts, kind=kind, Kp=Kp, Ki=Ki, Kd=Kd, Kv=Kv, Ka=Ka, Kf0=gains.ff0, kj=plant.kj, bj=plant.bj,
                         timing=timing, integration=plant.integration)
    if not np.all(np.isfinite(x)) or abs(x[-1] - STEP_MM) > 0.02 * STEP_MM:
        return math.inf
    return max(float(x.max()) - STEP_MM, 0.0) / STEP_MM

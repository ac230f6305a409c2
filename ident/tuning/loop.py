"""A digital position loop around a rigid plant: the controller forms the tuner knows, sampled.

The tuner needs the response of *the controller as the machine runs it* around a plant
(thesis Fig. 3.2): eq. 3.3 is the continuous-time form of that loop, but a servo computes
its law once per period Ts, holds the output (ZOH), differentiates by differences and may
act one period late.  Those sample delays are what make an identified eq. 3.3 model's
coefficients differ from eq. 3.4/3.5 evaluated with the true plant (docs/tuning.md), so the
plant is recovered, and the gains are judged, on this sampled loop.

Per servo tick k (the laws of thesis Fig. 3.2, e = x_r − x, v the feedback velocity):

* P-PI (``ppi``):  e_v = Kp·(e + Kv·ẋ_r + Ka·ẍ_r) − v,  u = Kd·e_v + Ki·Ts·Σe_v;
* PID (``pid``):   u = Kp·e + Ki·Ts·Σe + Kd·(ẋ_r − v) + Kf0·x_r + Kv·ẋ_r + Ka·ẍ_r
  (LinuxCNC pid: Kp = P, Ki = I, Kd = D, Kf0 = FF0, Kv = FF1, Ka = FF2);

u clipped to ±u_max (integration stops while clipped; the law and its anti-windup are
:func:`core.pid_law.position_law`, shared with the virtual CNC's servo), applied after
``delay`` whole periods and held.  Plant, per unit inertia (thesis §3.2, eq. 3.2), x in mm::

    ẍ = kj·(u − d(ẋ)) − bj·ẋ,   d = d⁺ moving +, d⁻ moving −, stick while d⁻ ≤ u ≤ d⁺

integrated with ``substeps`` steps per period (velocity exact for the step, friction
direction frozen, a zero crossing stops the body).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from core.pid_law import position_law

__all__ = ["Timing", "simulate_loop"]


@dataclass(frozen=True)
class Timing:
    """How a controller form samples (docs/tuning.md, "Timing").

    central_reference : ẋ_r, ẍ_r by central differences (the interpolator knows the next
        command) rather than backward differences.
    measured_velocity : the feedback velocity is the drive's own (an encoder's velocity
        output, LinuxCNC's feedback-deriv) rather than the backward difference of position.
    delay : whole periods between computing u and applying it.
    previous_target : the position error is taken against the previous period's command
        (e = x_r(k−1) − x(k)) while the derivatives use the current one: LinuxCNC pid's
        ``error-previous-target``, on in the headless test machine (docs/tuning.md).
    """

    central_reference: bool = True
    measured_velocity: bool = False
    delay: int = 0
    previous_target: bool = False


@njit(cache=True)
def _loop(xr, Ts, nsub, ppi, Kp, Ki, Kd, Kv, Ka, Kf0, u_max, kj, bj, dp, dm, central, meas_vel, delay,
          prev_target, euler, out_x, out_u):
    n = xr.shape[0]
    h = Ts / nsub
    x = xr[0]
    v = 0.0
    integ = 0.0
    prev = x
    queue = np.zeros(delay + 1)
    for k in range(n):
        if meas_vel:
            vel = v
        else:
            vel = (x - prev) / Ts if k > 0 else 0.0
        prev = x
        if central and 0 < k < n - 1:
            xrd = (xr[k + 1] - xr[k - 1]) / (2.0 * Ts)
            xrdd = (xr[k + 1] - 2.0 * xr[k] + xr[k - 1]) / (Ts * Ts)
        elif k > 1:
            xrd = (xr[k] - xr[k - 1]) / Ts
            xrdd = (xr[k] - 2.0 * xr[k - 1] + xr[k - 2]) / (Ts * Ts)
        else:
            xrd = 0.0
            xrdd = 0.0
        if prev_target and k > 0:
            e = xr[k - 1] - x
        else:
            e = xr[k] - x
        u, integ = position_law(ppi, e, vel, xrd, xrdd, xr[k], integ, Ts, Kp, Ki, Kd, Kv, Ka, Kf0, u_max)
        out_x[k] = x
        out_u[k] = u
        for j in range(delay):
            queue[j] = queue[j + 1]
        queue[delay] = u
        ua = queue[0]
        if euler:
            # one semi-implicit Euler step; friction as the force that would stop the body
            # within the step, clamped to the Coulomb band (fixtures/linuxcnc/machine.hal)
            a_drive = kj * ua - bj * v
            f = a_drive + v / Ts
            lo, hi = kj * dm, kj * dp
            f = hi if f > hi else (lo if f < lo else f)
            v = v + (a_drive - f) * Ts
            x += v * Ts
            continue
        for _ in range(nsub):
            if v > 0.0:
                s = 1.0
            elif v < 0.0:
                s = -1.0
            else:
                if ua > dp:
                    s = 1.0
                elif ua < dm:
                    s = -1.0
                else:
                    continue  # sticks
            d = dp if s > 0 else dm
            acc = kj * (ua - d)
            # exact velocity over the step for constant drive force: v' = acc − bj·v
            if bj > 0.0:
                ev_ = np.exp(-bj * h)
                v1 = v * ev_ + acc / bj * (1.0 - ev_)
            else:
                v1 = v + acc * h
            if v1 * s < 0.0:  # reverses inside the step: stop at the zero crossing
                frac = v / (v - v1)
                x += 0.5 * v * frac * h
                v = 0.0
            else:
                x += 0.5 * (v + v1) * h
                v = v1


def simulate_loop(x_r: np.ndarray, Ts: float, *, kind: str, Kp: float, Ki: float, Kd: float,
                  Kv: float = 0.0, Ka: float = 0.0, Kf0: float = 0.0, kj: float, bj: float, d_plus: float = 0.0,
                  d_minus: float = 0.0, u_max: float = np.inf, timing: Timing = Timing(),
                  substeps: int = 10, integration: str = "continuous") -> tuple[np.ndarray, np.ndarray]:
    """Actual position x [mm] and control u [V], each (N,), of the sampled loop following ``x_r``.

    Parameters
    ----------
    x_r : commanded position, mm, (N,) at Ts [s].
    kind : "ppi" or "pid" (module docstring for the laws and the gains' units).
    kj : control-to-acceleration gain K/J, mm/(V·s²); bj : viscous pole B/J, 1/s.
    d_plus, d_minus : Coulomb friction as control equivalents, V (d⁺ ≥ 0 ≥ d⁻).
    u_max : output limit, V (inf: none).
    integration : "continuous" (the drive's physics, integrated finely) or "euler" (one
        semi-implicit Euler step per period, v(k) = v(k−1) + a·Ts, x(k) = x(k−1) + v(k)·Ts:
        the plant of the headless LinuxCNC test machine, fixtures/linuxcnc).
    """
    xr = np.ascontiguousarray(np.asarray(x_r, dtype=float))
    x = np.empty_like(xr)
    u = np.empty_like(xr)
    _loop(xr, float(Ts), int(substeps), kind == "ppi", float(Kp), float(Ki), float(Kd), float(Kv), float(Ka),
          float(Kf0), float(u_max) if np.isfinite(u_max) else 1e300, float(kj), float(bj), float(d_plus), float(d_minus),
          bool(timing.central_reference), bool(timing.measured_velocity), int(timing.delay),
          bool(timing.previous_target), integration == "euler", x, u)
    return x, u

"""One period of a servo's position-loop law, thesis Fig. 3.2: the controller forms of the
virtual CNC (:mod:`virtual_cnc.servo`) and of the tuner's sampled loop
(:mod:`ident.tuning.loop`), written once so the two cannot drift apart.

With e = x_r − x the position error and v the feedback velocity:

* P-PI (``ppi``):  e_v = Kp·(e + Kv·ẋ_r + Ka·ẍ_r) − v,  u = Kd·e_v + Ki·Ts·Σe_v;
* PID:             u = Kp·e + Ki·Ts·Σe + Kd·(ẋ_r − v) + Kf0·x_r + Kv·ẋ_r + Ka·ẍ_r.

u is clipped to ±u_max with conditional-integration anti-windup: while the output is
clipped the integrator keeps its old value unless its input drives the output back from
the limit.  Compiled (numba) so the kernels that call it inline it per tick.
"""

from __future__ import annotations

from numba import njit

__all__ = ["position_law"]


@njit(cache=True, nogil=True)
def position_law(ppi: bool, e: float, vel: float, xrd: float, xrdd: float, xr: float, integ: float,
                 Ts: float, Kp: float, Ki: float, Kd: float, Kv: float, Ka: float, Kf0: float,
                 u_max: float) -> tuple[float, float]:
    """The control u [V] of one period and the integrator's state after it.

    Parameters
    ----------
    ppi : the P-PI cascade (True) or the PID (False) law (module docstring).
    e : position error x_r − x, mm; vel : feedback velocity, mm/s.
    xrd, xrdd : commanded velocity and acceleration, mm/s and mm/s².
    xr : commanded position, mm (only the PID's Kf0 term uses it).
    integ : the integrator's state before this period (Σ of its input times Ts).
    Kp … Kf0 : the gains in the units of the law; u_max : output limit, V.
    """
    if ppi:
        ev = Kp * (e + Kv * xrd + Ka * xrdd) - vel
        w = ev
        i_new = integ + Ts * ev
        u = Kd * ev + Ki * i_new
    else:
        w = e
        i_new = integ + Ts * e
        u = Kp * e + Ki * i_new + Kd * (xrd - vel) + Kf0 * xr + Kv * xrd + Ka * xrdd
    if u > u_max:
        u = u_max
        if w <= 0.0:
            integ = i_new
    elif u < -u_max:
        u = -u_max
        if w >= 0.0:
            integ = i_new
    else:
        integ = i_new
    return u, integ

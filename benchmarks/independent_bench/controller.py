"""Drive controllers sampled at the servo rate (1 kHz), force (current) output with a limit.

Inputs per sample ``k``: command ``x_r[k]``, the position feedback ``y[k]`` (motor encoder
when semi-closed, table scale when full-closed) and the motor encoder ``y_m[k]`` for the
velocity loop (a real dual-loop drive: the velocity loop always runs on the motor encoder).
Derived as a drive does: ``v_r = (x_r[k] - x_r[k-1]) / Ts``, ``a_r = (v_r[k] - v_r[k-1]) / Ts``,
measured velocity ``v_y`` = backward difference of ``y_m`` through a first-order low-pass
(``alpha = 1 - exp(-2 pi f_vf Ts)``).

Cascade P-PI (kind 0)::

    v_cmd = Kp (x_r - y) + kvff v_r
    I    += Ki (v_cmd - v_y) Ts                      # no anti-windup
    u     = Kv (v_cmd - v_y) + I + kaff m_ff a_r

PID (kind 1), derivative on the measurement::

    I    += Ki (x_r - y) Ts                          # no anti-windup
    u     = Kp (x_r - y) + I - Kd v_y + kvff (Kd + B_ff) v_r + kaff m_ff a_r

Force applied: ``F = clip(u, -F_max, F_max)`` (amplifier current limit).

Tuning (:func:`tune_ppi`, :func:`tune_pid`) for a rigid mass ``m``: P-PI with velocity
bandwidth ``f_v`` (``Kv = 2 pi f_v m``, PI corner at ``f_v / 4``) and position gain ``Kp``
(1/s); PID by placing the three closed-loop poles at ``-w``:
``m s^3 + Kd s^2 + Kp s + Ki = m (s + w)^3``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

KIND, KP, KV, KI, KD, KVFF, KAFF, M_FF, F_MAX, ALPHA, B_FF = range(11)
N_CTRL = 11
# controller state
S_I, S_YPREV, S_VY, S_XRPREV, S_VRPREV = range(5)
N_CSTATE = 5


@dataclass(frozen=True)
class ControllerParams:
    kind: str = "ppi"          # "ppi" (cascade P-PI) or "pid"
    kp: float = 30.0           # P-PI: 1/s;  PID: N/m
    kv: float = 1.0e5          # P-PI velocity gain, N s/m
    ki: float = 1.0e7          # P-PI: N/m;  PID: N/(m s)
    kd: float = 0.0            # PID: N s/m
    kvff: float = 0.0          # velocity feed-forward, 0..1
    kaff: float = 0.0          # acceleration feed-forward, 0..1
    m_ff: float = 0.0          # mass used by the acceleration feed-forward, kg
    f_max: float = 1.0e9       # N, force limit
    f_vf: float = 500.0        # Hz, velocity-measurement filter
    b_ff: float = 0.0          # N s/m, viscous term of the PID velocity feed-forward
    Ts: float = 0.001

    def pack(self) -> np.ndarray:
        c = np.zeros(N_CTRL)
        c[KIND] = 0.0 if self.kind == "ppi" else 1.0
        c[KP], c[KV], c[KI], c[KD] = self.kp, self.kv, self.ki, self.kd
        c[KVFF], c[KAFF], c[M_FF], c[F_MAX] = self.kvff, self.kaff, self.m_ff, self.f_max
        c[ALPHA] = 1.0 - math.exp(-2.0 * math.pi * self.f_vf * self.Ts)
        c[B_FF] = self.b_ff
        return c


def tune_ppi(m: float, f_v: float, kp: float, **kw) -> ControllerParams:
    """Cascade P-PI for a rigid mass ``m`` (kg): velocity bandwidth ``f_v`` Hz, position gain ``kp`` 1/s."""
    kv = 2.0 * math.pi * f_v * m
    return ControllerParams(kind="ppi", kp=kp, kv=kv, ki=kv * 2.0 * math.pi * f_v / 4.0, m_ff=m, **kw)


def tune_pid(m: float, w: float, **kw) -> ControllerParams:
    """PID with the closed-loop poles of a rigid mass ``m`` at ``-w`` (rad/s, triple)."""
    return ControllerParams(kind="pid", kp=3.0 * m * w * w, ki=m * w ** 3, kd=3.0 * m * w, m_ff=m, **kw)


@njit(cache=True)
def control_step(xr, y, ym, cs, c, Ts, first):
    """One servo sample: update the controller state ``cs`` in place, return the limited force, N."""
    if first:
        cs[S_YPREV] = ym
        cs[S_XRPREV] = xr
    vr = (xr - cs[S_XRPREV]) / Ts
    ar = (vr - cs[S_VRPREV]) / Ts
    cs[S_XRPREV] = xr
    cs[S_VRPREV] = vr
    vy_raw = (ym - cs[S_YPREV]) / Ts
    cs[S_YPREV] = ym
    cs[S_VY] += c[ALPHA] * (vy_raw - cs[S_VY])
    vy = cs[S_VY]
    e = xr - y
    if c[KIND] == 0.0:
        v_cmd = c[KP] * e + c[KVFF] * vr
        ev = v_cmd - vy
        cs[S_I] += c[KI] * ev * Ts
        u = c[KV] * ev + cs[S_I] + c[KAFF] * c[M_FF] * ar
    else:
        cs[S_I] += c[KI] * e * Ts
        u = c[KP] * e + cs[S_I] - c[KD] * vy + c[KVFF] * (c[KD] + c[B_FF]) * vr + c[KAFF] * c[M_FF] * ar
    if u > c[F_MAX]:
        return c[F_MAX]
    if u < -c[F_MAX]:
        return -c[F_MAX]
    return u

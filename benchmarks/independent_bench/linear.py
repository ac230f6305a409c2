"""Linearised closed loop of a two-mass drive: where its lightly damped mode sits.

The two-mass plant's free mode ``sqrt(k (1/m_m + 1/m_t))`` is not what a recording shows
when the velocity loop holds the motor (then the table rings near ``sqrt(k / m_t)``).  The
"truth" a diagnosis should find is the closed-loop mode: the least-damped complex pole
pair of the continuous-time loop (sampling, filter, friction nonlinearity, limit ignored;
friction linearised as the viscous term), states ``[x_m, v_m, x_t, v_t, I]``::

    m_m v_m' = u - k (x_m - x_t) - c (v_m - v_t) - B_m v_m
    m_t v_t' =     k (x_m - x_t) + c (v_m - v_t) - B_t v_t
    P-PI:  ev = -Kp y - v_m,  u = Kv ev + I,  I' = Ki ev
    PID:   e  = -y,           u = Kp e + I - Kd v_m,  I' = Ki e

with ``y = x_m`` (semi-closed) or ``x_t`` (full-closed).
"""

from __future__ import annotations

import math

import numpy as np

from .simulate import Drive


def closed_loop_matrix(drive: Drive) -> np.ndarray:
    p, c, s = drive.plant, drive.controller, drive.sensors
    k, cl, mm, mt = p.k_link, p.c_link, p.m_m, p.m_t
    A = np.zeros((5, 5))
    A[0, 1] = 1.0
    A[2, 3] = 1.0
    # plant part (without u)
    A[1, :4] = [-k / mm, -(cl + p.b_m) / mm, k / mm, cl / mm]
    A[3, :4] = [k / mt, cl / mt, -k / mt, -(cl + p.b_t) / mt]
    iy = 2 if s.full_closed else 0
    # u = g . state  (row vector), I' = h . state
    g = np.zeros(5)
    h = np.zeros(5)
    if c.kind == "ppi":
        ev = np.zeros(5)
        ev[iy] -= c.kp
        ev[1] -= 1.0
        g = c.kv * ev
        g[4] += 1.0
        h = c.ki * ev
    else:
        g[iy] -= c.kp
        g[4] += 1.0
        g[1] -= c.kd
        h[iy] -= c.ki
    A[1] += g / mm
    A[4] = h
    return A


def closed_loop_mode(drive: Drive, f_min: float = 5.0, f_max: float = 500.0) -> tuple[float, float]:
    """(natural frequency Hz, damping ratio) of the least-damped complex closed-loop pole pair."""
    lam = np.linalg.eigvals(closed_loop_matrix(drive))
    best = (float("nan"), float("inf"))
    for z in lam:
        if z.imag <= 0:
            continue
        wn = abs(z)
        f = wn / (2 * math.pi)
        zeta = -z.real / wn
        if f_min <= f <= f_max and zeta < best[1]:
            best = (f, zeta)
    return best

"""The lumped feed-drive plant: motor (rotary inertia as an equivalent linear mass) and table.

Bodies (SI units, positions in m):

- rigid (``two_mass=False``): one body of mass ``m_m + m_t``;
  ``(m_m+m_t) a = F_u + F_rip(x) + F_ext - B_m v - F_f``
- two-mass: motor ``m_m a_m = F_u + F_rip(x_m) - B_m v_m - F_link``,
  table ``m_t a_t = F_link + F_ext - F_f``.

Link (ball screw / coupling), ``d = x_m - x_t``, ``w = v_m - v_t``:

- no gap: ``F_link = k d + c w``
- gap ``g`` (backlash): contact only when ``|d| > g/2``;
  ``F_link = k (d - g/2) + c w`` (clipped at >= 0) for ``d > g/2``,
  ``F_link = k (d + g/2) + c w`` (clipped at <= 0) for ``d < -g/2``, else 0
  (contact stiffness and damping, not a dead zone on position).

Friction on the table guideways (the body that carries it), asymmetric:
``F_slip(v) = sgn(v) [F_c± + (F_s± - F_c±) exp(-(|v|/v_s)^delta)] + B_t v``
(``±`` the level for positive/negative motion), with a Karnopp stick model: inside the
velocity band ``|v| < dv`` the body sticks (friction balances the other forces, velocity
reset to 0) while ``-F_s- <= F_other <= F_s+``; above it breaks away with ``F_s`` of that
direction.  A slipping body whose velocity would cross zero within a step is stopped.

Cogging / force ripple on the motor: ``F_rip = A_r sin(2 pi x_m / P_r + phi_r)``.

Integration: semi-implicit (symplectic) Euler in sub-steps of ``dt`` (the loop uses
20 sub-steps per 1 ms servo sample, 20 kHz).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

# indices of the packed parameter vector
M_M, M_T, TWO_MASS, K_LINK, C_LINK, GAP = 0, 1, 2, 3, 4, 5
FC_POS, FC_NEG, FS_POS, FS_NEG, V_S, DELTA, B_T, B_M = 6, 7, 8, 9, 10, 11, 12, 13
RIP_A, RIP_P, RIP_PHI, DV = 14, 15, 16, 17
N_PLANT = 18


@dataclass(frozen=True)
class PlantParams:
    """Plant parameters (SI).  ``m_m`` is the motor+screw inertia as an equivalent linear mass."""

    m_m: float = 150.0                 # kg (J (2 pi / lead)^2)
    m_t: float = 150.0                 # kg
    two_mass: bool = False
    k_link: float = 2.0e8              # N/m (screw stiffness or contact stiffness)
    c_link: float = 2.0e4              # N s/m
    gap: float = 0.0                   # m (backlash)
    fc_pos: float = 20.0               # N, Coulomb level for v > 0
    fc_neg: float = 20.0               # N, for v < 0 (magnitude)
    fs_pos: float = 20.0               # N, static (breakaway) level, v > 0
    fs_neg: float = 20.0               # N
    v_s: float = 1.0e-3                # m/s, Stribeck velocity
    delta: float = 2.0                 # Stribeck exponent (1 or 2)
    b_t: float = 100.0                 # N s/m, viscous (guideways)
    b_m: float = 0.0                   # N s/m, viscous (motor bearings)
    ripple_amp: float = 0.0            # N, cogging / force ripple
    ripple_period: float = 0.005       # m
    ripple_phase: float = 0.0          # rad
    dv: float = 1.0e-6                 # m/s, Karnopp stick band

    @property
    def m_total(self) -> float:
        return self.m_m + self.m_t

    def resonance_hz(self) -> float:
        """Natural frequency of the free two-mass mode (motor against table), Hz."""
        mu = self.m_m * self.m_t / self.m_total
        return math.sqrt(self.k_link / mu) / (2.0 * math.pi)

    def pack(self) -> np.ndarray:
        p = np.zeros(N_PLANT)
        p[M_M], p[M_T], p[TWO_MASS] = self.m_m, self.m_t, float(self.two_mass)
        p[K_LINK], p[C_LINK], p[GAP] = self.k_link, self.c_link, self.gap
        p[FC_POS], p[FC_NEG], p[FS_POS], p[FS_NEG] = self.fc_pos, self.fc_neg, self.fs_pos, self.fs_neg
        p[V_S], p[DELTA], p[B_T], p[B_M] = self.v_s, self.delta, self.b_t, self.b_m
        p[RIP_A], p[RIP_P], p[RIP_PHI], p[DV] = self.ripple_amp, self.ripple_period, self.ripple_phase, self.dv
        return p


@njit(cache=True)
def slip_friction(v, p):
    """Friction force opposing motion at velocity ``v != 0`` (Stribeck + viscous), N."""
    if v > 0.0:
        fc, fs = p[FC_POS], p[FS_POS]
        s = 1.0
    else:
        fc, fs = p[FC_NEG], p[FS_NEG]
        s = -1.0
    level = fc + (fs - fc) * math.exp(-((abs(v) / p[V_S]) ** p[DELTA]))
    return s * level + p[B_T] * v


@njit(cache=True)
def link_force(d, w, p):
    """Force the motor exerts on the table through the screw / gap, N."""
    g2 = 0.5 * p[GAP]
    k, c = p[K_LINK], p[C_LINK]
    if g2 <= 0.0:
        return k * d + c * w
    if d > g2:
        f = k * (d - g2) + c * w
        return f if f > 0.0 else 0.0
    if d < -g2:
        f = k * (d + g2) + c * w
        return f if f < 0.0 else 0.0
    return 0.0


@njit(cache=True)
def karnopp_step(v, f_other, m, dt, p):
    """One semi-implicit Euler velocity update of a body with guideway friction.

    Returns the new velocity.  ``f_other`` is every force on the body but friction.
    """
    if abs(v) < p[DV]:
        if -p[FS_NEG] <= f_other <= p[FS_POS]:
            return 0.0                                   # stuck: friction balances f_other
        f_fr = p[FS_POS] if f_other > 0.0 else -p[FS_NEG]  # breakaway
        return v + dt * (f_other - f_fr) / m
    v_new = v + dt * (f_other - slip_friction(v, p)) / m
    if v_new * v < 0.0:
        return 0.0                                       # stops within the step
    return v_new


@njit(cache=True)
def substep(state, f_u, f_ext, dt, p):
    """Advance ``state = [x_m, v_m, x_t, v_t]`` by ``dt`` under motor force ``f_u`` and load ``f_ext``."""
    x_m, v_m, x_t, v_t = state[0], state[1], state[2], state[3]
    f_rip = 0.0
    if p[RIP_A] != 0.0:
        f_rip = p[RIP_A] * math.sin(2.0 * math.pi * x_m / p[RIP_P] + p[RIP_PHI])
    if p[TWO_MASS] == 0.0:
        m = p[M_M] + p[M_T]
        v = karnopp_step(v_m, f_u + f_rip + f_ext - p[B_M] * v_m, m, dt, p)
        x = x_m + dt * v
        state[0], state[1], state[2], state[3] = x, v, x, v
        return
    fl = link_force(x_m - x_t, v_m - v_t, p)
    v_m_new = v_m + dt * (f_u + f_rip - p[B_M] * v_m - fl) / p[M_M]
    v_t_new = karnopp_step(v_t, fl + f_ext, p[M_T], dt, p)
    state[0] = x_m + dt * v_m_new
    state[1] = v_m_new
    state[2] = x_t + dt * v_t_new
    state[3] = v_t_new

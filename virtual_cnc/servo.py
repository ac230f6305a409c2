"""The servo loop of the virtual CNC: digital controller at Ts with ZOH, plant integrated finely.

Timing, per servo tick k (t_k = k·Ts):

1. the encoders are read at t_k: the table (load-side) position, quantised + noise, is the
   "actual" position returned and used by the position terms; the velocity/derivative
   terms use the backward difference of the motor encoder (the same encoder on a rigid
   axis) — a full-closed-loop axis, the usual CNC arrangement;
2. the controller computes u_k (see :mod:`virtual_cnc.drive` for the laws; reference
   derivatives by central differences of x_r, which the interpolator knows ahead; the
   integrator is a rectangular sum with anti-windup while saturated);
3. u_k is clipped to the actuator limit, quantised by the DAC and held (ZOH) over
   [t_k, t_k + Ts) — no computation delay beyond the inherent ZOH;
4. the plant is integrated over the period with ``substeps`` classical RK4 steps
   (friction events located inside a step, see below).

Friction is handled with a stick/slip state machine: within a step the friction direction
is frozen; a body at rest stays exactly at rest while the applied force is inside the
breakaway band [r·d⁻, r·d⁺] (r = Stribeck static/Coulomb ratio, 1 without Stribeck); when
the velocity crosses zero inside a step the crossing instant is located, the body is
integrated up to it and stopped, and the rest of the step restarts from rest (stick, or
slide whichever way the applied force breaks away).  The rest state is chatter-free and
reversals converge quickly with the step (tests/test_sim_servo.py: a rigid drive with
Coulomb friction changes by < 1e-8 mm from 20 to 40 substeps; with a 100 Hz two-mass mode
and Stribeck friction by < 1e-5 mm).  Presets use 20 substeps (20 kHz at Ts = 1 ms).

Delays: ``time_delay`` at the actuation reads u from ``delay_s`` earlier (resolved to the
plant step), at the feedback/capture from a per-plant-step position history.

Plant (per unit total inertia J; forces in mm/s²; μ = motor share of J):

    rigid:     ẍ  = (K/J)(u − d(ẋ)) − (B/J)ẋ + c(x)
    two-mass:  μ·ẍ_m = (K/J)u − μ(B/J)ẋ_m − F + c(x_m)
               (1−μ)·ẍ_t = F − (1−μ)(B/J)ẋ_t − (K/J)d(ẋ_t)
               F = k·δ + c_d·δ̇ (δ = x_m − x_t), or with backlash gap g the dead-zone contact
               F = k(δ ∓ g/2) + c_d·δ̇ outside |δ| ≤ g/2, never pulling.

with c(x) = −A·sin(2πx/P + φ) the cyclic disturbance.  The hot loop is numba-compiled.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from core.errors import InputError
from core.pid_law import position_law
from virtual_cnc.drive import AxisDrive
from virtual_cnc.effects import (
    Backlash,
    CyclicError,
    Effect,
    Resonance,
    Saturation,
    Stribeck,
    TimeDelay,
)

if TYPE_CHECKING:
    from virtual_cnc.presets import Machine

__all__ = ["AxisResponse", "simulate_axis", "simulate_axis_response", "simulate_machine"]

#: Damping ratio of the motor–table contact used for backlash without a resonance.
BACKLASH_CONTACT_DAMPING = 0.5


@dataclass(frozen=True)
class AxisResponse:
    """Everything one axis simulation produced, each (N,) at the servo ticks t_k = k·Ts.

    actual : encoder reading of the table (quantised + noise) [mm] — the recorded actual.
    table : true table position [mm].
    motor : true motor-side position [mm] (equals ``table`` on a rigid axis).
    u : control command applied after limit and DAC [V].
    """

    actual: np.ndarray
    table: np.ndarray
    motor: np.ndarray
    u: np.ndarray


# ----------------------------------------------------------------------------- kernel

@njit(cache=True)
def _friction(s, v, kj, d_pos, d_neg, rs, vs):
    """Friction force per unit J [mm/s²] for sliding direction s (±1) at velocity v."""
    shape = 1.0
    if vs > 0.0 and rs != 1.0:
        w = v / vs
        shape = 1.0 + (rs - 1.0) * math.exp(-w * w)
    if s > 0:
        return kj * d_pos * shape
    return kj * d_neg * shape


@njit(cache=True)
def _cyclic(x, amp, period, phase):
    if amp == 0.0:
        return 0.0
    return -amp * math.sin(2.0 * math.pi * x / period + phase)


@njit(cache=True)
def _coupling(d, dd, k, c, half_gap):
    """Motor→table force per unit J [mm/s²] for deflection d = x_m − x_t and its rate dd."""
    if half_gap <= 0.0:
        return k * d + c * dd
    if d > half_gap:
        f = k * (d - half_gap) + c * dd
        return f if f > 0.0 else 0.0
    if d < -half_gap:
        f = k * (d + half_gap) + c * dd
        return f if f < 0.0 else 0.0
    return 0.0


@njit(cache=True)
def _slide_direction(f_app, kj, d_pos, d_neg, rs):
    """Direction a body at rest starts to slide under applied force f_app, 0 if it sticks."""
    if f_app > kj * d_pos * rs:
        return 1
    if f_app < kj * d_neg * rs:
        return -1
    return 0


# Plant parameters travel as one tuple P (indices below) to keep signatures short.
_KJ, _BJ, _DPOS, _DNEG, _RS, _VS, _AMP, _PER, _PHA, _MU, _KSP, _CSP, _HGAP = range(13)


@njit(cache=True)
def _acc_rigid(x, v, s, u, P):
    return (P[_KJ] * u - P[_BJ] * v - _friction(s, v * s, P[_KJ], P[_DPOS], P[_DNEG], P[_RS], P[_VS])
            + _cyclic(x, P[_AMP], P[_PER], P[_PHA]))


@njit(cache=True)
def _acc_two(xm, vm, xt, vt, s, u, P):
    mu = P[_MU]
    f = _coupling(xm - xt, vm - vt, P[_KSP], P[_CSP], P[_HGAP])
    am = (P[_KJ] * u - mu * P[_BJ] * vm - f + _cyclic(xm, P[_AMP], P[_PER], P[_PHA])) / mu
    if s == 0:  # table stuck
        return am, 0.0
    at = (f - (1.0 - mu) * P[_BJ] * vt
          - _friction(s, vt * s, P[_KJ], P[_DPOS], P[_DNEG], P[_RS], P[_VS])) / (1.0 - mu)
    return am, at


@njit(cache=True)
def _rk4_rigid(x, v, s, u, dt, P):
    """One classical RK4 step of the rigid body with friction direction s frozen."""
    a1 = _acc_rigid(x, v, s, u, P)
    v2 = v + 0.5 * dt * a1
    a2 = _acc_rigid(x + 0.5 * dt * v, v2, s, u, P)
    v3 = v + 0.5 * dt * a2
    a3 = _acc_rigid(x + 0.5 * dt * v2, v3, s, u, P)
    v4 = v + dt * a3
    a4 = _acc_rigid(x + dt * v3, v4, s, u, P)
    return (x + dt / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4),
            v + dt / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4))


@njit(cache=True)
def _rk4_two(xm, vm, xt, vt, s, u, dt, P):
    """One classical RK4 step of the two-mass drive with the table's friction direction frozen."""
    am1, at1 = _acc_two(xm, vm, xt, vt, s, u, P)
    vm2 = vm + 0.5 * dt * am1
    vt2 = vt + 0.5 * dt * at1
    am2, at2 = _acc_two(xm + 0.5 * dt * vm, vm2, xt + 0.5 * dt * vt, vt2, s, u, P)
    vm3 = vm + 0.5 * dt * am2
    vt3 = vt + 0.5 * dt * at2
    am3, at3 = _acc_two(xm + 0.5 * dt * vm2, vm3, xt + 0.5 * dt * vt2, vt3, s, u, P)
    vm4 = vm + dt * am3
    vt4 = vt + dt * at3
    am4, at4 = _acc_two(xm + dt * vm3, vm4, xt + dt * vt3, vt4, s, u, P)
    return (xm + dt / 6.0 * (vm + 2.0 * vm2 + 2.0 * vm3 + vm4),
            vm + dt / 6.0 * (am1 + 2.0 * am2 + 2.0 * am3 + am4),
            xt + dt / 6.0 * (vt + 2.0 * vt2 + 2.0 * vt3 + vt4),
            vt + dt / 6.0 * (at1 + 2.0 * at2 + 2.0 * at3 + at4))


@njit(cache=True)
def _plant_step_rigid(x, v, u, h, P):
    """Advance the rigid body by h with stick/slip events located inside the step.

    Friction direction is frozen over a sub-interval; when the velocity crosses zero the
    crossing instant is located (linear interpolation of v), the body is integrated up to
    it, stopped, and the rest of the step restarts from rest (stick, or slide whichever way
    the applied force breaks away).
    """
    remaining = h
    for _ in range(4):  # at most a few friction events per plant step
        if v > 0.0:
            s = 1
        elif v < 0.0:
            s = -1
        else:
            f_app = P[_KJ] * u + _cyclic(x, P[_AMP], P[_PER], P[_PHA])
            s = _slide_direction(f_app, P[_KJ], P[_DPOS], P[_DNEG], P[_RS])
            if s == 0:
                return x, 0.0  # stuck for the rest of the step
        x1, v1 = _rk4_rigid(x, v, s, u, remaining, P)
        if v1 * s > 0.0:
            return x1, v1
        theta = v / (v - v1) if v != v1 else 0.0  # fraction of the step to the zero crossing
        if theta > 0.0:
            x, _v = _rk4_rigid(x, v, s, u, theta * remaining, P)
        v = 0.0
        remaining *= 1.0 - theta
        if remaining <= 0.0:
            break
    return x, v


@njit(cache=True)
def _plant_step_two(xm, vm, xt, vt, u, h, P):
    """Advance the two-mass drive by h; the table's stick/slip events are located as above."""
    remaining = h
    for _ in range(4):
        if vt > 0.0:
            s = 1
        elif vt < 0.0:
            s = -1
        else:
            f_app = _coupling(xm - xt, vm, P[_KSP], P[_CSP], P[_HGAP])
            s = _slide_direction(f_app, P[_KJ], P[_DPOS], P[_DNEG], P[_RS])
        xm1, vm1, xt1, vt1 = _rk4_two(xm, vm, xt, vt, s, u, remaining, P)
        if s == 0:
            # stuck table: re-check breakaway at the end of the step (next step)
            return xm1, vm1, xt, 0.0
        if vt1 * s > 0.0:
            return xm1, vm1, xt1, vt1
        theta = vt / (vt - vt1) if vt != vt1 else 0.0
        if theta > 0.0:
            xm, vm, xt, _v = _rk4_two(xm, vm, xt, vt, s, u, theta * remaining, P)
        vt = 0.0
        remaining *= 1.0 - theta
        if remaining <= 0.0:
            break
    return xm, vm, xt, vt


@njit(cache=True)
def _quantise(x, res):
    if res > 0.0:
        return res * math.floor(x / res + 0.5)
    return x


@njit(cache=True)
def _servo_loop(xr, noise_t, noise_m, Ts, nsub, ppi, Kp, Ki, Kd, Kv, Ka, u_max, dac_res, enc_res,
                two_mass, P, delay_sub, delay_fb, delay_cap, out_meas, out_u, out_xt, out_xm):
    n = xr.shape[0]
    h = Ts / nsub
    xt = xr[0]
    vt = 0.0
    xm = xr[0]
    vm = 0.0
    integ = 0.0
    prev_m = _quantise(xr[0], enc_res)
    # position history at every plant step, for feedback / capture dead time
    keep = delay_fb > 0 or delay_cap > 0
    hist_t = np.empty(n * nsub if keep else 1)
    hist_m = np.empty(n * nsub if keep else 1)
    for kk in range(n):
        if keep:
            hist_t[kk * nsub] = xt
            hist_m[kk * nsub] = xm
        # 1. measure at t_k (at t_k - delay with feedback dead time)
        pt = xt
        pm = xm
        if delay_fb > 0:
            i = kk * nsub - delay_fb
            pt = hist_t[i] if i >= 0 else xr[0]
            pm = hist_m[i] if i >= 0 else xr[0]
        meas_t = _quantise(pt + noise_t[kk], enc_res)
        if two_mass:
            meas_m = _quantise(pm + noise_m[kk], enc_res)
        else:
            meas_m = meas_t
        # the recorded actual: the same reading, or an older one with capture dead time
        if delay_cap > 0:
            i = kk * nsub - delay_cap
            rec = _quantise((hist_t[i] if i >= 0 else xr[0]) + noise_t[kk], enc_res)
        else:
            rec = meas_t
        vel_fb = (meas_m - prev_m) / Ts if kk > 0 else 0.0
        prev_m = meas_m
        # reference derivatives (central differences; one-sided at the ends)
        if n == 1:
            xrd = 0.0
            xrdd = 0.0
        elif kk == 0:
            xrd = (xr[1] - xr[0]) / Ts
            xrdd = 0.0
        elif kk == n - 1:
            xrd = (xr[kk] - xr[kk - 1]) / Ts
            xrdd = 0.0
        else:
            xrd = (xr[kk + 1] - xr[kk - 1]) / (2.0 * Ts)
            xrdd = (xr[kk + 1] - 2.0 * xr[kk] + xr[kk - 1]) / (Ts * Ts)
        # 2. control law, 3. actuator limit with anti-windup (conditional integration), DAC
        e = xr[kk] - meas_t
        u, integ = position_law(ppi, e, vel_fb, xrd, xrdd, 0.0, integ, Ts, Kp, Ki, Kd, Kv, Ka, 0.0, u_max)
        u = _quantise(u, dac_res)
        out_u[kk] = u
        out_meas[kk] = rec
        out_xt[kk] = xt
        out_xm[kk] = xm if two_mass else xt
        # 4. plant over [t_k, t_k + Ts), u held (ZOH), delayed by delay_sub plant steps
        for j in range(nsub):
            if keep and j > 0:
                hist_t[kk * nsub + j] = xt
                hist_m[kk * nsub + j] = xm if two_mass else xt
            idx = kk * nsub + j - delay_sub
            if idx < 0:
                ua = 0.0
            elif delay_sub == 0:
                ua = u
            else:
                ua = out_u[idx // nsub]
            if two_mass:
                xm, vm, xt, vt = _plant_step_two(xm, vm, xt, vt, ua, h, P)
            else:
                xt, vt = _plant_step_rigid(xt, vt, ua, h, P)
                xm = xt


# ----------------------------------------------------------------------------- wrappers

def _effects_for(effects: Sequence[Effect]) -> dict[str, Effect]:
    by_kind: dict[str, Effect] = {}
    for eff in effects:
        if eff.name in by_kind:
            raise InputError(f"effect {eff.name!r} given twice for the same axis")
        by_kind[eff.name] = eff
    return by_kind


def simulate_axis_response(
    x_r: np.ndarray,
    axis: AxisDrive,
    effects: Sequence[Effect] = (),
    rng: np.random.Generator | None = None,
    Ts: float | None = None,
) -> AxisResponse:
    """Run the servo loop of ``axis`` on the commanded positions ``x_r`` [mm] sampled at Ts.

    Parameters
    ----------
    x_r : (N,) commanded position [mm] at t_k = k·Ts; the axis starts at rest at x_r[0].
    axis : controller, plant, encoder, period and substeps.
    effects : extra physics (:mod:`virtual_cnc.effects`), at most one of each kind; their
        ``axis`` field is ignored here (see :func:`simulate_machine`).
    rng : source of the encoder noise; a fresh ``default_rng(0)`` when None.
    Ts : servo period [s]; defaults to ``axis.Ts``.
    """
    xr = np.ascontiguousarray(np.asarray(x_r, dtype=np.float64))
    if xr.ndim != 1 or xr.size == 0:
        raise InputError(f"commanded positions must be a non-empty 1-D array, got shape {xr.shape}")
    if not np.all(np.isfinite(xr)):
        bad = int(np.flatnonzero(~np.isfinite(xr))[0])
        raise InputError(f"commanded position is not finite at sample {bad}: {xr[bad]!r}")
    Ts = axis.Ts if Ts is None else float(Ts)
    if not (math.isfinite(Ts) and Ts > 0):
        raise InputError(f"servo period Ts must be > 0 s, got {Ts!r}")
    rng = np.random.default_rng(0) if rng is None else rng
    n = xr.size
    nsub = axis.substeps
    h = Ts / nsub
    c, p, enc = axis.controller, axis.plant, axis.encoder
    fx = _effects_for(effects)

    two_mass = False
    mu = 0.5
    k_sp = c_sp = half_gap = 0.0
    res = fx.get("resonance")
    bl = fx.get("backlash")
    if isinstance(res, Resonance):
        two_mass = True
        mu = res.motor_fraction
        w = 2 * math.pi * res.freq_hz
        zeta = res.damping
    elif isinstance(bl, Backlash):
        two_mass = True
        mu = bl.motor_fraction
        w = 2 * math.pi * bl.contact_freq_hz
        zeta = BACKLASH_CONTACT_DAMPING
    if two_mass:
        if w * h > 2 * math.pi / 10:  # RK4 needs >= 10 steps per period of the mode
            raise InputError(
                f"mode at {w / (2 * math.pi):g} Hz is too fast for the plant step {h:g} s; "
                f"use at least {math.ceil(10 * w / (2 * math.pi) * Ts)} substeps"
            )
        m_red = mu * (1 - mu)  # reduced inertia per unit J
        k_sp = w * w * m_red
        c_sp = 2 * zeta * w * m_red
    if isinstance(bl, Backlash):
        half_gap = 0.5 * bl.gap_mm
    rs, vs = 1.0, 0.0
    st = fx.get("stribeck")
    if isinstance(st, Stribeck):
        rs, vs = st.static_to_coulomb_ratio, st.stribeck_velocity_mm_s
    td = fx.get("time_delay")
    delay_sub = delay_fb = delay_cap = 0
    if isinstance(td, TimeDelay):
        steps = int(round(td.delay_s / h))
        if td.where == "actuation":
            delay_sub = steps
        elif td.where == "feedback":
            delay_fb = steps
        else:
            delay_cap = steps
    cy = fx.get("cyclic_error")
    amp, period, phase = 0.0, 1.0, 0.0
    if isinstance(cy, CyclicError):
        amp, period, phase = cy.amplitude, cy.period_mm, cy.phase_rad
    u_max = p.u_max
    sat = fx.get("saturation")
    if isinstance(sat, Saturation):
        u_max = min(u_max, sat.limit_v)

    noise_t = rng.standard_normal(n) * enc.noise_std if enc.noise_std > 0 else np.zeros(n)
    noise_m = rng.standard_normal(n) * enc.noise_std if (enc.noise_std > 0 and two_mass) else np.zeros(n)
    out = [np.empty(n) for _ in range(4)]
    P = (p.K_over_J, p.B_over_J, p.d_plus, p.d_minus, float(rs), float(vs), float(amp),
         float(period), float(phase), float(mu), float(k_sp), float(c_sp), float(half_gap))
    _servo_loop(xr, noise_t, noise_m, Ts, nsub, c.kind == "ppi", c.Kp, c.Ki, c.Kd, c.Kv, c.Ka,
                float(u_max), axis.dac_resolution, enc.resolution, two_mass, P,
                delay_sub, delay_fb, delay_cap, *out)
    meas, u, xt, xm = out
    return AxisResponse(actual=meas, table=xt, motor=xm, u=u)


def simulate_axis(
    x_r: np.ndarray,
    axis: AxisDrive,
    effects: Sequence[Effect] = (),
    rng: np.random.Generator | None = None,
    Ts: float | None = None,
) -> np.ndarray:
    """Measured actual position [mm], (N,), of ``axis`` following ``x_r`` [mm] sampled at Ts.

    See :func:`simulate_axis_response` for the parameters; this returns only its ``actual``.
    """
    return simulate_axis_response(x_r, axis, effects, rng=rng, Ts=Ts).actual


def simulate_machine(
    commanded: Mapping[str, np.ndarray],
    machine: Machine,
    effects: Sequence[Effect] = (),
    seed: int | None = 0,
) -> dict[str, np.ndarray]:
    """Simulate every commanded axis of ``machine``; returns {axis: measured actual [mm]}.

    Parameters
    ----------
    commanded : {axis name: (N,) commanded position [mm] at machine.Ts}.
    machine : a :class:`virtual_cnc.presets.Machine`; its own ``effects`` apply first.
    effects : extra effects; one with ``axis=None`` acts on every axis, otherwise on that axis.
    seed : seed of the encoder noise (reproducible); None for fresh entropy.  Each axis gets
        its own stream, independent of which other axes are simulated.
    """
    all_effects = tuple(machine.effects) + tuple(effects)
    for eff in all_effects:
        if eff.axis is not None and eff.axis not in machine.axes:
            raise InputError(
                f"effect {eff.name!r} names axis {eff.axis!r}; machine {machine.name!r} has "
                f"{', '.join(machine.axes)}"
            )
    out: dict[str, np.ndarray] = {}
    names = list(machine.axes)
    for name, x_r in commanded.items():
        if name not in machine.axes:
            raise InputError(
                f"axis {name!r} is not on machine {machine.name!r} (axes: {', '.join(names)})"
            )
        index = names.index(name)
        entropy = None if seed is None else [int(seed), index]
        rng = np.random.default_rng(np.random.SeedSequence(entropy))
        mine = [e for e in all_effects if e.axis is None or e.axis == name]
        out[name] = simulate_axis(x_r, machine.axes[name], mine, rng=rng, Ts=machine.Ts)
    return out

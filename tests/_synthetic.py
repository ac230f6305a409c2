"""Synthetic identification data for the model and solver tests (not part of ident/).

* :func:`point_to_point` -- a random point-to-point command (trapezoidal velocity, exact
  stop at every target, like the G01 blocks of thesis Table 3.2), analytic x_r, v_r, a_r.
* :func:`simulate` -- the continuous model of eq. 3.3 with Coulomb friction, integrated
  by RK4 on a fine step (numba), sampled at T_s; returns the states (e_i, x, xdot) and the
  exact acceleration xddot at the samples.
* :func:`build_regression` -- Phi, Y of eq. 3.11 from the samples, either from the exact
  states (the regression then holds to rounding) or from positions only with the central
  differences and rectangle integral of eq. 3.9 (what a real capture allows).

Until the preprocessing/regression module exists these builders stand in for it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ident.model import DriveModel

#: Table 3.4, PID X axis, "Actual" column.
PID_X = DriveModel(a1=192.65, a2=44356.23, a3=316830.21, b0=0.0, b1=190.10, b2=44356.23, d0=441.0, d1=-302.0)
#: Table 3.3, P-PI X axis, "Actual" column.
PPI_X = DriveModel(a1=372.76, a2=62009.83, a3=1527104.87, b0=0.0, b1=0.0, b2=11106.33, d0=441.0, d1=-302.0)


@dataclass(frozen=True)
class Command:
    """Commanded trajectory sampled on ``t`` (s): position mm, velocity mm/s, acceleration mm/s^2."""

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray


def point_to_point(duration: float, dt: float, seed: int, travel: float = 10.0, feed: float = 200.0,
                   accel: float = 2000.0, settle: float = 0.3) -> Command:
    """Random moves to targets uniform in [-travel, travel] mm, trapezoidal velocity
    (``feed`` mm/s, ``accel`` mm/s^2), stopping at each target; ``settle`` s at rest at both
    ends.  Sampled every ``dt`` s over ``duration`` s."""
    rng = np.random.default_rng(seed)
    # list of constant-acceleration pieces: (t_start, x0, v0, a)
    pieces = [(0.0, 0.0, 0.0, 0.0)]
    t_now, x_now = settle, 0.0
    while t_now < duration - settle:
        target = rng.uniform(-travel, travel)
        dist = target - x_now
        if abs(dist) < 1e-3:
            continue
        sgn = np.sign(dist)
        dist = abs(dist)
        t_acc = feed / accel
        if accel * t_acc**2 >= dist:  # triangular profile
            t_acc = np.sqrt(dist / accel)
            t_flat = 0.0
        else:
            t_flat = (dist - accel * t_acc**2) / feed
        vpk = accel * t_acc
        pieces.append((t_now, x_now, 0.0, sgn * accel))
        x1 = x_now + sgn * 0.5 * accel * t_acc**2
        pieces.append((t_now + t_acc, x1, sgn * vpk, 0.0))
        x2 = x1 + sgn * vpk * t_flat
        pieces.append((t_now + t_acc + t_flat, x2, sgn * vpk, -sgn * accel))
        t_now += 2 * t_acc + t_flat
        x_now = target
        pieces.append((t_now, x_now, 0.0, 0.0))
    n = int(round(duration / dt)) + 1
    t = np.arange(n) * dt
    starts = np.array([pc[0] for pc in pieces])
    k = np.searchsorted(starts, t, side="right") - 1
    t0, x0, v0, a0 = (np.array([pc[i] for pc in pieces])[k] for i in range(4))
    tau = t - t0
    return Command(t=t, x=x0 + v0 * tau + 0.5 * a0 * tau**2, v=v0 + a0 * tau, a=a0)


@njit(cache=True)
def _rk4(xr, vr, ar, h, params):  # pragma: no cover - numba
    """Integrate eq. 3.3 (once-integrated form) with RK4; inputs on a half-step grid."""
    a1, a2, a3, b0, b1, b2, d0, d1 = params
    n = (xr.size - 1) // 2
    out = np.empty((n + 1, 4))
    ei = 0.0
    x = xr[0]
    v = 0.0

    def acc(ei, x, v, xr_, vr_, ar_):
        fr = d0 if v > 0.0 else (d1 if v < 0.0 else 0.0)
        return -a1 * v - a2 * x + a3 * ei + b0 * ar_ + b1 * vr_ + b2 * xr_ - fr

    for k in range(n + 1):
        j = 2 * k
        out[k, 0] = ei
        out[k, 1] = x
        out[k, 2] = v
        out[k, 3] = acc(ei, x, v, xr[j], vr[j], ar[j])
        if k == n:
            break
        k1e = xr[j] - x
        k1x = v
        k1v = out[k, 3]
        e2, x2, v2 = ei + 0.5 * h * k1e, x + 0.5 * h * k1x, v + 0.5 * h * k1v
        k2e = xr[j + 1] - x2
        k2x = v2
        k2v = acc(e2, x2, v2, xr[j + 1], vr[j + 1], ar[j + 1])
        e3, x3, v3 = ei + 0.5 * h * k2e, x + 0.5 * h * k2x, v + 0.5 * h * k2v
        k3e = xr[j + 1] - x3
        k3x = v3
        k3v = acc(e3, x3, v3, xr[j + 1], vr[j + 1], ar[j + 1])
        e4, x4, v4 = ei + h * k3e, x + h * k3x, v + h * k3v
        k4e = xr[j + 2] - x4
        k4x = v4
        k4v = acc(e4, x4, v4, xr[j + 2], vr[j + 2], ar[j + 2])
        ei += h / 6.0 * (k1e + 2 * k2e + 2 * k3e + k4e)
        x += h / 6.0 * (k1x + 2 * k2x + 2 * k3x + k4x)
        v += h / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
    return out


@dataclass(frozen=True)
class Simulated:
    """Samples at T_s: command and exact model states (e_i mm s, x mm, xdot mm/s, xddot mm/s^2)."""

    Ts: float
    cmd: Command
    ei: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray


def simulate(model: DriveModel, duration: float = 5.0, Ts: float = 1e-3, seed: int = 0,
             substeps: int = 10, **traj) -> Simulated:
    """Simulate ``model`` on a random point-to-point command; fine RK4 step Ts/substeps."""
    h = Ts / substeps
    fine = point_to_point(duration, h / 2, seed, **traj)
    params = np.array([model.a1, model.a2, model.a3, model.b0, model.b1, model.b2, model.d0, model.d1])
    out = _rk4(fine.x, fine.v, fine.a, h, params)[::substeps]
    take = slice(None, None, 2 * substeps)
    cmd = Command(t=fine.t[take], x=fine.x[take], v=fine.v[take], a=fine.a[take])
    n = min(cmd.t.size, out.shape[0])
    cmd = Command(cmd.t[:n], cmd.x[:n], cmd.v[:n], cmd.a[:n])
    return Simulated(Ts=Ts, cmd=cmd, ei=out[:n, 0], x=out[:n, 1], v=out[:n, 2], a=out[:n, 3])


def build_regression(sim: Simulated, exact: bool = False, noise_mm: float = 0.0, seed: int = 0,
                     v_threshold: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Phi (N, 8) and Y (N,) of eq. 3.11.

    exact=True uses the simulated states; otherwise only positions are used: ``noise_mm``
    white noise (mm, std) is added to the actual position, derivatives are the central
    differences and e_i the rectangle sum of eq. 3.9, two samples trimmed at each end.
    PV/NV are 1 when the velocity is above +v_threshold / below -v_threshold (mm/s).
    """
    if exact:
        xr, vr, ar = sim.cmd.x, sim.cmd.v, sim.cmd.a
        x, v, a, ei = sim.x, sim.v, sim.a, sim.ei
    else:
        Ts = sim.Ts
        rng = np.random.default_rng(seed)
        x_full = sim.x + noise_mm * rng.standard_normal(sim.x.size)
        xr_full = sim.cmd.x

        def d(y):
            out = np.full_like(y, np.nan)
            out[1:-1] = (y[2:] - y[:-2]) / (2 * Ts)
            return out

        ei_full = Ts * np.cumsum(xr_full - x_full)
        v_full, vr_full = d(x_full), d(xr_full)
        a_full, ar_full = d(v_full), d(vr_full)
        keep = slice(2, -2)
        xr, vr, ar = xr_full[keep], vr_full[keep], ar_full[keep]
        x, v, a, ei = x_full[keep], v_full[keep], a_full[keep], ei_full[keep]
    pv = (v > v_threshold).astype(float)
    nv = (v < -v_threshold).astype(float)
    Phi = np.column_stack([ei, -v, -a, xr, vr, ar, -pv, -nv])
    return Phi, x.copy()

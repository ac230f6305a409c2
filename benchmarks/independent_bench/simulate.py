"""The closed loop: controller at ``Ts`` (1 ms), plant in ``n_sub`` sub-steps (20 kHz), sensors.

Per servo sample ``k`` (time ``k Ts``): read the position feedback sensor and the motor
encoder for the velocity loop (both delayed by ``delay_fb``, interpolated between
sub-steps, noise, quantisation) and, for the capture, the capture
sensor; compute the force; then integrate the plant over ``[k Ts, (k+1) Ts)`` applying at
sub-step time ``t`` the force computed at sample ``floor((t - delay_act) / Ts)`` (zero-order
hold shifted by the actuation dead time, integer and fractional samples).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from numba import njit

from .controller import N_CSTATE, ControllerParams, control_step
from .plant import PlantParams, substep
from .sensors import (CAPTURE_TABLE, DELAY_ACT, DELAY_FB, FULL_CLOSED, NOISE_SD, Q_ENC, Q_SCALE, SensorParams,
                      feedback_q, feedback_true, quantize, table_scale_true)

TS = 0.001
N_SUB = 20


@dataclass(frozen=True)
class Drive:
    """One feed drive: plant, controller, sensors (and an optional load-force schedule)."""

    plant: PlantParams = PlantParams()
    controller: ControllerParams = ControllerParams()
    sensors: SensorParams = SensorParams()
    #: external load pulses/steps: (t_start_s, t_end_s, force_N) windows
    load_windows: tuple = ()
    meta: dict = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class SimResult:
    t: np.ndarray            # s
    x_r: np.ndarray          # m, command
    feedback: np.ndarray     # m, what the loop read
    captured: np.ndarray     # m, what a capture records
    force: np.ndarray        # N, controller output after the limit
    x_m: np.ndarray          # m, motor at k Ts
    x_t: np.ndarray          # m, table at k Ts


@njit(cache=True)
def _run(xr, f_ext, noise_fb, noise_cap, p, c, s, Ts, n_sub):
    n = xr.shape[0]
    dt = Ts / n_sub
    state = np.zeros(4)
    cs = np.zeros(N_CSTATE)
    hist = np.zeros(n * n_sub + 1)          # true feedback-sensor position at every sub-step
    hist_m = np.zeros(n * n_sub + 1)        # motor position at every sub-step
    u_hist = np.zeros(n)
    fb = np.zeros(n)
    cap = np.zeros(n)
    xm = np.zeros(n)
    xt = np.zeros(n)
    q_fb = feedback_q(s)
    shift = s[DELAY_FB] / dt
    hist[0] = feedback_true(state[0], state[2], s)
    for k in range(n):
        i0 = k * n_sub
        pos = i0 - shift
        if pos <= 0.0:
            y_true = hist[0]
            ym_true = hist_m[0]
        else:
            j = int(np.floor(pos))
            fr = pos - j
            y_true = hist[j] if fr == 0.0 else (1.0 - fr) * hist[j] + fr * hist[j + 1]
            ym_true = hist_m[j] if fr == 0.0 else (1.0 - fr) * hist_m[j] + fr * hist_m[j + 1]
        y = quantize(y_true + s[NOISE_SD] * noise_fb[k], q_fb)
        ym = y if s[FULL_CLOSED] == 0.0 else quantize(ym_true + s[NOISE_SD] * noise_cap[k], s[Q_ENC])
        fb[k] = y
        xm[k] = state[0]
        xt[k] = state[2]
        if s[CAPTURE_TABLE] != 0.0:
            cap[k] = quantize(table_scale_true(state[0], state[2], s) + s[NOISE_SD] * noise_cap[k], s[Q_SCALE])
        else:
            cap[k] = y
        u_hist[k] = control_step(xr[k], y, ym, cs, c, Ts, k == 0)
        for j in range(n_sub):
            ta = (k * n_sub + j) * dt - s[DELAY_ACT]
            m = int(np.floor(ta / Ts + 1e-9))
            fu = u_hist[m] if m >= 0 else 0.0
            substep(state, fu, f_ext[k], dt, p)
            hist[i0 + j + 1] = feedback_true(state[0], state[2], s)
            hist_m[i0 + j + 1] = state[0]
    return fb, cap, u_hist, xm, xt


def simulate(drive: Drive, x_r_mm: np.ndarray, seed: int = 0, Ts: float = TS, n_sub: int = N_SUB) -> SimResult:
    """Run the closed loop on the command ``x_r_mm`` (mm per servo sample); noise from ``seed``."""
    xr = np.ascontiguousarray(np.asarray(x_r_mm, dtype=float) * 1e-3)
    n = xr.size
    t = np.arange(n) * Ts
    f_ext = np.zeros(n)
    for t0, t1, f in drive.load_windows:
        f_ext[(t >= t0) & (t < t1)] += f
    rng = np.random.default_rng(seed)
    noise_fb = rng.standard_normal(n)
    noise_cap = rng.standard_normal(n)
    fb, cap, u, xm, xt = _run(xr, f_ext, noise_fb, noise_cap, drive.plant.pack(), drive.controller.pack(),
                              drive.sensors.pack(), Ts, n_sub)
    return SimResult(t=t, x_r=xr, feedback=fb, captured=cap, force=u, x_m=xm, x_t=xt)


def command(programs: Sequence, Ts: float = TS, a_max: float = 2000.0):
    """Commanded X positions (mm) and segment index of ``gcode_gen`` programs."""
    from gcode_gen.commands import command_programs

    run = command_programs(programs, ["X"], Ts=Ts, a_max=a_max)
    return run.commanded["X"], run.segment


def record(drive: Drive, programs: Sequence, seed: int = 0, metadata: dict | None = None):
    """A :class:`core.Recording` of ``programs`` on ``drive``: commanded and captured X, mm."""
    from core import Recording

    x_r, segment = command(programs)
    sim = simulate(drive, x_r, seed=seed)
    return Recording.from_arrays(t=sim.t, commanded={"X": x_r}, actual={"X": sim.captured * 1e3},
                                 segment=segment, sample_period=TS, metadata=dict(metadata or {}))

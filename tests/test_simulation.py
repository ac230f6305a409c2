"""Free-run simulation of eq. 3.3 (ident/simulation.py) against independent references."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from scipy import signal

from ident.model import DriveModel
from ident.simulation import simulate

TS = 1e-3
# Thesis Table 4.1 (PID-controlled Fadal virtual drive): wn 33 Hz, zeta 0.45, p 1.17 Hz.
WN, ZETA, P = 2 * np.pi * 33, 0.45, 2 * np.pi * 1.17
A2 = WN**2 + 2 * P * ZETA * WN


def thesis_model(b0=0.0, d0=441.0, d1=-302.0) -> DriveModel:
    return DriveModel.from_search(WN, ZETA, P, 1.0, 190.1 / A2, b0 / A2, d0 / A2, d1 / A2)


def smooth_command(T=2.0, Ts=TS):
    """Starts at rest (lsim's zero initial state), goes back and forth."""
    t = np.arange(0, T, Ts)
    return t, 5 * (1 - np.cos(2 * np.pi * 1.3 * t)) ** 2 + 2 * np.sin(2 * np.pi * 4.1 * t) ** 3


@pytest.mark.parametrize("b0", [0.0, 0.3])
def test_friction_free_model_matches_lsim_of_G_track(b0):
    m = thesis_model(b0=b0, d0=0.0, d1=0.0)
    t, x_r = smooth_command()
    x_hat = simulate(m, x_r, TS)
    num, den = m.tracking_tf()
    _, y, _ = signal.lsim((np.trim_zeros(num, "f"), den), x_r, t)
    e = x_r - y
    # the only difference is the central-difference ẋ_r, ẍ_r inside u (eq. 3.9): O(Ts²)
    assert np.max(np.abs(x_hat - y)) < 5e-3 * np.max(np.abs(e))


@njit(cache=True)
def _euler_reference(xr, xrd, xrdd, Ts, a1, a2, a3, b0, b1, b2, d0, d1, m):  # pragma: no cover
    """Fine-step semi-implicit Euler with a Karnopp stick band: an independent reference."""
    n = xr.size
    out = np.empty(n)
    h = Ts / m
    z, x, v = 0.0, xr[0], xrd[0]
    out[0] = x
    for k in range(n - 1):
        for j in range(m):
            f = j / m
            r = xr[k] + (xr[k + 1] - xr[k]) * f
            u = (b0 * (xrdd[k] + (xrdd[k + 1] - xrdd[k]) * f) + b1 * (xrd[k] + (xrd[k + 1] - xrd[k]) * f)
                 + b2 * r)
            F = u - a2 * x + a3 * z - a1 * v
            if v > 0:
                acc = F - d0
            elif v < 0:
                acc = F - d1
            elif F > d0:
                acc = F - d0
            elif F < d1:
                acc = F - d1
            else:
                acc = 0.0
            vn = v + h * acc
            if v * vn < 0:
                vn = 0.0
            z += h * (r - x)
            x += h * vn
            v = vn
        out[k + 1] = x
    return out


def test_friction_model_matches_a_fine_step_reference_through_reversals_and_dwells():
    m = thesis_model(b0=0.2)
    t = np.arange(0, 2.0, TS)
    x_r = 0.05 * np.sin(2 * np.pi * 0.7 * t) ** 2 * np.sign(np.sin(2 * np.pi * 0.5 * t)) \
        + 0.02 * np.sin(2 * np.pi * 3 * t)
    xrd = np.gradient(x_r, TS)
    xrdd = np.gradient(xrd, TS)
    ref = _euler_reference(x_r, xrd, xrdd, TS, m.a1, m.a2, m.a3, m.b0, m.b1, m.b2, m.d0, m.d1, 2000)
    x_hat = simulate(m, x_r, TS)
    e = x_r - ref
    assert np.sqrt(np.mean((x_hat - ref) ** 2)) < 1e-3 * np.std(e)
    # friction matters here: the friction-free model is far off
    lin = simulate(thesis_model(b0=0.2, d0=0.0, d1=0.0), x_r, TS)
    assert np.sqrt(np.mean((lin - ref) ** 2)) > 0.1 * np.std(e)


def test_axis_sticks_without_chattering_when_friction_holds_it():
    # No integral action (a3 = 0, P-P control like EMPS): after the move the remaining
    # error force a2·e is within the friction band, so the axis must stop dead.
    m = DriveModel(a1=95.0, a2=16000.0, a3=0.0, b0=0.0, b1=0.0, b2=16000.0, d0=300.0, d1=-300.0)
    t = np.arange(0, 1.5, TS)
    x_r = np.where(t < 0.5, 20 * t, 10.0)
    x_hat = simulate(m, x_r, TS)
    tail = x_hat[t > 0.9]
    assert np.ptp(tail) == 0.0  # exactly held, no chattering
    e_ss = x_r[-1] - tail[-1]
    assert e_ss != 0.0 and m.d1 <= m.a2 * e_ss <= m.d0  # held off target, by friction only


def test_integral_action_eventually_breaks_the_axis_free():
    m = thesis_model()
    t = np.arange(0, 3.0, TS)
    x_r = np.where(t < 0.5, 20 * t, 10.0)
    x_hat = simulate(m, x_r, TS)
    assert abs(x_r[-1] - x_hat[-1]) < 0.3 * m.d0 / m.a2  # the integrator pushed it on


def test_state_restarts_at_each_segment_from_the_recorded_position():
    m = thesis_model()
    _, a = smooth_command(1.0)
    b = a[::-1] + 3.0
    x_r = np.concatenate([a, b])
    seg = np.r_[np.zeros(a.size), np.ones(b.size)].astype(int)
    x_rec = x_r - 0.01  # pretend recorded actual position
    joined = simulate(m, x_r, TS, segment=seg, x0=x_rec)
    assert np.array_equal(joined[: a.size], simulate(m, a, TS, x0=x_rec[0]))
    assert np.array_equal(joined[a.size:], simulate(m, b, TS, x0=x_rec[a.size]))
    assert joined[a.size] == x_rec[a.size]


def test_substeps_converge():
    m = thesis_model()
    t = np.arange(0, 1.0, TS)
    x_r = 0.05 * np.sin(2 * np.pi * 1.5 * t) ** 3
    fine = simulate(m, x_r, TS, substeps=64)
    errs = [np.max(np.abs(simulate(m, x_r, TS, substeps=s) - fine)) for s in (1, 4, 16)]
    assert errs[0] > errs[1] > errs[2]


def test_bad_arguments_are_rejected():
    m = thesis_model()
    with pytest.raises(ValueError, match="scalar x0 is ambiguous"):
        simulate(m, np.zeros(10), TS, segment=np.r_[np.zeros(5), np.ones(5)].astype(int), x0=1.0)
    with pytest.raises(ValueError, match="Ts must be a positive"):
        simulate(m, np.zeros(10), 0.0)
    with pytest.raises(TypeError, match="a1, a2"):
        simulate(object(), np.zeros(10), TS)
    with pytest.raises(ValueError, match="load has shape"):
        simulate(m, np.zeros(10), TS, disturbance=np.zeros(9))


def test_a_load_enters_where_the_command_drive_does():
    # a constant extra acceleration w on a loop with integral action: the same response as
    # the command drive raised by w (the integral then takes it up, no lasting offset)
    m = thesis_model(d0=0.0, d1=0.0)
    t = np.arange(0, 3.0, TS)
    x_r = np.where(t < 0.5, 20 * t, 10.0)
    w = np.where(t > 1.0, 500.0, 0.0)
    moved = simulate(m, x_r, TS, disturbance=w) - simulate(m, x_r, TS)
    assert moved[t > 1.0][50] > 0.0  # pushed the way the load pushes
    assert abs(moved[-1]) < 0.02 * np.max(np.abs(moved))

"""The regression of eq. 3.11 (ident/regression.py)."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import IdentificationError
from ident import preprocessing as pp
from ident.model import DriveModel
from ident.regression import COLUMNS, build_regression, lstsq_scaled
from ident.simulation import simulate

WN, ZETA, P = 2 * np.pi * 33, 0.45, 2 * np.pi * 1.17  # thesis Table 4.1
A2 = WN**2 + 2 * P * ZETA * WN


def thesis_model(d0=441.0, d1=-302.0) -> DriveModel:
    return DriveModel.from_search(WN, ZETA, P, 1.0, 190.1 / A2, 0.0, d0 / A2, d1 / A2)


def random_moves(seed, n_moves, Ts, max_step=5.0, feed=100.0, acc=2000.0, dwell=0.0):
    """Random back-and-forth moves with trapezoidal velocity (a high-speed set in miniature)."""
    rng = np.random.default_rng(seed)
    pos, out = 0.0, [np.zeros(int(0.05 / Ts))]
    for _ in range(n_moves):
        D = rng.uniform(-max_step, max_step)
        d = abs(D)
        if d < feed**2 / acc:
            ta, tf = np.sqrt(d / acc), 0.0
        else:
            ta, tf = feed / acc, (d - feed**2 / acc) / feed
        vp, T = acc * ta, 2 * ta + tf
        t = np.minimum(np.arange(1, int(np.ceil(T / Ts)) + 1) * Ts, T)
        s = np.where(t < ta, 0.5 * acc * t**2,
                     np.where(t < ta + tf, 0.5 * acc * ta**2 + vp * (t - ta), d - 0.5 * acc * (T - t) ** 2))
        out.append(pos + np.sign(D) * s)
        pos += D
        if dwell:
            out.append(np.full(int(dwell / Ts), pos))
    return np.concatenate(out)


def rel_err(theta, true):
    return np.abs(theta - true) / np.abs(true)


def test_columns_are_those_of_eq_3_11():
    Ts = 1e-3
    x_r = random_moves(0, 6, Ts)
    x = simulate(thesis_model(), x_r, Ts)
    R = build_regression(x_r, x, Ts, shift=0, vel_threshold=0.05, standstill="hold")
    assert COLUMNS == ("e_i", "-xd", "-xdd", "x_r", "xd_r", "xdd_r", "-PV", "-NV")
    xd, xdd = pp.central_derivatives(x, Ts)
    xrd, xrdd = pp.central_derivatives(x_r, Ts)
    e_i = pp.integrated_error(x_r, x, Ts)
    d = pp.direction(xd, 0.05)
    k = R.index
    expect = np.column_stack([e_i, -xd, -xdd, x_r, xrd, xrdd, -1.0 * (d > 0), -1.0 * (d < 0)])[k]
    assert np.allclose(R.Phi, expect)
    assert np.array_equal(R.Y, x[k])
    assert k[0] == 2 and k[-1] == x.size - 3  # ẍ is undefined on 2 samples at each end


def test_standstill_rows_are_dropped_by_default():
    Ts = 1e-3
    x_r = random_moves(9, 20, Ts, dwell=0.05)
    x = simulate(thesis_model(), x_r, Ts)
    held = build_regression(x_r, x, Ts, shift=0, standstill="hold")
    dropped = build_regression(x_r, x, Ts, shift=0)
    xd, _ = pp.central_derivatives(x, Ts)
    assert np.all(np.abs(xd[dropped.index]) > dropped.vel_threshold)
    assert dropped.n_rows < held.n_rows
    assert np.all((dropped.Phi[:, 6] + dropped.Phi[:, 7]) == -1.0)  # every kept row is PV or NV


def test_least_squares_recovers_theta_of_a_friction_free_model():
    Ts = 2.5e-4
    m = thesis_model(0.0, 0.0)
    x_r = random_moves(1, 30, Ts)
    R = build_regression(x_r, simulate(m, x_r, Ts), Ts, shift=0)
    theta, _ = lstsq_scaled(R.Phi, R.Y)
    nz = m.theta != 0
    assert np.all(rel_err(theta[nz], m.theta[nz]) < 0.01)
    assert np.all(np.abs(theta[~nz]) < 1e-3 * np.abs(m.theta).max())


def test_least_squares_recovers_theta_with_coulomb_friction():
    Ts = 1e-4  # friction switching is resolved to a sample: the bias is O(Ts)
    m = thesis_model()
    x_r = random_moves(2, 30, Ts)
    R = build_regression(x_r, simulate(m, x_r, Ts), Ts, shift=0)
    theta, _ = lstsq_scaled(R.Phi, R.Y)
    nz = m.theta != 0
    assert np.all(rel_err(theta[nz], m.theta[nz]) < 0.02)


def test_equation_error_bias_shrinks_with_the_sample_period():
    m = thesis_model()
    errs = []
    for Ts in (1e-3, 2.5e-4):
        x_r = random_moves(3, 20, Ts)
        R = build_regression(x_r, simulate(m, x_r, Ts), Ts, shift=0)
        theta, _ = lstsq_scaled(R.Phi, R.Y)
        errs.append(np.max(rel_err(theta[m.theta != 0], m.theta[m.theta != 0])))
    assert errs[1] < 0.5 * errs[0]


@pytest.mark.parametrize("true_shift", [2, -3])
def test_preview_shift_is_found_and_applied(true_shift):
    Ts = 1e-3
    m = thesis_model()
    x_r = random_moves(4, 25, Ts)
    x = simulate(m, pp.shift_command(x_r, true_shift), Ts)
    R = build_regression(x_r, x, Ts)
    assert R.shift == true_shift
    assert min(R.shift_costs, key=R.shift_costs.get) == true_shift
    assert np.array_equal(R.command, pp.shift_command(x_r, true_shift))


def test_segments_are_joined_without_crossing_the_seam():
    Ts = 1e-3
    m = thesis_model()
    lo = random_moves(5, 40, Ts, max_step=0.03, feed=50.0, dwell=0.02)  # low-speed set
    hi = random_moves(6, 15, Ts) + 1.0  # high-speed set
    x_r = np.concatenate([lo, hi])
    seg = np.r_[np.zeros(lo.size), np.ones(hi.size)].astype(int)
    x = simulate(m, x_r, Ts, segment=seg)
    R = build_regression(x_r, x, Ts, seg, shift=1)
    edges = [0, 1, lo.size - 3, lo.size - 2, lo.size - 1, lo.size, lo.size + 1, x.size - 3, x.size - 2, x.size - 1]
    assert not np.isin(edges, R.index).any()  # 2 edge samples + the shifted-in sample
    first_hi = np.searchsorted(R.index, lo.size)
    k = R.index[first_hi]
    cmd = pp.shift_command(x_r, 1, seg)
    e = cmd[lo.size: k + 1] - x[lo.size: k + 1]
    assert R.Phi[first_hi, 0] == pytest.approx(Ts * (e.sum() - 0.5 * (e[0] + e[-1])))  # e_i restarts
    assert np.all(np.abs(R.Phi[:, 1]) < 1e3)  # no velocity spike from the 1 mm seam jump


def test_no_reversal_and_no_motion_are_identification_errors():
    Ts = 1e-3
    x_r = np.cumsum(np.full(500, 0.01))
    with pytest.raises(IdentificationError, match="never reverses direction"):
        build_regression(x_r, x_r - 0.05, Ts)
    with pytest.raises(IdentificationError, match="no motion on axis Y"):
        build_regression(np.ones(500), np.ones(500), Ts, axis="Y")


def test_lowpass_and_threshold_settings_are_recorded():
    Ts = 1e-3
    x_r = random_moves(7, 10, Ts)
    x = simulate(thesis_model(), x_r, Ts)
    R = build_regression(x_r, x, Ts, shift=0, lowpass_hz=100.0, vel_threshold=0.2)
    assert R.lowpass_hz == 100.0 and R.vel_threshold == 0.2 and R.shift_costs == {}
    assert R.Phi.shape == (R.n_rows, 8)


def test_bad_options_are_one_line_input_errors():
    from core.errors import InputError

    Ts = 1e-3
    x_r = random_moves(8, 6, Ts)
    x = simulate(thesis_model(), x_r, Ts)
    with pytest.raises(InputError, match="shift must be an integer"):
        build_regression(x_r, x, Ts, shift="2")
    with pytest.raises(InputError, match="standstill must be"):
        build_regression(x_r, x, Ts, standstill="sometimes")
    with pytest.raises(InputError, match="low-pass cutoff must be between 0 and Nyquist 500 Hz"):
        build_regression(x_r, x, Ts, lowpass_hz=600.0)

"""Preprocessing of recordings (ident/preprocessing.py): sampling, plausibility, signals."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from core.errors import IdentificationError, RapidIdentWarning, RecordingError
from ident import preprocessing as pp
from core.recording import AxisTrace, Recording

TS = 1e-3


def _motion(n: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) * TS
    x_r = 10.0 * np.sin(2 * np.pi * 1.0 * t)
    return x_r, x_r - 0.01 * np.cos(2 * np.pi * 1.0 * t)


# ---------------------------------------------------------------- sampling


def test_time_going_backwards_is_an_error_naming_the_sample():
    t = np.array([0.0, 0.001, 0.002, 0.0015, 0.004])
    with pytest.raises(RecordingError, match="time goes backwards at sample 3"):
        pp.regularise_sampling(t, {"x": np.zeros(5)}, TS)


def test_repeated_timestamp_is_an_error():
    t = np.array([0.0, 0.001, 0.001, 0.003])
    with pytest.raises(RecordingError, match="does not advance at sample 2"):
        pp.regularise_sampling(t, {"x": np.zeros(4)}, TS)


@pytest.mark.parametrize("n, msg", [(0, "empty"), (1, "only 1 sample")])
def test_empty_or_single_sample_recording_is_an_error(n, msg):
    with pytest.raises(RecordingError, match=msg):
        pp.regularise_sampling(np.arange(n) * TS, {"x": np.zeros(n)}, TS)


def test_regular_clock_with_rounding_is_left_alone():
    t = (np.arange(1000) * TS).astype(np.float32).astype(float)  # EMPS-style float32 clock
    x = np.sin(t)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        t2, sig, seg = pp.regularise_sampling(t, {"x": x}, TS)
    assert np.array_equal(t2, t) and np.array_equal(sig["x"], x)
    assert np.all(seg == 0)


def test_jittered_clock_is_resampled_to_the_nominal_period_with_a_warning():
    rng = np.random.default_rng(1)
    t = np.arange(500) * TS + rng.uniform(-0.2, 0.2, 500) * TS
    t[0] = 0.0
    x = 3.0 + 2.0 * t  # linear: interpolation must be exact
    with pytest.warns(RapidIdentWarning, match="irregular sample timing"):
        t2, sig, seg = pp.regularise_sampling(t, {"x": x}, TS)
    assert np.allclose(np.diff(t2), TS)
    assert np.allclose(sig["x"], 3.0 + 2.0 * t2)
    assert np.all(seg == 0)


def test_gap_splits_into_segments_and_is_never_bridged():
    t = np.concatenate([np.arange(100), np.arange(110, 200)]) * TS
    x = np.arange(t.size, dtype=float)
    with pytest.warns(RapidIdentWarning, match="1 gap"):
        t2, sig, seg = pp.regularise_sampling(t, {"x": x}, TS)
    assert t2.size == t.size  # no samples invented in the gap
    assert np.array_equal(sig["x"], x)
    assert np.array_equal(seg, np.r_[np.zeros(100), np.ones(90)])


def test_known_segments_are_kept_and_renumbered():
    t = np.arange(10) * TS
    _, _, seg = pp.regularise_sampling(t, {}, TS, segment=np.array([3] * 4 + [7] * 6))
    assert np.array_equal(seg, [0] * 4 + [1] * 6)


def test_nan_names_axis_and_sample():
    x_r, x = _motion(100)
    x[42] = np.nan
    with pytest.raises(RecordingError, match=r"axis Y: actual position is nan at sample 42"):
        pp.check_motion(x_r, x, TS, axis="Y")


def test_prepare_recording_checks_every_axis():
    x_r, x = _motion(100)
    bad = x.copy()
    bad[7] = np.inf
    rec = Recording(t=np.arange(100) * TS, axes={"X": AxisTrace(x_r, x), "Z": AxisTrace(x_r, bad)},
                    sample_period=TS)
    with pytest.raises(RecordingError, match="axis Z: actual position is inf at sample 7"):
        pp.prepare_recording(rec)
    rec.axes["Z"] = AxisTrace(x_r, x)
    out = pp.prepare_recording(rec)
    assert out.n_samples == 100 and out.axis_names == ["X", "Z"]


# ---------------------------------------------------------------- plausibility


def test_constant_position_is_no_motion():
    with pytest.raises(IdentificationError, match="no motion on axis X"):
        pp.check_motion(np.full(50, 12.5), np.full(50, 12.5), TS, axis="X")


def test_metres_given_as_mm_warns_with_factor_1000():
    x_r, x = _motion()
    with pytest.warns(RapidIdentWarning, match="factor 1000"):
        pp.check_motion(x_r / 1000, x / 1000, TS, axis="X")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pp.check_motion(x_r, x, TS, axis="X")  # the same motion in mm is fine


def test_units_metadata_in_metres_warns():
    x_r, x = _motion()
    with pytest.warns(RapidIdentWarning, match="metres"):
        pp.check_motion(x_r, x, TS, axis="X", units="m")


def test_no_reversal_is_an_error_naming_the_friction_terms():
    with pytest.raises(IdentificationError, match="axis X never reverses direction.*d0/d1"):
        pp.check_reversals(np.array([0, 1, 1, 1, 0]), axis="X")
    pp.check_reversals(np.array([0, 1, -1]), axis="X")


# ---------------------------------------------------------------- signals


def test_central_differences_follow_eq_3_9_and_stop_at_seams():
    t = np.arange(20) * TS
    x = 5.0 * t**2
    x[10:] += 100.0  # a jump at a seam must not become a velocity spike
    seg = np.r_[np.zeros(10), np.ones(10)].astype(int)
    xd, xdd = pp.central_derivatives(x, TS, seg)
    inner_v = np.r_[1:9, 11:19]
    inner_a = np.r_[2:8, 12:18]
    assert np.allclose(xd[inner_v], 10.0 * t[inner_v])
    assert np.allclose(xdd[inner_a], 10.0)
    assert np.isnan(xd[[0, 9, 10, 19]]).all()
    assert np.isnan(xdd[[0, 1, 8, 9, 10, 11, 18, 19]]).all()


def test_integrated_error_restarts_per_segment():
    n = 10
    x_r = np.ones(2 * n)
    x = np.zeros(2 * n)
    seg = np.r_[np.zeros(n), np.ones(n)].astype(int)
    rect = pp.integrated_error(x_r, x, TS, seg, rule="rectangle")
    trap = pp.integrated_error(x_r, x, TS, seg)
    k = np.arange(n)
    assert np.allclose(rect, TS * np.r_[k + 1, k + 1])  # eq. 3.9: Ts·Σ_{m≤k}
    assert np.allclose(trap, TS * np.r_[k, k])  # ∫ from the segment start


def test_shift_command_advances_within_segments_holding_the_edges():
    x_r = np.arange(10, dtype=float)
    seg = np.r_[np.zeros(5), np.ones(5)].astype(int)
    assert np.array_equal(pp.shift_command(x_r, 2, seg), [2, 3, 4, 4, 4, 7, 8, 9, 9, 9])
    assert np.array_equal(pp.shift_command(x_r, -1, seg), [0, 0, 1, 2, 3, 5, 5, 6, 7, 8])


def test_lowpass_is_zero_phase_and_removes_high_frequencies():
    t = np.arange(4000) * TS
    slow = np.sin(2 * np.pi * 2.0 * t)
    y = pp.lowpass(slow + 0.1 * np.sin(2 * np.pi * 200.0 * t), TS, 30.0)
    inner = slice(500, 3500)
    assert np.max(np.abs(y[inner] - slow[inner])) < 2e-3  # no lag, 200 Hz gone


def test_velocity_threshold_cannot_be_flipped_by_encoder_noise():
    rng = np.random.default_rng(3)
    q = 1e-3  # 1 µm encoder
    t = np.arange(6000) * TS
    true = np.where(t < 2, 5.0 * t, np.where(t < 4, 10.0, 10.0 - 5.0 * (t - 4)))  # move, dwell, back
    x = np.round((true + rng.normal(0, 0.4e-3, t.size)) / q) * q
    thr = pp.velocity_threshold(x, TS)
    assert thr >= q / TS
    xd, _ = pp.central_derivatives(x, TS)
    d = pp.direction(xd, thr)
    dwell = (t > 2.05) & (t < 3.95)
    assert np.all(d[dwell] == 1)  # keeps the last direction through the dwell
    assert np.all(d[(t > 0.05) & (t < 1.95)] == 1) and np.all(d[(t > 4.05) & (t < 5.95)] == -1)
    assert np.count_nonzero(np.diff(d[1:-1]) != 0) == 1  # +1 → −1 exactly once


def test_direction_zero_mode_gives_no_friction_at_standstill():
    xd = np.array([0.0, 2.0, 0.5, -0.5, -2.0, 0.1])
    assert np.array_equal(pp.direction(xd, 1.0), [0, 1, 1, 1, -1, -1])
    assert np.array_equal(pp.direction(xd, 1.0, standstill="zero"), [0, 1, 0, 0, -1, 0])


def test_position_resolution_detects_quantised_signals_only():
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.integers(-3, 4, 1000)) * 5e-5
    assert pp.position_resolution(x) == pytest.approx(5e-5, rel=1e-6)
    assert pp.position_resolution(np.cumsum(rng.normal(0.01, 1e-3, 1000))) == 0.0


def test_prepare_recording_accepts_an_idle_axis_and_warns_on_metres():
    x_r, x = _motion(500)
    rec = Recording(t=np.arange(500) * TS,
                    axes={"X": AxisTrace(x_r / 1000, x / 1000), "Z": AxisTrace(np.zeros(500), np.zeros(500))},
                    sample_period=TS, metadata={"units": {"X": "m", "Z": "mm"}})
    with pytest.warns(RapidIdentWarning, match="axis X: positions are recorded in metres"):
        out = pp.prepare_recording(rec)
    assert out.axis_names == ["X", "Z"]  # Z never moves: an error only when Z is identified


def test_declared_sample_period_must_match_the_clock():
    t = np.arange(100) * 2e-3
    with pytest.raises(RecordingError, match="Ts = 1 ms disagrees with the clock: the median step is 2 ms"):
        pp.regularise_sampling(t, {}, 1e-3)


def test_non_finite_time_is_an_error():
    t = np.arange(5) * TS
    t[3] = np.nan
    with pytest.raises(RecordingError, match="time is nan at sample 3"):
        pp.regularise_sampling(t, {}, TS)

"""A drive clips its own output, and that output also carries the plant's viscous friction.

Eq. 3.3's control-equivalent acceleration ``u`` is the drive's output less the viscous
share ``c`` of the speed term (``a1`` holds both the velocity gain and ``c``), so a drive
whose current limit clips its output at ±limit clips ``u`` at ``±limit − c·ẋ``: the limit
falls with speed in the direction it pushes (``limit_slope`` = c).  The virtual CNC's plant
(``J·ẍ = K·(u − d) − B·ẋ``, its amplifier clipped) is that drive with ``c = B/J``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ident.diagnosis import diagnose
from ident.diagnosis.augmented import EFFECTS, EP_INDEX, MODE_SLOTS, N_EP, N_MODES, simulate_augmented
from tests.test_diagnosis_units import THETA, Ts, point_to_point

FIX = Path(__file__).resolve().parents[1] / "fixtures" / "diagnosis"


def clipped_run(x_r: np.ndarray, limit: float, slope: float, windup: bool = False, theta: np.ndarray = THETA):
    """Eq. 3.3 (thesis Table 3.3's P-PI drive by default) with its output clipped; positions, u and speed."""
    ep, flags, modes = np.zeros(N_EP), np.zeros(len(EFFECTS), dtype=np.int64), np.zeros(N_MODES, dtype=np.int64)
    ep[EP_INDEX["limit"]], ep[EP_INDEX["limit_slope"]] = limit, slope
    flags[EFFECTS.index("saturation")] = 1
    modes[MODE_SLOTS["saturation"]] = int(windup)
    u = np.empty(x_r.size)
    y = simulate_augmented(x_r, x_r, Ts, theta, flags=flags, ep=ep, modes=modes, u_out=u)
    return y, u, np.gradient(y, Ts)


@pytest.fixture(scope="module")
def fast_moves() -> np.ndarray:
    return point_to_point(3, T=3.0, span=10.0, v_max=150.0, a_max=3000.0)


def test_the_drive_output_never_exceeds_the_limit_and_reaches_it(fast_moves):
    limit, c = 2500.0, 4.0
    _, u, v = clipped_run(fast_moves, limit, c)
    drive_output = np.abs(u + c * v)
    assert drive_output.max() <= 1.01 * limit
    assert np.count_nonzero(drive_output > 0.99 * limit) > 50


def test_at_speed_the_clip_pushes_less_along_the_motion_by_the_slope(fast_moves):
    limit, c = 2500.0, 4.0
    _, u, v = clipped_run(fast_moves, limit, c)
    along = (u * v > 0) & (np.abs(v) > 100.0)  # accelerating at speed
    assert along.any()
    assert np.max(np.abs(u[along])) < limit - c * 100.0 + 0.01 * limit


def test_without_slope_the_limit_is_the_same_at_every_speed(fast_moves):
    _, u, v = clipped_run(fast_moves, 2500.0, 0.0)
    assert np.max(np.abs(u)) == pytest.approx(2500.0)
    assert np.max(np.abs(u[np.abs(v) > 100.0])) == pytest.approx(2500.0)


def test_an_integral_winding_up_while_clipped_overshoots_more(fast_moves):
    frozen, _, _ = clipped_run(fast_moves, 2500.0, 4.0, windup=False)
    wound, _, _ = clipped_run(fast_moves, 2500.0, 4.0, windup=True)
    assert np.max(np.abs(wound - fast_moves)) > np.max(np.abs(frozen - fast_moves))


@pytest.mark.slow
def test_the_virtual_cnc_amplifier_limit_is_named_with_its_limit_and_viscous_slope():
    """fixtures/diagnosis/saturation (scripts/make_concealed_recordings.py): the virtual CNC's
    fadal-ppi X axis, amplifier clipped at 2.2 V: limit K/J·2.2 V = 2200 mm/s², slope B/J."""
    from virtual_cnc.presets import load_machine

    case = json.loads((FIX / "cases.json").read_text())["saturation"]
    plant = load_machine(case["machine"]).axes["X"].plant
    load = [np.loadtxt(FIX / f"saturation{s}.csv", delimiter=",", skiprows=1) for s in ("", "_validation")]
    (_, x_r, x, seg), (_, vx_r, vx, vseg) = (d.T for d in load)
    d = diagnose(x_r, x, Ts, case["base_model"], segment=seg.astype(np.int32),
                 validation=(vx_r, vx, vseg.astype(np.int32)))
    assert d.verdict == "saturation", d.summary
    p = next(c for c in d.candidates if c.accepted).parameters
    assert p["limit"] == pytest.approx(plant.K / plant.J * case["truth"]["limit"], rel=0.1)
    assert p["limit_slope"] == pytest.approx(plant.B / plant.J, rel=0.5)


@pytest.mark.parametrize("windup", [True, False], ids=["winding_up", "frozen"])
def test_a_long_recording_is_fitted_with_the_drive_limit_slope_and_integral(windup):
    """14 s: long enough for the race to cut windows (2 × race_seconds), were the integral's
    wound-up state readable at a restart; it is not, so saturation races on segments from
    rest.  The drive with full feed-forward, clipped from about 90 mm/s on (top 150 mm/s)."""
    from ident.diagnosis.augmented import segment_starts
    from ident.diagnosis.candidates import search
    from ident.diagnosis.config import DEFAULT
    from ident.diagnosis.spec import ModelSpec, make_chunk, sse

    theta = THETA.copy()
    theta[3:6] = 1.0, theta[0], theta[1]  # b0, b1, b2: acceleration, velocity and position feed-forward
    x_r = point_to_point(11, T=14.0, span=10.0, v_max=150.0, a_max=2500.0)
    limit, c = 3200.0, 4.0
    x, _, _ = clipped_run(x_r, limit, c, windup=windup, theta=theta)
    x = x + np.random.default_rng(0).normal(0.0, 2e-5, x.size)
    chunk = make_chunk(x_r, x, Ts, segment_starts(x_r.size, None))
    assert 2 * DEFAULT.race_seconds <= chunk.n * Ts
    fit = search(ModelSpec(theta), "saturation", chunk, {}, DEFAULT)
    assert fit.modes[MODE_SLOTS["saturation"]] == int(windup)
    assert fit.ep[EP_INDEX["limit"]] == pytest.approx(limit, rel=0.02)
    assert fit.ep[EP_INDEX["limit_slope"]] == pytest.approx(c, rel=0.1)
    assert sse(fit, chunk) < 1e-3 * sse(ModelSpec(theta), chunk)

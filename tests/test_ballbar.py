"""ident.ballbar: each ballbar feature read back from a synthetic circle that has only it.

The runs are built as a controller would run them: a full circle from θ = 45°, with a
trapezoidal feed profile (accelerate from rest, cruise at the feed, stop at 45° again),
sampled every millisecond; the actual path is the commanded one with one error added.
"""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from core.errors import InputError
from ident.ballbar import ballbar_run, analyse_ballbar, plot_ballbar, words

R, V, DT, ACC = 50.0, 25.0, 1e-3, 250.0        # mm, mm/s, s, mm/s²
CENTRE = (10.0, -5.0)
START = np.radians(45.0)


def _arc(t: np.ndarray) -> np.ndarray:
    """Arc length travelled at time t (s) on the trapezoidal profile, mm; 0 before t = 0."""
    L, t1 = 2 * np.pi * R, V / ACC
    tc = (L - V * t1) / V
    T = 2 * t1 + tc
    t = np.clip(t, 0.0, T)
    return np.where(t < t1, 0.5 * ACC * t**2,
                    np.where(t < t1 + tc, 0.5 * V * t1 + V * (t - t1),
                             L - 0.5 * ACC * np.clip(T - t, 0, None) ** 2))


def _times() -> np.ndarray:
    L, t1 = 2 * np.pi * R, V / ACC
    return np.arange(0.0, 2 * t1 + (L - V * t1) / V + DT / 2, DT)


def _angle(t: np.ndarray, direction: str) -> np.ndarray:
    return START + (1 if direction == "ccw" else -1) * _arc(t) / R


def _run(direction, *, tau=(0.0, 0.0), gain=(1.0, 1.0), dx=None, dr=None, **kw):
    """Commanded and actual arrays; tau: axis delays s; gain: axis scales; dx(t, θ):
    mm added to X; dr(θ): mm added to the radius."""
    t = _times()
    th = _angle(t, direction)
    xc, yc = CENTRE[0] + R * np.cos(th), CENTRE[1] + R * np.sin(th)
    x = CENTRE[0] + gain[0] * R * np.cos(_angle(t - tau[0], direction))
    y = CENTRE[1] + gain[1] * R * np.sin(_angle(t - tau[1], direction))
    if dr is not None:
        x, y = x + dr(th) * np.cos(th), y + dr(th) * np.sin(th)
    if dx is not None:
        x = x + dx(t, th, xc)
    return ballbar_run(x, y, xc=xc, yc=yc, centre=CENTRE, radius=R, feed=V,
                       direction=direction, dt=DT, **kw)


def _both(**kw):
    return analyse_ballbar([_run("ccw", **kw), _run("cw", **kw)])


def test_a_perfect_circle_has_no_features():
    res = _both()
    assert all(f.circularity_um < 1e-6 for f in res.runs)
    assert res.hysteresis_um < 1e-6
    w = words(res)
    assert len(w) == 1 and w[0].startswith("circularity 0.0 µm ccw, 0.0 µm cw")


@pytest.mark.parametrize("tau, dtau_ms, ccw_deg",
                         [((0.012, 0.010), 2.0, 45), ((0.010, 0.012), -2.0, 135)])
def test_servo_mismatch_from_axis_lags(tau, dtau_ms, ccw_deg):
    res = _both(tau=tau)
    assert res.servo_mismatch_ms == pytest.approx(dtau_ms, rel=0.05)
    assert res.servo_ellipse_deg == {"ccw": ccw_deg, "cw": 180 - ccw_deg}
    assert abs(res.squareness_um) < 0.05 and abs(res.scale_mismatch_um) < 0.05
    lag = "X lags Y" if dtau_ms > 0 else "Y lags X"
    assert any(w.startswith(f"servo mismatch 2.00 ms ({lag})") for w in words(res))
    # ½·v·Δτ = 25 µm: ±25 µm ellipses, G = 50 µm each; r_ccw − r_cw = 50 µm·sin 2θ.
    assert [f.circularity_um for f in res.runs] == pytest.approx([50.0, 50.0], rel=0.05)
    assert res.hysteresis_um == pytest.approx(50.0, rel=0.05)


@pytest.mark.parametrize("direction", ["ccw", "cw"])
def test_servo_mismatch_from_one_direction_is_an_estimate(direction):
    res = analyse_ballbar([_run(direction, tau=(0.012, 0.010))])
    assert res.servo_mismatch_ms == pytest.approx(2.0, rel=0.05)
    assert res.servo_from_one_direction and res.squareness_um is None and res.hysteresis_um is None
    assert any("from one direction only" in w for w in words(res))


def test_scale_mismatch_in_ppm():
    res = _both(gain=(1 + 50e-6, 1.0))
    # x·(1+ε): dr = Rε cos²θ, a cos 2θ term of Rε/2 = 1.25 µm; + means X draws longer.
    assert res.scale_mismatch_ppm == pytest.approx(50.0, rel=0.02)
    assert res.scale_mismatch_um == pytest.approx(1.25, rel=0.02)
    assert abs(res.servo_mismatch_ms) < 0.01
    assert any(w.startswith("scale mismatch 50 ppm (X draws longer") for w in words(res))
    y_longer = analyse_ballbar([_run("ccw", gain=(1.0, 1 + 50e-6))])
    assert y_longer.scale_mismatch_ppm == pytest.approx(-50.0, rel=0.02)


def _x_reversal_bump(h_mm, T=0.005, delay=0.0):
    """X pushed outward by a bump peaking at h_mm T s after each X reversal, which is
    ``delay`` s after the commanded one."""
    def dx(t, th, xc):
        out = np.zeros_like(t)
        vx = np.gradient(xc)
        for i in np.flatnonzero(np.sign(vx[1:]) * np.sign(vx[:-1]) < 0):
            u = np.clip(t - t[i] - delay, 0.0, None)
            out += np.sign(np.cos(th[i])) * h_mm * (u / T) * np.exp(1 - u / T)
        return out
    return dx


@pytest.mark.parametrize("tau", [(0.0, 0.0), (0.012, 0.010)])
def test_reversal_spikes_on_x_only(tau):
    res = _both(tau=tau, dx=_x_reversal_bump(0.010, delay=tau[0]))
    x, y = res.axis_reversals
    assert (x.axis, x.angles_deg, y.axis, y.angles_deg) == ("X", (0.0, 180.0), "Y", (90.0, 270.0))
    assert x.spike_um == pytest.approx(10.0, rel=0.10)
    assert y.spike_um < 0.2 and abs(x.step_um) < 0.5 and abs(y.step_um) < 0.5
    spikes = [r for f in res.runs for r in f.reversals if r.axis == "X"]
    assert len(spikes) == 4 and all(r.spike_um == pytest.approx(10.0, rel=0.10) for r in spikes)
    w = words(res)
    assert any(s.startswith("reversal spikes on X at 0° and 180°: 10") for s in w)
    assert not any("on Y" in s or "backlash" in s for s in w)
    assert res.servo_mismatch_ms == pytest.approx(1e3 * (tau[0] - tau[1]), abs=0.02)


def test_lost_motion_is_a_step_and_does_not_read_as_servo_mismatch():
    b = 0.008   # mm of lost motion on X: the axis trails its command by b/2
    res = _both(dx=lambda t, th, xc: -0.5 * b * np.sign(np.gradient(xc)))
    x, y = res.axis_reversals
    assert x.step_um == pytest.approx(8.0, rel=0.05) and abs(y.step_um) < 0.3
    assert x.spike_um < 1.0 and y.spike_um < 1.0
    assert abs(res.servo_mismatch_ms) < 0.02 and abs(res.squareness_um) < 0.2
    assert any(s.startswith("reversal step on X at 0° and 180°: +8") for s in words(res))


def test_cyclic_error_order_and_amplitude():
    res = _both(dr=lambda th: 0.002 * np.sin(21 * th))
    assert res.cyclic_order == 21
    assert res.cyclic_amplitude_um == pytest.approx(2.0, rel=0.05)
    assert any(w.startswith("cyclic error: 21 lobes per turn, 2.0 µm") for w in words(res))
    assert not any(w.startswith(("reversal", "backlash", "servo")) for w in words(res))


def test_circularity_is_about_the_least_squares_centre():
    # A pure centre offset of the whole path is not circular deviation.
    run = _run("ccw", dx=lambda t, th, xc: np.full_like(t, 0.020))
    res = analyse_ballbar([run])
    assert res.runs[0].circularity_um < 0.05
    assert res.runs[0].lsc_offset_um == pytest.approx((20.0, 0.0), abs=0.05)
    assert res.runs[0].harmonics_um[:2] == pytest.approx((20.0, 0.0), abs=0.05)


def test_feed_in_and_out_are_not_used():
    run = _run("ccw")
    ramp = V / ACC / DT                               # samples of accelerating
    assert run.used.size - run.used.sum() == pytest.approx(2 * ramp, abs=4)
    bare = ballbar_run(run.x, run.y, centre=CENTRE, radius=R, feed=V, direction="ccw")
    off = np.degrees(np.abs(bare.theta - START))       # no wrap: the run is far from 0°
    assert off[~bare.used].max() == pytest.approx(10.0, abs=0.1)
    assert off[bare.used].min() == pytest.approx(10.0, abs=0.1)


def test_to_dict_is_json():
    d = json.loads(json.dumps(_both(tau=(0.012, 0.010)).to_dict()))
    assert d["servo_mismatch_ms"] == pytest.approx(2.0, rel=0.05)
    assert d["axis_reversals"][0]["axis"] == "X" and len(d["cyclic_spectrum_um"]) == 58


def test_bad_input_is_named():
    run = _run("ccw")
    with pytest.raises(InputError, match="runs the other way"):
        ballbar_run(run.x, run.y, centre=CENTRE, radius=R, feed=V, direction="cw")
    with pytest.raises(InputError, match="one ccw and one cw"):
        analyse_ballbar([run, run])
    with pytest.raises(InputError, match="choose ccw or cw"):
        ballbar_run(run.x, run.y, centre=CENTRE, radius=R, feed=V, direction="up")


def test_polar_plot_renders_runs_and_overlay():
    pytest.importorskip("matplotlib")
    pred, meas = _both(tau=(0.012, 0.010)), _both(tau=(0.012, 0.0105))
    fig = plot_ballbar(pred, measured=meas)
    labels = [ln.get_label() for ln in fig.axes[0].get_lines()]
    for lab in ("nominal", "ccw predicted", "cw predicted", "ccw measured", "cw measured"):
        assert lab in labels
    assert "µm/div" in fig.axes[0].get_title()
    buf = io.BytesIO()
    fig.savefig(buf, format="svg")
    assert b"<svg" in buf.getvalue()[:400]

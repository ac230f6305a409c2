"""Multiple shooting: every scored sample in short windows, each simulated from the recorded state.

:meth:`Chunk.shots` cuts a recording into consecutive windows; each restarts mid-move on
the recorded position, velocity and acceleration a short unscored lead-in before its first
sample.  For the drive that made the recording that restart is its own state, so the
windows reproduce the recording; and each scored sample counts exactly once.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ident.diagnosis.augmented import EP_INDEX, N_EP
from ident.diagnosis.candidates import shoot
from ident.diagnosis.config import DEFAULT
from ident.diagnosis.spec import (estimated_states, residual, residual_jacobian, restart_responses, simulate_spec,
                                  sse)
from test_diagnosis_windows import DRIVES, Ts, recorded, x_r  # noqa: F401  (x_r: the fixture)

# a lightly damped two-mass mode, the loop closed on the motor: the restart holds the
# spring's deflection under the recorded acceleration
DRIVES_SHOT = {**DRIVES, "lightly damped two-mass mode": (
    "resonance", {"freq_hz": 100.0, "damping": 0.03, "motor_fraction": 0.7}, [0, 0, 0, 2, 1]),
    # a mode on the recorded position restarts undeflected: its state is estimated per window
    # (with what every restart misreads)
    "lightly damped mode on the recorded position": (
    "resonance", {"freq_hz": 40.0, "damping": 0.03, "gain": 1.0}, [0, 0, 0, 0, 1])}


def test_every_scored_sample_is_scored_once_and_each_window_is_short(x_r):  # noqa: F811
    chunk, _ = recorded(x_r, None, {}, [0, 0, 0, 0, 1])
    tagged = dataclasses.replace(chunk, w=np.arange(chunk.n, dtype=float))  # a weight is carried per sample
    shot = tagged.shots(0.3, lead_s=0.1)
    kept = shot.w.astype(int)  # the sample of the recording each shot sample is
    assert np.array_equal(shot.x[1:][np.diff(kept) == 1], chunk.x[kept[1:][np.diff(kept) == 1]])
    assert np.array_equal(np.sort(kept[shot.score]), np.flatnonzero(chunk.score))
    bounds = np.append(np.flatnonzero(shot.starts), shot.n)
    lengths = np.diff(bounds) * Ts
    # a window is its 0.3 s (at most 1.5 × that at a segment's end) plus a lead-in of at most 0.2 s
    assert lengths.max() <= 0.45 + 0.2 + Ts
    assert shot.starts.sum() >= chunk.n * Ts / 0.45  # many windows, not a few long ones
    # every window but a segment's first restarts warm, and its lead-in is not scored
    assert shot.warm[0].sum() == shot.starts.sum() - chunk.starts.sum()
    for k in np.flatnonzero(shot.warm[0]):
        assert not shot.score[k : k + int(0.1 / Ts)].any()


@pytest.mark.parametrize("drive", list(DRIVES_SHOT))
def test_the_shots_of_a_recording_reproduce_the_drive_that_recorded_it(x_r, drive):  # noqa: F811
    chunk, spec = recorded(x_r, *DRIVES_SHOT[drive])
    shot = chunk.shots(0.3)
    r = residual(spec, shot)
    e = (shot.w * (shot.x_r - shot.x))[shot.score]
    assert np.linalg.norm(r) < 0.02 * np.linalg.norm(e)


@pytest.mark.parametrize("drive", ["lightly damped mode on the recorded position", "gap, full-closed two-mass"])
def test_the_state_a_restart_misreads_is_estimated_per_window(x_r, drive):  # noqa: F811
    chunk, spec = recorded(x_r, *DRIVES_SHOT[drive])
    shot = chunk.shots(0.3)
    raw = (shot.w * (simulate_spec(spec, shot) - shot.x))[shot.score]  # as restarted, states misread
    assert np.linalg.norm(residual(spec, shot)) < 0.1 * np.linalg.norm(raw)
    # the race's windows keep the restart as it is (no state estimated)
    win = chunk.windows(4.0)
    assert np.array_equal(residual(spec, win), (win.w * (simulate_spec(spec, win) - win.x))[win.score])


@pytest.mark.parametrize("drive", ["Stribeck friction", "lightly damped mode on the recorded position"])
def test_the_exact_jacobian_of_the_windows_is_the_slope_of_their_residual(x_r, drive):  # noqa: F811
    # with the window states eliminated by the projection the fit holds (restart responses of its start)
    chunk, truth = recorded(x_r, *DRIVES_SHOT[drive])
    spec = truth.copy()
    spec.theta = truth.theta * np.array([1.05, 0.95, 1.05, 1.0, 1.02, 0.95, 0.9, 0.9])
    shot = chunk.shots(0.3)
    restarts = restart_responses(spec, shot)
    m = shot.score

    def resid(s):
        r = shot.w[m] * (simulate_spec(s, shot)[m] - shot.x[m])
        return estimated_states(r, s.effects, s.ep, s.modes, shot, restarts)

    d_th = np.diag(spec.theta)[[0, 1, 6]]  # a1, a2, d0: per unit of their values
    d_ep = np.zeros((3, N_EP))
    G = residual_jacobian(spec, shot, d_th, d_ep, restarts=restarts)
    for g, d in zip(G, d_th):
        h = 1e-5
        up, down = spec.copy(), spec.copy()
        up.theta = spec.theta + h * d
        down.theta = spec.theta - h * d
        fd = (resid(up) - resid(down)) / (2 * h)
        assert np.linalg.norm(g - fd) < 1e-3 * np.linalg.norm(fd)
    # without the projection the slope is another: the window states move with the parameters
    raw = residual_jacobian(spec, shot, d_th, d_ep)
    assert np.linalg.norm(raw[0] - G[0]) > 0.01 * np.linalg.norm(G[0])


@pytest.mark.parametrize("jacobian", ["differences", "exact, log coordinates"])
def test_a_multiple_shooting_fit_finds_the_stribeck_curve_of_the_drive_that_recorded_it(x_r, jacobian):  # noqa: F811
    chunk, truth = recorded(x_r, *DRIVES["Stribeck friction"])
    start = truth.copy()
    start.ep[EP_INDEX["static_to_coulomb_ratio"]] = 1.4
    start.ep[EP_INDEX["stribeck_velocity_mm_s"]] = 4.0
    start.theta = truth.theta * np.array([1.1, 0.9, 1.1, 1.0, 1.05, 0.9, 0.8, 0.8])
    exact = jacobian != "differences"
    on = dataclasses.replace(DEFAULT, shooting_window_s=0.3, exact_fine=exact, exact_rough=exact, fit_log=exact)
    fit = shoot(start, chunk, on)
    p = fit.ep[[EP_INDEX["static_to_coulomb_ratio"], EP_INDEX["stribeck_velocity_mm_s"]]]
    assert np.allclose(p, [2.0, 2.0], rtol=0.05)
    assert sse(fit, chunk) < 0.01 * sse(start, chunk)  # and so the free run of the whole recording
    assert shoot(start, chunk, DEFAULT) is start  # off by default: the race's winner goes to the polish as it is


def test_with_shooting_on_a_mode_is_named_and_its_held_out_windows_figure_is_told_beside_the_free_run():
    from ident.diagnosis import diagnose
    from test_diagnosis_units import MODEL
    from test_diagnosis_verdicts import _mode_recording

    x_r, x = _mode_recording(41, 40.0)
    v_r, v = _mode_recording(42, 40.0)
    on = dataclasses.replace(DEFAULT, shooting_window_s=0.3)
    d = diagnose(x_r, x, Ts, MODEL, validation=(v_r, v, None), effects=("resonance",), config=on)
    assert d.verdict == "resonance", d.summary
    c = next(c for c in d.candidates if c.accepted)
    assert abs(c.parameters["freq_hz"] / 40.0 - 1.0) < 0.02
    # the free-run figure judges; the k-step-ahead one (windows from the recorded state) is told beside it
    assert c.score["held_out_windows_s"] == 0.3
    assert 0.0 < c.score["held_out_windows_residual_reduction"] <= 1.0
    assert c.score["held_out_residual_reduction"] > DEFAULT.min_relevant

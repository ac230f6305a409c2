"""The race's windows: short stretches spread over a recording, each restarted mid-move.

A window's simulation restarts on the recorded state (position, velocity, acceleration);
for the model that made the recording that is its own state, so after the short lead-in
the window reproduces the recording as the simulation of the whole does.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from ident.diagnosis.augmented import EP_INDEX, N_EP, N_MODES, segment_starts, simulate_augmented
from ident.diagnosis.candidates import held_force, race_part
from ident.diagnosis.config import DiagnosisConfig
from ident.diagnosis.spec import ModelSpec, make_chunk, simulate_spec
from test_diagnosis_units import point_to_point

Ts = 0.001
# a PID drive (no acceleration feed-forward: a large tracking error), eq. 3.3 parameters
THETA_PID = np.array([192.65, 44356.0, 316830.0, 0.0, 190.1, 44356.0, 441.0, -302.0])
EFFECTS = ("backlash", "stribeck", "resonance", "time_delay", "cyclic_error", "saturation")


@pytest.fixture(scope="module")
def x_r() -> np.ndarray:
    return point_to_point(7, T=12.0)  # 12 s of moves, two segments below


def recorded(x_r: np.ndarray, effect: str | None, params: dict[str, float], modes: list[int]):
    """The chunk a drive with ``effect`` records, and that drive as a ModelSpec."""
    ep = np.zeros(N_EP)
    for k, v in params.items():
        ep[EP_INDEX[k]] = v
    flags = np.array([1 if e == effect else 0 for e in EFFECTS])
    md = np.zeros(N_MODES, dtype=np.int64)
    md[: len(modes)] = modes
    starts = segment_starts(x_r.size, np.repeat([0, 1], x_r.size // 2 + 1)[: x_r.size])
    x = simulate_augmented(x_r, x_r, Ts, THETA_PID, flags=flags, ep=ep, modes=md, starts=starts)
    return make_chunk(x_r, x, Ts, starts), ModelSpec(THETA_PID.copy(), (effect,) if effect else (), ep, md)


DRIVES = {
    "continuous loop": (None, {}, [0, 0, 0, 0, 0]),
    "sampled loop": (None, {}, [0, 0, 0, 0, 1]),
    "causal feed-forward": (None, {}, [0, 0, 0, 0, 2]),
    "gap, table held by friction": ("backlash", {"gap_mm": 0.02}, [0, 0, 0, 0, 1]),
    "gap, full-closed two-mass": ("backlash", {"gap_mm": 0.02, "motor_fraction": 0.6}, [1, 0, 0, 0, 1]),
    "gap, semi-closed two-mass": ("backlash", {"gap_mm": 0.02, "motor_fraction": 0.6}, [2, 0, 0, 0, 1]),
    "Stribeck friction": ("stribeck", {"static_to_coulomb_ratio": 2.0, "stribeck_velocity_mm_s": 2.0}, [0, 0, 0, 0, 1]),
    "capture delay": ("time_delay", {"delay_s": 0.003}, [0, 0, 0, 0, 1]),
    "position-periodic force": ("cyclic_error", {"period_mm": 5.0, "amplitude_sin": 300.0}, [0, 0, 1, 0, 1]),
    "position-periodic error": ("cyclic_error", {"period_mm": 5.0, "amplitude_sin": 0.005}, [0, 0, 0, 0, 1]),
}


@pytest.mark.parametrize("drive", list(DRIVES))
def test_a_window_restarted_mid_move_reproduces_the_drive_that_recorded_it(x_r, drive):
    chunk, spec = recorded(x_r, *DRIVES[drive])
    win = chunk.windows(4.0)
    assert win.warm is not None and win.warm[0].sum() >= 2  # restarts mid-move, not only at segment starts
    r = (simulate_spec(spec, win) - win.x)[win.score]
    e = (win.x_r - win.x)[win.score]
    assert np.linalg.norm(r) < 0.01 * np.linalg.norm(e)
    # restarted at rest instead, the same windows miss the drive by far more
    cold = type(win)(win.x_r, win.x, win.Ts, win.starts, win.derivs, win.w, win.score)
    r_cold = (simulate_spec(spec, cold) - cold.x)[cold.score]
    assert np.linalg.norm(r_cold) > 3 * np.linalg.norm(r)


def test_windows_spread_over_the_whole_recording_and_hold_the_seconds_asked(x_r):
    chunk, _ = recorded(x_r, None, {}, [0, 0, 0, 0, 1])
    win = chunk.windows(4.0, window_s=1.0, lead_s=0.1)
    where = {(a, b): k for k, (a, b) in enumerate(zip(chunk.x_r, chunk.x))}  # the recorded samples are distinct
    kept = np.array([where[(a, b)] for a, b in zip(win.x_r, win.x)])
    assert kept[0] < 0.1 * chunk.n and kept[-1] > 0.8 * chunk.n  # first and last stretch of the recording
    assert win.starts.sum() == 4
    # four one-second windows (one may end early at the end of its segment), each with a
    # lead-in of at most 0.2 s
    assert 3.0 <= win.n * Ts <= 4.0 + 4 * 0.2 + Ts
    # the lead-in after a warm restart is not scored
    for k in np.flatnonzero(win.warm[0]):
        assert not win.score[k : k + int(0.1 / Ts)].any()


def test_a_chunk_no_longer_than_the_windows_is_its_own_window(x_r):
    chunk, _ = recorded(x_r, None, {}, [0, 0, 0, 0, 1])
    assert chunk.windows(20.0) is chunk


@pytest.fixture(scope="module")
def x_r_dwelling() -> np.ndarray:
    # 12 s of faster moves with dwells of 60-300 ms: rests a recording shows
    return point_to_point(7, T=12.0, span=10.0, v_max=200.0, a_max=8000.0, dwell=(60, 300))


def encoder(chunk):
    """The chunk as a 0.1 µm encoder records it (a rest is then a position that does not change)."""
    return make_chunk(chunk.x_r, np.round(chunk.x / 1e-4) * 1e-4, Ts, chunk.starts)


def test_a_window_restarted_at_rest_reproduces_a_wound_up_integral_a_mid_move_restart_misreads(x_r_dwelling):
    # an integral winding up while the output is clipped is a state no recording shows
    # mid-move; at a rest it is known (wound up beyond what friction holds, it would move the axis)
    chunk, spec = recorded(x_r_dwelling, "saturation", {"limit": 3000.0}, [0, 0, 0, 0, 1, 1])
    chunk = encoder(chunk)

    def miss(win):
        return (np.linalg.norm((simulate_spec(spec, win) - win.x)[win.score])
                / np.linalg.norm((win.x_r - win.x)[win.score]))

    assert miss(chunk.rest_windows(4.0, 1.0, 0.05)) < 0.01
    assert miss(chunk.windows(4.0)) > 0.3


def test_rest_windows_restart_only_where_the_axis_rests_and_score_every_sample(x_r_dwelling):
    chunk, _ = recorded(x_r_dwelling, None, {}, [0, 0, 0, 0, 1])
    chunk = encoder(chunk)
    chunk = replace(chunk, w=1.0 + np.arange(chunk.n))  # a weight that tells each sample's index
    win = chunk.rest_windows(4.0, window_s=1.0, rest_s=0.05)
    rests = chunk.rests(0.05)
    # the windows' restarts: segment starts, or rests of the recording at velocity 0
    kept = (win.w - 1.0).astype(int)
    assert np.all(np.diff(kept) > 0)
    assert win.starts.sum() >= 3
    for k in kept[win.starts]:
        assert rests.starts[k]
    assert np.all(win.warm[1][win.warm[0]] == 0.0)
    assert np.array_equal(win.score, chunk.score[kept])  # nothing misread at a rest: no lead-in
    # about the seconds asked (a window may end early at its segment's end), far from all of it
    assert 3.0 <= win.n * Ts and win.n < 0.5 * chunk.n
    # the race of a model a restart mid-move misreads runs on them
    cfg = DiagnosisConfig(race_seconds=6.0, race_window_s=1.0, rest_restart_s=0.05)
    for frac in (0.5, 1.0):
        raced, rested = race_part(chunk, frac, cfg, restart=False), chunk.rest_windows(6.0 * frac, 1.0, 0.05)
        assert np.array_equal(raced.w, rested.w) and np.array_equal(raced.starts, rested.starts)


def test_a_recording_without_a_rest_has_no_rest_windows_and_is_raced_on_the_first_part_of_each_segment(x_r):
    chunk, _ = recorded(x_r, None, {}, [0, 0, 0, 0, 1])  # dwells of 5-40 ms: no rest of 50 ms
    chunk = encoder(chunk)
    assert chunk.rest_windows(4.0, 1.0, 0.05) is None
    raced = race_part(chunk, 0.5, DiagnosisConfig(race_seconds=4.0), restart=False)
    assert raced.n == chunk.part(0.5).n


@pytest.mark.parametrize("drive", ["sampled loop", "Stribeck friction", "capture delay"])
def test_a_rest_window_restarts_holding_the_force_the_model_holds_there(x_r_dwelling, drive):
    # at a rest the integral holds a force friction balances: the model's own (its free
    # run's u there) restarts the window on the model's state, where none misreads it
    chunk, spec = recorded(x_r_dwelling, *DRIVES[drive])
    chunk = encoder(chunk)

    def miss(win):
        return (np.linalg.norm((simulate_spec(spec, win) - win.x)[win.score])
                / np.linalg.norm((win.x_r - win.x)[win.score]))

    held = miss(chunk.rest_windows(4.0, 1.0, 0.05, held=held_force(spec, chunk)))
    assert held < 0.002
    assert miss(chunk.rest_windows(4.0, 1.0, 0.05)) > 10 * held

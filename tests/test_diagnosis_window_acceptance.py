"""The acceptance judged on held-out windows (``DiagnosisConfig.accept_on_windows``).

With multiple shooting on, the held-out recording can be scored over short windows, each
simulated from the recorded state with its restart state estimated (k-step-ahead), instead
of one free run.  The switch makes the acceptance's likelihood-ratio test read those
windows — the same test at the same significance, the per-window states shared nuisance
parameters of reference and candidate, so the degrees of freedom stay the parameters the
effect adds — and tells the free-run figures beside them.

Recordings are simulated with the diagnosis's own augmented model on random point-to-point
commands, with white encoder noise.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.stats import chi2

from ident.diagnosis import diagnose
from ident.diagnosis.augmented import EP_INDEX, N_EP, N_MODES, simulate_augmented
from ident.diagnosis.config import DEFAULT, DiagnosisConfig
from ident.diagnosis.effects import EFFECT_MODELS
from ident.model import BASE_KEYS
from test_diagnosis_units import point_to_point
from ident.diagnosis.spec import residual
from test_diagnosis_shooting import DRIVES_SHOT
from test_diagnosis_windows import EFFECTS, THETA_PID, Ts, recorded, x_r  # noqa: F401  (x_r: the fixture)

ON = dataclasses.replace(DEFAULT, shooting_window_s=0.3, accept_on_windows=True)
NOISE_MM = 5e-4


def _recording(seed: int, stribeck: bool) -> tuple[np.ndarray, np.ndarray]:
    """6 s of a digital PID drive (sampled controller), with or without a Stribeck curve
    (breakaway 2 × Coulomb, Stribeck velocity 2 mm/s), plus 0.5 µm of white encoder noise."""
    x_r = point_to_point(seed, T=6.0)
    ep = np.zeros(N_EP)
    flags = np.zeros(len(EFFECTS), dtype=np.int64)
    if stribeck:
        ep[EP_INDEX["static_to_coulomb_ratio"]], ep[EP_INDEX["stribeck_velocity_mm_s"]] = 2.0, 2.0
        flags[EFFECTS.index("stribeck")] = 1
    modes = np.zeros(N_MODES, dtype=np.int64)
    modes[4] = 1
    x = simulate_augmented(x_r, x_r, Ts, THETA_PID, flags=flags, ep=ep, modes=modes)
    return x_r, x + NOISE_MM * np.random.default_rng(seed).standard_normal(x_r.size)


def _diagnose(stribeck: bool):
    x_r, x = _recording(11, stribeck)
    v_r, v = _recording(12, stribeck)
    return diagnose(x_r, x, Ts, dict(zip(BASE_KEYS, THETA_PID)), validation=(v_r, v, None),
                    effects=("stribeck",), config=ON)


def test_a_stribeck_drive_is_named_on_held_out_windows_with_the_free_run_figures_beside():
    d = _diagnose(stribeck=True)
    assert d.verdict == "stribeck", d.summary
    c = next(c for c in d.candidates if c.accepted)
    assert abs(c.parameters["static_to_coulomb_ratio"] / 2.0 - 1.0) < 0.25
    s = c.score
    assert s["held_out_scored_on"].startswith("windows of 0.3 s")
    # the same χ² test: the effect's own parameters are the degrees of freedom (the
    # windows' states are nuisance parameters of reference and candidate alike)
    k = EFFECT_MODELS["stribeck"].added
    assert s["threshold"] == pytest.approx(chi2.ppf(1.0 - DEFAULT.alpha / 4, k))
    assert s["likelihood_ratio"] > s["threshold"] and s["held_out_residual_reduction"] >= DEFAULT.min_relevant
    # the free run's figures are told beside the windows', and in the words
    for key in ("held_out_free_run_residual_reduction", "held_out_free_run_likelihood_ratio",
                "held_out_free_run_significant", "held_out_free_run_rms_after_mm"):
        assert key in s
    assert "in free run" in d.summary
    # the held-out fit in the JSON stays that of the free run (fit = 100·(1 − ‖r‖/‖e‖))
    assert (100.0 - c.fit_after_pct) / (100.0 - c.fit_before_pct) == pytest.approx(
        s["held_out_free_run_rms_after_mm"] / s["held_out_free_run_rms_before_mm"], rel=1e-9)


def test_a_clean_drive_judged_on_held_out_windows_gives_none():
    d = _diagnose(stribeck=False)
    assert d.verdict == "none", d.summary
    c = next(c for c in d.candidates if c.effect == "stribeck")
    assert not c.accepted and c.score["held_out_scored_on"].startswith("windows")
    # the words tell the free run's residual beside its fit
    before, after = (1e3 * c.score[f"held_out_free_run_rms_{k}_mm"] for k in ("before", "after"))
    assert f"residual rms {before:.3g} → {after:.3g} µm" in d.summary, d.summary


def test_judging_on_windows_needs_the_windows_length():
    with pytest.raises(ValueError, match="shooting_window_s"):
        DiagnosisConfig(accept_on_windows=True)
    assert not DEFAULT.accept_on_windows  # off by default


def test_the_windows_estimate_the_same_restart_states_for_every_model(x_r):  # noqa: F811
    # a model without a mode: the shared states are all its windows estimate
    chunk, spec = recorded(x_r, *DRIVES_SHOT["Stribeck friction"])
    shot = chunk.shots(0.3)
    assert np.array_equal(residual(spec, shot, shared_states=True), residual(spec, shot))
    # a mode on the recorded position: its free response per window is not estimated when
    # models are compared (it would be two nuisance parameters per window the reference lacks)
    chunk, spec = recorded(x_r, *DRIVES_SHOT["lightly damped mode on the recorded position"])
    shot = chunk.shots(0.3)
    shared, own = residual(spec, shot, shared_states=True), residual(spec, shot)
    assert np.linalg.norm(own) < np.linalg.norm(shared)

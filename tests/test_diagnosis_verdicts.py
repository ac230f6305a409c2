"""A verdict is a statement with its evidence: the held-out likelihood ratio decides, a
parameter on a bound of its fit is told as not resolved (never a refusal), and every
accepted parameter comes with a 95 % confidence interval.

Recordings are simulated with the diagnosis's own augmented model (so the truth is a model
the diagnosis can hold) on a random point-to-point command, with white encoder noise.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from ident.diagnosis import diagnose
from ident.diagnosis.augmented import EP_INDEX, N_EP, N_MODES, segment_starts, simulate_augmented
from ident.diagnosis.config import DEFAULT
from ident.diagnosis.diagnose import Candidate, _why_not
from ident.diagnosis.effects import EFFECT_MODELS
from ident.diagnosis.intervals import at_bound
from ident.diagnosis.spec import ModelSpec, make_chunk
from test_diagnosis_units import MODEL, THETA, Ts, point_to_point

NOISE_MM = 5e-4


def _mode_recording(seed: int, freq_hz: float | None, damping: float = 0.03,
                    variant: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """3 s of the P-PI drive of Table 3.3 as a digital drive (the sampled controller, causal
    feed-forward) with (or without: ``freq_hz`` None) a mode — on the recorded position
    (output filter, ``variant`` 0) or of a two-mass drive (``variant`` 1–3, motor share
    0.6) — plus 0.5 µm of white encoder noise."""
    x_r = point_to_point(seed)
    ep = np.zeros(N_EP)
    flags = np.zeros(6, dtype=np.int64)
    if freq_hz is not None:
        ep[EP_INDEX["freq_hz"]], ep[EP_INDEX["damping"]], ep[EP_INDEX["gain"]] = freq_hz, damping, 1.0
        ep[EP_INDEX["motor_fraction"]] = 0.6
        flags[2] = 1
    modes = np.zeros(N_MODES, dtype=np.int64)
    modes[3] = variant
    modes[4] = 2
    x = simulate_augmented(x_r, x_r, Ts, THETA, flags=flags, ep=ep, modes=modes)
    return x_r, x + NOISE_MM * np.random.default_rng(seed).standard_normal(x_r.size)


def _diagnose(freq_hz: float | None, damping: float = 0.03, variant: int = 0):
    x_r, x = _mode_recording(41, freq_hz, damping, variant)
    v_r, v = _mode_recording(42, freq_hz, damping, variant)
    return diagnose(x_r, x, Ts, MODEL, validation=(v_r, v, None), effects=("resonance",))


def test_a_damping_on_the_lower_bound_is_not_resolved_and_one_on_the_upper_is_no_lightly_damped_mode():
    res = EFFECT_MODELS["resonance"]
    spec = ModelSpec(THETA.copy(), ("resonance",))
    spec.modes[3] = 2
    spec.ep[EP_INDEX["motor_fraction"]] = 0.7
    chunk = make_chunk(np.linspace(0, 1, 300), np.linspace(0, 1, 300), Ts, segment_starts(300, None))
    lower, _ = res.bounds("damping", 0.03, chunk, DEFAULT)
    spec.ep[EP_INDEX["freq_hz"]], spec.ep[EP_INDEX["damping"]] = 40.0, lower
    assert res.implausible(spec, chunk, DEFAULT) == ""
    assert "damping" in at_bound(spec, "resonance", chunk, DEFAULT)
    spec.ep[EP_INDEX["damping"]] = 0.03
    assert res.implausible(spec, chunk, DEFAULT) == "" and at_bound(spec, "resonance", chunk, DEFAULT) == {}
    # the upper bound is the definition of a lightly damped mode: a fit held there is a filter
    spec.ep[EP_INDEX["damping"]] = DEFAULT.max_mode_damping
    assert "not a lightly damped mode" in res.implausible(spec, chunk, DEFAULT)
    # a mode beyond the Nyquist band is no mode the sampling shows
    spec.ep[EP_INDEX["freq_hz"]], spec.ep[EP_INDEX["damping"]] = 600.0, 0.03
    assert res.implausible(spec, chunk, DEFAULT) != ""


def test_an_accepted_mode_has_95_percent_intervals_that_hold_the_truth():
    d = _diagnose(40.0, 0.03)
    assert d.verdict == "resonance", d.summary
    c = next(c for c in d.candidates if c.accepted)
    lo, hi = c.intervals["freq_hz"]
    assert lo <= 40.0 <= hi and hi - lo < 2.0
    lo, hi = c.intervals["damping"]
    assert lo <= 0.03 <= hi and hi - lo < 0.02
    assert c.unresolved == {}
    js = json.loads(json.dumps(d.to_dict()))
    cand = next(c for c in js["candidates"] if c["accepted"])
    assert set(cand["parameters_interval95"]) >= {"freq_hz", "damping"}
    # the words give each value with its interval and the share of the residual it removes
    assert "resonance at 40.0 Hz (" in d.summary and "damping 0.030 (" in d.summary, d.summary
    assert "of the held-out residual" in d.summary


def test_a_mode_of_a_semi_closed_loop_recorded_on_the_motor_encoder_is_named_with_its_frequency():
    # the loop and the recording both read the motor: the mode shows only through the
    # table's reaction on the motor (resonance mode 3), as a controller's scope records it
    d = _diagnose(40.0, 0.03, variant=3)
    assert d.verdict == "resonance", d.summary
    c = next(c for c in d.candidates if c.accepted)
    assert c.parameters["freq_hz"] == pytest.approx(40.0, rel=0.10)
    assert "seen on the motor encoder" in d.summary, d.summary


def test_a_well_damped_pole_pair_is_not_named_a_resonance():
    # ζ 0.4 is no lightly damped mode: the fit ends on the box's upper bound (0.15) and is
    # refused by the definition, however much of the held-out residual it removes
    d = _diagnose(40.0, 0.4)
    c = next(c for c in d.candidates if c.effect == "resonance")
    assert not c.accepted and "resonance" not in (d.verdict if isinstance(d.verdict, list) else [d.verdict])
    assert c.parameters["damping"] == pytest.approx(DEFAULT.max_mode_damping)


def test_a_clean_drive_gives_none_whatever_bound_its_trial_mode_ends_on():
    d = _diagnose(None)
    assert d.verdict == "none", d.summary
    c = next(c for c in d.candidates if c.effect == "resonance")
    # refused by the held-out evidence itself (likelihood ratio, or too small a share)
    assert not c.accepted
    assert not (c.score["significant"] and c.score["held_out_residual_reduction"] >= DEFAULT.min_relevant)


def _candidate(**score) -> Candidate:
    return Candidate("resonance", {"freq_hz": 253.0, "damping": 0.15}, 90.0, 92.0, False,
                              {"held_out_residual_reduction": 0.26, "required_reduction": 0.03, **score})


def test_a_refused_candidate_says_why_in_the_order_of_the_rule():
    assert _why_not(_candidate(significant=False)) == "not significant"
    small = _why_not(_candidate(significant=True, held_out_residual_reduction=0.01))
    assert small == "significant, but it removes 1 % of the held-out residual, under 3 %"
    # a mode on the damping bound is told as what it is, with what it removes
    bound = _why_not(_candidate(significant=True, size_test="failed: not a lightly damped mode (ζ = 0.15 "
                                                                     "on the bound of a lightly damped one, 253 Hz)"))
    assert bound.startswith("significant, removes 26 % of the held-out residual, not named: not a lightly damped")

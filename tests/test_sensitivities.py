"""Exact parameter sensitivities of the augmented simulator (complex-step derivative,
``ident.diagnosis.augmented.sensitivities``) agree with central differences of the real
simulation, and the fits that use them (``fit_spec``'s exact Jacobian) reach the same
valley floor the differences do."""

from __future__ import annotations

import numpy as np
import pytest

from ident.diagnosis.augmented import N_EP, sensitivities, simulate_augmented, simulate_augmented_many
from ident.diagnosis.spec import ModelSpec, sim_substeps
from tests.test_diagnosis_lockstep import THETA, VARIANTS, _chunk


def _directions(spec: ModelSpec) -> tuple[np.ndarray, np.ndarray]:
    """One direction per parameter, θ then ep, each the size of the parameter (or a floor)."""
    P = 8 + N_EP
    d_th, d_ep = np.zeros((P, 8)), np.zeros((P, N_EP))
    d_th[np.arange(8), np.arange(8)] = np.maximum(np.abs(spec.theta), 1.0)
    d_ep[8 + np.arange(N_EP), np.arange(N_EP)] = np.maximum(np.abs(spec.ep), 1e-3)
    return d_th, d_ep


def _kw(spec, chunk):
    return dict(flags=spec.flags(), modes=spec.modes, starts=chunk.starts, derivs=chunk.derivs,
                nsub=sim_substeps(spec, chunk.Ts), warm=chunk.warm)


def _moved(spec, chunk, d_th, d_ep, h):
    """The free runs at every parameter moved by h along its direction, (P, N)."""
    return simulate_augmented_many(chunk.x_r, chunk.x, chunk.Ts, spec.theta + h * d_th, spec.ep + h * d_ep,
                                   **_kw(spec, chunk))


def _central(spec, chunk, d_th, d_ep, h):
    return (_moved(spec, chunk, d_th, d_ep, h) - _moved(spec, chunk, d_th, d_ep, -h)) / (2.0 * h)


def _agree(D, C):
    """D and C agree but on a few samples: where a step moves a switch (a stick, a contact)
    across a sub-step a difference reads the jump, not the slope."""
    off = np.abs(D - C) > 1e-4 * np.abs(C).max() + 5e-8  # a 1e-6 difference is good to ~1e-9 mm
    return off.mean() <= 0.01


@pytest.mark.parametrize("effect, params, variant", VARIANTS)
@pytest.mark.parametrize("controller", [0, 1, 2])
def test_sensitivities_are_the_slope_of_the_branch_taken_for_every_effect_and_variant(effect, params, variant,
                                                                                       controller):
    """Central differences where the run is smooth at the estimate; at a kink exactly there (a
    drive at rest right on its breakaway force) the one-sided difference of one side."""
    spec = ModelSpec(THETA.copy()) if effect is None else ModelSpec(THETA.copy()).with_effect(effect, params, variant)
    spec.modes[4] = controller
    for chunk in _chunk():
        d_th, d_ep = _directions(spec)
        D = sensitivities(chunk.x_r, chunk.x, chunk.Ts, spec.theta, spec.ep, d_th, d_ep, **_kw(spec, chunk))
        C = _central(spec, chunk, d_th, d_ep, 1e-6)
        assert D.shape == C.shape
        y = simulate_augmented(chunk.x_r, chunk.x, chunk.Ts, spec.theta, ep=spec.ep, **_kw(spec, chunk))
        h = 1e-7
        F = (_moved(spec, chunk, d_th, d_ep, h) - y) / h
        B = (y - _moved(spec, chunk, d_th, d_ep, -h)) / h
        for j in range(D.shape[0]):
            if not np.all(np.isfinite(C[j])):  # a dead time of 0 stepped below 0: the forward side only
                assert _agree(D[j], F[j]), j
                continue
            assert _agree(D[j], C[j]) or _agree(D[j], F[j]) or _agree(D[j], B[j]), j


def test_on_a_smooth_model_the_sensitivities_are_the_slope_to_many_digits():
    """No friction, continuous loop, a filter mode, a capture delay and a cyclic error: nothing
    switches, so the central difference converges on the complex step as h² does."""
    theta = THETA.copy()
    theta[6:] = 0.0
    spec = (ModelSpec(theta).with_effect("resonance", {"freq_hz": 40.0, "damping": 0.05, "gain": 0.1}, 0)
            .with_effect("cyclic_error", {"period_mm": 2.0, "amplitude_sin": 0.002, "amplitude_cos": 0.001}, 0))
    chunk = _chunk()[0]
    d_th, d_ep = _directions(spec)
    keep = np.r_[np.arange(6), 8 + np.array([3, 4, 5, 7, 8, 9])]  # a1..b2, the mode's and the error's
    d_th, d_ep = d_th[keep], d_ep[keep]
    C = _central(spec, chunk, d_th, d_ep, 1e-5)
    D = sensitivities(chunk.x_r, chunk.x, chunk.Ts, spec.theta, spec.ep, d_th, d_ep, **_kw(spec, chunk))
    for j in range(D.shape[0]):
        assert np.abs(D[j] - C[j]).max() <= 1e-6 * np.abs(C[j]).max() + 1e-10, j


def test_a_fit_with_the_exact_jacobian_gets_where_differences_get(monkeypatch):
    """fit_spec at the fine step, with ``exact_fine``, takes its Jacobian from the sensitivities
    (no difference of the smooth model is simulated) and ends where the forward differences
    end (the default): a dead time
    in the loop started 20 % short and the base 3 % off."""
    import ident.diagnosis.candidates as cand
    from dataclasses import replace

    import ident.diagnosis.spec as spec_module
    from ident.diagnosis.config import DEFAULT
    from ident.diagnosis.spec import make_chunk, sse

    chunk0 = _chunk()[0]
    true = ModelSpec(THETA.copy()).with_effect("time_delay", {"delay_s": 0.0023}, 1)
    x = simulate_augmented(chunk0.x_r, chunk0.x, chunk0.Ts, true.theta, ep=true.ep, **_kw(true, chunk0))
    chunk = make_chunk(chunk0.x_r, x + np.random.default_rng(1).normal(0.0, 1e-5, x.size), chunk0.Ts, chunk0.starts)
    start = true.copy()
    start.theta = true.theta * 1.03
    start.ep[cand.EP_INDEX["delay_s"]] = 0.0018
    with monkeypatch.context() as mp:
        calls = []
        mp.setattr(spec_module, "sensitivities", lambda *a, **k: calls.append(1) or sensitivities(*a, **k))
        mp.setattr(cand, "simulate_augmented_many", lambda *a, **k: pytest.fail("a difference was taken"))
        exact = cand.fit_spec(start, chunk, max_iter=30, cfg=replace(DEFAULT, exact_fine=True))
        assert calls
    differences = cand.fit_spec(start, chunk, max_iter=30, cfg=DEFAULT)
    assert sse(exact, chunk) < 0.02 * sse(start, chunk)
    # Both stop short of the noise floor in the base parameters' long valley (on the exactly
    # stepped single mass as on the Euler step before it), at floors 1-2 % apart; the dead
    # time they find agrees to 1e-3 (below).
    assert sse(exact, chunk) == pytest.approx(sse(differences, chunk), rel=2e-2)
    d = cand.EP_INDEX["delay_s"]
    assert exact.ep[d] == pytest.approx(differences.ep[d], rel=1e-3)
    assert abs(exact.ep[d] - 0.0023) < 0.2 * abs(start.ep[d] - 0.0023)


def test_a_saturated_sampled_loops_exact_slope_is_its_costs_trend():
    """The sampled controller's conditional integration takes the share of its increment that
    puts the output on the limit (ident.kernel._integral_share), so the free run is
    continuous in the parameters: the cost over ±0.5 % of a1 lies on its trend and the
    exact slope is the trend's (benchmarks/bench_cost_ripple.py's measure).  A freeze of
    the whole increment at once jumped by a3·Ts·e wherever the output grazed the limit at
    a sample: ripple 0.14 of the cost, exact slope −0.7 × the trend's."""
    from benchmarks.bench_cost_ripple import MODELS, THETA as PID, TS, ripple
    from ident.diagnosis.augmented import segment_starts
    from ident.diagnosis.spec import make_chunk, simulate_spec
    from tests.test_diagnosis_units import point_to_point

    effect, params, variant = MODELS["saturation, psi 0.5"]
    true = ModelSpec(PID.copy()).with_effect(effect, params, variant)  # the bench's PID drive
    true.modes[4] = 1
    x_r = point_to_point(3)
    starts = segment_starts(x_r.size, None)
    x = simulate_spec(true, make_chunk(x_r, x_r, TS, starts))
    chunk = make_chunk(x_r, x + np.random.default_rng(0).normal(0.0, 5e-5, x.size), TS, starts)
    off = true.copy()
    off.theta = off.theta * 1.02
    rough, slope = ripple(off, chunk, "a1")
    assert rough < 0.01
    assert slope == pytest.approx(1.0, abs=0.1)


def test_the_intervals_exact_jacobian_is_the_central_differences_on_a_smooth_model():
    """intervals._jacobian (exact) against its central differences at 1 % on a dead time in the
    loop: the same columns, base and effect, to the differences' truncation (both on the
    estimate's sub-steps: here +1 % of a1 would make the model choose 3 instead of 2)."""
    from ident.diagnosis.intervals import _Columns, _jacobian
    from ident.diagnosis.spec import make_chunk, simulate_spec

    chunk0 = _chunk()[0]
    spec = ModelSpec(THETA.copy()).with_effect("time_delay", {"delay_s": 0.0023}, 1)
    x = simulate_augmented(chunk0.x_r, chunk0.x, chunk0.Ts, spec.theta, ep=spec.ep, **_kw(spec, chunk0))
    chunk = make_chunk(chunk0.x_r, x + np.random.default_rng(2).normal(0.0, 1e-5, x.size), chunk0.Ts, chunk0.starts)
    c = _Columns(spec, {"time_delay": {}})
    J, r = _jacobian(spec, chunk, c, None)
    d_th, d_ep = np.zeros((len(c.cols), 8)), np.zeros((len(c.cols), N_EP))
    for k, (e, j, _) in enumerate(c.cols):  # column k: its parameter moved by its scale
        (d_th if e is None else d_ep)[k, j] = c.scale[k]
    m = chunk.score
    Jd = (chunk.w[m] * _central(spec, chunk, d_th, d_ep, 0.01)[:, m]).T  # ±1 % of each scale
    np.testing.assert_array_equal(r, chunk.w[m] * (simulate_spec(spec, chunk)[m] - chunk.x[m]))
    assert J.shape == Jd.shape == (r.size, 9)  # θ and the dead time
    for k in range(J.shape[1]):
        assert np.linalg.norm(J[:, k] - Jd[:, k]) <= 0.02 * np.linalg.norm(Jd[:, k]), k

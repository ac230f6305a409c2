"""Gauss–Newton steps to the stationary point (ident/gauss_newton.py) on problems with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from ident.gauss_newton import to_stationary_point

T = np.linspace(0.0, 2.0, 200)


def _exp_problem(noise_seed: int = 0):
    """y = a·exp(−b·t) with a = 3, b = 1.5, plus small noise: r(v) = model − y."""
    y = 3.0 * np.exp(-1.5 * T) + 1e-3 * np.random.default_rng(noise_seed).standard_normal(T.size)

    def residual(v):
        return v[0] * np.exp(-v[1] * T) - y

    def jacobian(v):
        e = np.exp(-v[1] * T)
        return np.column_stack([e, -v[0] * T * e]), residual(v)

    return y, residual, jacobian


def test_a_linear_problem_reaches_the_least_squares_solution_in_one_step():
    rng = np.random.default_rng(1)
    A = rng.standard_normal((50, 3)) * np.array([1e3, 1.0, 1e-3])  # parameters of very different sizes
    y = rng.standard_normal(50)
    v, J, r = to_stationary_point(np.zeros(3), lambda v: (A, A @ v - y), lambda v: A @ v - y,
                                  scale=lambda v: np.array([1e-3, 1.0, 1e3]), max_steps=3)
    np.testing.assert_allclose(v, np.linalg.lstsq(A, y, rcond=None)[0], rtol=1e-9)
    assert np.max(np.abs(J.T @ r)) < 1e-8 * np.max(np.abs(J.T @ y))  # stationary: Jᵀr = 0


def test_a_nonlinear_fit_ends_where_the_gradient_vanishes():
    _, residual, jacobian = _exp_problem()
    v, J, r = to_stationary_point(np.array([2.8, 1.6]), jacobian, residual, scale=np.abs, max_steps=10,
                                  rel_decrease=1e-12)
    assert v == pytest.approx([3.0, 1.5], rel=2e-3)
    g = J.T @ r
    assert np.all(np.abs(g) < 1e-6 * np.linalg.norm(J, axis=0) * np.linalg.norm(r))


def test_the_projection_holds_a_parameter_on_its_bound():
    _, residual, jacobian = _exp_problem()
    v, _, _ = to_stationary_point(np.array([2.8, 1.4]), jacobian, residual, scale=np.abs,
                                  project=lambda v: np.clip(v, [0.0, 0.0], [np.inf, 1.45]), max_steps=10)
    assert v[1] == 1.45 and 2.8 < v[0] < 3.0  # a fits the data with b held at its bound


def test_an_inadmissible_trial_is_halved_and_none_found_leaves_the_start():
    _, residual, jacobian = _exp_problem()
    v0 = np.array([2.8, 1.6])
    # every point with a > 2.8 is inadmissible (the step raises a towards 3): each trial is
    # halved and refused, and the search gives up where it started
    def admissible_residual(v):
        return None if v[0] > 2.8 else residual(v)

    v, J, r = to_stationary_point(v0, jacobian, admissible_residual, scale=np.abs, max_steps=5)
    assert v is v0 and np.array_equal(r, residual(v0))


def test_no_step_is_taken_at_the_stationary_point_by_the_linear_decrease_rule():
    _, residual, jacobian = _exp_problem()
    v_star, _, _ = to_stationary_point(np.array([2.8, 1.6]), jacobian, residual, scale=np.abs, max_steps=10,
                                       rel_decrease=1e-12)
    calls = []
    to_stationary_point(v_star, jacobian, lambda v: calls.append(v) or residual(v), scale=np.abs,
                        min_linear_decrease=1e-4)
    assert calls == []

"""The bounded Levenberg–Marquardt (ident.least_squares.bounded_lm) and its secant version
(secant_lm) on problems with known solutions."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from ident.least_squares import bounded_lm, secant_lm


class Counted:
    """A residual that records the points it is evaluated at."""

    def __init__(self, f):
        self.f = f
        self.points = []

    def __call__(self, z):
        self.points.append(np.array(z, dtype=float))
        return np.asarray(self.f(z), dtype=float)


def _correlated_linear(seed: int = 0):
    """r = A z − b with two strongly correlated columns and the unconstrained solution (1, −1)."""
    rng = np.random.default_rng(seed)
    a0 = rng.standard_normal(200)
    a1 = 0.9 * a0 + 0.1 * rng.standard_normal(200)
    A = np.column_stack([a0, a1])
    b = A @ np.array([1.0, -1.0]) + 0.01 * rng.standard_normal(200)
    return A, b


def test_linear_least_squares_with_an_active_bound_reaches_the_constrained_solution():
    A, b = _correlated_linear()
    z_free = np.linalg.lstsq(A, b, rcond=None)[0]
    assert z_free[1] < -0.5  # the bound z1 >= 0 cuts the unconstrained solution off
    # with z1 on its bound the solution is the one-column least squares in z0
    expected = np.array([A[:, 0] @ b / (A[:, 0] @ A[:, 0]), 0.0])
    resid = Counted(lambda z: A @ z - b)
    res = bounded_lm(resid, np.array([0.3, 0.5]), [-np.inf, 0.0], [np.inf, np.inf], max_iter=50,
                     step=1e-6, ftol=1e-12, xtol=1e-12)
    np.testing.assert_allclose(res.z, expected, atol=1e-6)
    assert res.z[1] == 0.0
    r = A @ expected - b
    assert res.cost == pytest.approx(0.5 * r @ r, rel=1e-9)
    assert res.nfev == len(resid.points)
    assert not res.message.startswith("max_iter")


def test_bounded_rosenbrock():
    # r = (10 (z1 − z0²), 1 − z0): minimum (1, 1); with z0 <= 0.5 it is (0.5, 0.25), cost ½·0.25
    resid = Counted(lambda z: [10.0 * (z[1] - z[0] ** 2), 1.0 - z[0]])
    res = bounded_lm(resid, [-1.2, 1.0], [-2.0, -2.0], [0.5, 2.0], max_iter=200, step=1e-7,
                     ftol=1e-12, xtol=1e-12)
    np.testing.assert_allclose(res.z, [0.5, 0.25], atol=1e-6)
    assert res.cost == pytest.approx(0.125, rel=1e-6)
    assert np.all(np.array(resid.points)[:, 0] <= 0.5)  # never evaluated outside the box
    assert res.nfev == len(resid.points)


def _rosenbrock_jac(z, cols):
    """Exact ∂r/∂z_j of the Rosenbrock residual above, rows for j in cols."""
    full = np.array([[-20.0 * z[0], -1.0], [10.0, 0.0]])  # row j: ∂(r0, r1)/∂z_j
    return full[cols]


@pytest.mark.parametrize("solver", ["bounded_lm", "secant_lm"])
@pytest.mark.parametrize("skip", [(), (1,)])
def test_an_exact_jacobian_reaches_the_bounded_rosenbrock_minimum(solver, skip):
    """``jac`` in place of the differences (``jac_skip``: those columns by differences still)."""
    asked = []

    def jac(z, cols):
        asked.extend(cols)
        return _rosenbrock_jac(z, cols)

    resid = Counted(lambda z: [10.0 * (z[1] - z[0] ** 2), 1.0 - z[0]])
    kw = dict(step=1e-7, ftol=1e-12, jac=jac, jac_skip=skip)
    res = (bounded_lm(resid, [-1.2, 1.0], [-2.0, -2.0], [0.5, 2.0], max_iter=200, xtol=1e-12, **kw)
           if solver == "bounded_lm" else secant_lm(resid, [-1.2, 1.0], [-2.0, -2.0], [0.5, 2.0], max_nfev=400, **kw))
    np.testing.assert_allclose(res.z, [0.5, 0.25], atol=1e-6)
    assert asked and set(asked).isdisjoint(skip)
    # every exact column counts as an evaluation, and is not one
    assert res.nfev == len(resid.points) + len(asked)


def test_with_an_exact_jacobian_no_descent_stops_without_retrying_a_smaller_step():
    # at the minimum of a quadratic no damped step lowers the cost; an exact J is not retaken
    resid = Counted(lambda z: [z[0] - 1.0, 2.0 * (z[1] + 1.0)])
    res = bounded_lm(resid, [1.0, -1.0], [-5.0, -5.0], [5.0, 5.0], max_iter=10,
                     jac=lambda z, cols: np.array([[1.0, 0.0], [0.0, 2.0]])[cols])
    assert res.message == "no step decreases the cost"
    assert res.cost == 0.0


def test_a_parameter_on_its_bound_with_the_gradient_pointing_out_is_held():
    A, b = _correlated_linear()
    resid = Counted(lambda z: A @ z - b)
    # start on the bound z1 = 0, where the gradient of the cost in z1 points below it
    z0 = np.array([1.0, 0.0])
    assert (A[:, 1] @ (A @ z0 - b)) > 0
    res = bounded_lm(resid, z0, [-np.inf, 0.0], [np.inf, np.inf], max_iter=1, step=1e-6)
    # one iteration: z1 stays, z0 takes the (lightly damped) step that is best with z1 fixed,
    # not the joint step's z0 (≈ 1, the unconstrained solution) cut off in z1
    conditional = A[:, 0] @ b / (A[:, 0] @ A[:, 0])
    assert res.z[1] == 0.0
    assert res.z[0] == pytest.approx(conditional, rel=1e-2)
    assert abs(res.z[0] - 1.0) > 0.1


def test_every_parameter_held_stops_at_once():
    resid = Counted(lambda z: z - 2.0)  # minimum at 2, the box stops at 1
    res = bounded_lm(resid, [1.0], [0.0], [1.0], max_iter=10)
    assert res.z[0] == 1.0
    assert res.message == "every parameter is held at a bound"
    assert res.nfev == 2 == len(resid.points)  # the start and one Jacobian column
    assert resid.points[1][0] < 1.0  # the difference is taken inwards from the upper bound


def _rippled(z):
    """Slope 1 except on [5e-4, 1e-3], where it is −2: a ripple just above the start z = 0."""
    z = float(z[0])
    return [z - 1.0 - 3.0 * min(max(z - 5e-4, 0.0), 5e-4)]


def test_no_descent_retakes_the_jacobian_with_a_ten_times_smaller_step():
    # a difference over [0, 1e-3] reads the ripple (slope −0.5, the wrong sign): no damping
    # gives a descent; over [0, 1e-4] it reads the slope and the search reaches the zero
    resid = Counted(_rippled)
    res = bounded_lm(resid, [0.0], [-np.inf], [np.inf], max_iter=20, step=1e-3, ftol=1e-12, xtol=1e-14)
    assert res.z[0] == pytest.approx(1.0015, abs=1e-9)
    assert res.cost < 1e-15
    steps = sorted({abs(p[0]) for p in resid.points[1:] if 0 < abs(p[0]) <= 1e-3})
    assert steps[0] == pytest.approx(1e-4)
    assert res.nfev == len(resid.points)


def test_gives_up_after_the_smaller_step_fails_too():
    resid = Counted(lambda z: [z[0] ** 2])  # minimum at the start: nothing decreases the cost
    res = bounded_lm(resid, [0.0], [-1.0], [1.0], max_iter=10, step=1e-3)
    assert res.z[0] == 0.0
    assert res.message.startswith("no step decreases the cost")
    jacobian_steps = [p[0] for p in resid.points if p[0] > 0]
    assert jacobian_steps[0] == pytest.approx(1e-3) and jacobian_steps[-1] == pytest.approx(1e-4)
    assert res.nfev == len(resid.points)


def test_relative_difference_steps():
    resid = Counted(lambda z: [z[0] - 200.0, z[1] - 0.2])
    bounded_lm(resid, [100.0, 0.5], [-np.inf, -np.inf], [np.inf, np.inf], max_iter=1, step=[1e-5, 1e-3],
               relative_step=True)
    # step[j] * max(1, |z[j]|)
    np.testing.assert_allclose(resid.points[1] - resid.points[0], [1e-3, 0.0], rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(resid.points[2] - resid.points[0], [0.0, 1e-3], rtol=1e-6, atol=1e-12)
    resid = Counted(resid.f)
    bounded_lm(resid, [100.0, 0.5], [-np.inf, -np.inf], [np.inf, np.inf], max_iter=1, step=[1e-5, 1e-3])
    np.testing.assert_allclose(resid.points[1] - resid.points[0], [1e-5, 0.0], rtol=1e-6, atol=1e-12)


def test_relative_cost_decrease_stops_the_search():
    # an exponential fit: a few iterations, then the decrease falls below ftol
    t = np.linspace(0.0, 1.0, 50)
    y = 2.0 * np.exp(-3.0 * t)
    resid = Counted(lambda z: z[0] * np.exp(-z[1] * t) - y - 1e-3 * np.cos(40 * t))
    one = bounded_lm(resid, [1.0, 1.0], [0.0, 0.0], [10.0, 10.0], max_iter=100, step=1e-7, ftol=1e-4,
                     ftol_iter=1, xtol=0.0)
    two = bounded_lm(Counted(resid.f), [1.0, 1.0], [0.0, 0.0], [10.0, 10.0], max_iter=100, step=1e-7,
                     ftol=1e-4, ftol_iter=2, xtol=0.0)
    assert one.message.startswith("ftol") and two.message.startswith("ftol")
    assert two.nfev > one.nfev
    np.testing.assert_allclose(two.z, [2.0, 3.0], rtol=1e-2)


def test_an_exception_in_the_residual_propagates():
    class Stop(Exception):
        pass

    calls = []

    def resid(z):
        calls.append(1)
        if len(calls) > 3:
            raise Stop
        return np.array([z[0] - 1.0, z[1] + 1.0])

    with pytest.raises(Stop):
        bounded_lm(resid, [0.0, 0.0], [-5.0, -5.0], [5.0, 5.0])


@pytest.mark.parametrize("solver", ["bounded_lm", "secant_lm"])
def test_jacobian_columns_in_two_threads_and_together_give_the_same_search_bit_for_bit(solver):
    f, z0, lb, ub = _decays()
    many_rows = []

    def many(Z):  # several points at once, each exactly f(z)
        many_rows.append(len(Z))
        return np.array([f(z) for z in Z])

    run = (lambda **kw: bounded_lm(f, z0, lb, ub, max_iter=15, **kw)) if solver == "bounded_lm" else \
        (lambda **kw: secant_lm(f, z0, lb, ub, max_nfev=60, **kw))
    serial = run()
    for kw in (dict(parallel=True), dict(resid_many=many), dict(parallel=True, resid_many=many)):
        other = run(**kw)
        np.testing.assert_array_equal(other.z, serial.z)
        assert (other.cost, other.nfev, other.message) == (serial.cost, serial.nfev, serial.message)
    assert many_rows and max(many_rows) > 1  # the columns were asked for together


def test_an_exception_in_the_residual_propagates_from_the_helper_thread_too():
    class Stop(Exception):
        pass

    def resid(z):
        if z[1] != 0.0:  # the second column's point, whichever thread takes it
            raise Stop
        return np.array([z[0] - 1.0, z[1] + 1.0])

    with pytest.raises(Stop):
        bounded_lm(resid, [0.0, 0.0], [-5.0, -5.0], [5.0, 5.0], parallel=True)


def _decays():
    """r = Σ a_i exp(−b_i t) − y over four decays (8 parameters), a start and a box."""
    t = np.linspace(0.0, 1.0, 400)
    a, b = np.array([2.0, 0.5, 1.0, 0.3]), np.array([3.0, 20.0, 8.0, 50.0])
    y = (a[:, None] * np.exp(-b[:, None] * t)).sum(0)

    def f(z):
        z = np.asarray(z, dtype=float)
        return (z[0::2, None] * np.exp(-z[1::2, None] * t)).sum(0) - y

    return f, np.array([1.0, 1.0, 1.0, 10.0, 1.0, 5.0, 1.0, 30.0]), np.zeros(8), np.full(8, 100.0)


def test_secant_lm_gets_as_far_in_fewer_evaluations_than_differences_each_iteration():
    # 8 parameters: an iteration of bounded_lm costs 9 evaluations and more, one of
    # secant_lm 1-2; both are run until the cost is 10^-4 of the start's
    f, z0, lb, ub = _decays()
    target = 1e-4 * 0.5 * float(np.sum(f(z0) ** 2))

    def evaluations_to_target(counted: Counted) -> int:
        costs = [0.5 * float(np.sum(counted.f(p) ** 2)) for p in counted.points]
        return next(i + 1 for i, c in enumerate(costs) if c < target)

    sec, fd = Counted(f), Counted(f)
    res = secant_lm(sec, z0, lb, ub, max_nfev=300, step=1e-6, ftol=1e-14)
    bounded_lm(fd, z0, lb, ub, max_iter=300, step=1e-6, ftol=1e-14, xtol=0.0)
    assert res.nfev == len(sec.points) <= 300
    assert evaluations_to_target(sec) < 0.8 * evaluations_to_target(fd)


def test_secant_lm_keeps_to_its_budget_and_its_box():
    f, z0, lb, ub = _decays()
    ub = ub.copy()
    ub[0] = 1.5  # the first amplitude (2 at the solution) is cut off by the box
    sec = Counted(f)
    res = secant_lm(sec, z0, lb, ub, max_nfev=25, step=1e-6)
    assert res.nfev == len(sec.points) <= 25
    assert np.all(np.array(sec.points) <= ub) and np.all(np.array(sec.points) >= lb)
    assert 0.5 * float(np.sum(f(res.z) ** 2)) == pytest.approx(res.cost)
    assert res.cost < 0.5 * float(np.sum(f(z0) ** 2))


def test_secant_lm_stops_when_no_step_can_be_computed():
    # a residual that is nan everywhere but the start: every trial is rejected, the
    # Jacobian (nan) gives no step, and the search ends inside its budget at the start
    resid = Counted(lambda z: np.array([0.0, 1.0]) if np.all(z == 0.0) else np.array([np.nan, np.nan]))
    res = secant_lm(resid, [0.0, 0.0], [-1.0, -1.0], [1.0, 1.0], max_nfev=50)
    np.testing.assert_array_equal(res.z, [0.0, 0.0])
    assert res.nfev == len(resid.points) <= 50
    assert res.message.startswith("no usable step")


def test_the_module_imports_numpy_only():
    # and its fixed-order linear algebra (ident.fixed_order) numpy and numba: no scipy
    for module, allowed in (("least_squares", {"numpy", "__future__", "dataclasses", "ident", "threading",
                                               "concurrent"}),
                            ("fixed_order", {"numpy", "__future__", "numba"})):
        path = Path(__file__).resolve().parents[1] / "ident" / f"{module}.py"
        names = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module:
                names.add(node.module.split(".")[0])
        assert names <= allowed, module

"""The fits' linear algebra in a fixed order (ident.fixed_order): what each product promises."""

import numpy as np
import pytest

from ident.fixed_order import dot, normal_products, solve, sum_squares, weighted_rows


@pytest.fixture
def rows():
    rng = np.random.default_rng(7)
    return rng.standard_normal((5, 41)), rng.standard_normal(41), rng.uniform(0.5, 2.0, 41)


def test_weighted_rows_are_the_weighted_residuals_element_by_element(rows):
    Y, x, w = rows
    out = weighted_rows(Y.copy(), None, x, w)
    assert np.array_equal(out, w * (Y - x))  # bit for bit: the same two operations per element


def test_weighted_rows_of_every_column_are_written_in_place(rows):
    Y, x, w = rows
    Yc = Y.copy()
    assert weighted_rows(Yc, None, x, w) is Yc


def test_weighted_rows_of_the_scored_columns_only(rows):
    Y, x, w = rows
    cols = np.flatnonzero(np.arange(Y.shape[1]) % 3 != 1)
    out = weighted_rows(Y, cols, x[cols], w[cols])
    assert out.shape == (Y.shape[0], cols.size)
    assert np.array_equal(out, w[cols] * (Y[:, cols] - x[cols]))


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1e200])
def test_a_diverged_row_is_set_to_the_diverged_value_and_the_others_are_kept(rows, bad):
    Y, x, w = rows
    Y = Y.copy()
    Y[2, 7] = bad  # 1e200: finite, but its square overflows
    expected = w * (Y - x)
    out = weighted_rows(Y, None, x, w, diverged=1e3)
    assert np.all(out[2] == 1e3)
    keep = [0, 1, 3, 4]
    assert np.array_equal(out[keep], expected[keep])


def test_normal_products_and_sums_agree_with_numpy_to_rounding(rows):
    Y, x, _w = rows
    J = np.asfortranarray(Y.T)
    A, g = normal_products(J, x)
    assert np.allclose(A, J.T @ J, rtol=1e-13, atol=1e-12)
    assert np.allclose(g, J.T @ x, rtol=1e-13, atol=1e-12)
    assert sum_squares(x) == pytest.approx(float(x @ x), rel=1e-14)
    assert dot(x, Y[0]) == pytest.approx(float(x @ Y[0]), rel=1e-12, abs=1e-12)


def test_solve_returns_the_solution_of_a_well_conditioned_system(rows):
    Y, x, _w = rows
    A = Y[:, :5] @ Y[:, :5].T + 5.0 * np.eye(5)
    b = x[:5]
    assert np.allclose(A @ solve(A, b), b, rtol=1e-12, atol=1e-12)

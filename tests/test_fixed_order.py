"""The fits' linear algebra in a fixed order (ident.fixed_order): what each product promises."""

import numpy as np
import pytest

from ident.fixed_order import (dot, lstsq, matvec, moving_mean, norm, normal_products, qr_r, solve, solve_upper,
                               sum_squares, weighted_rows)


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


@pytest.fixture
def regression():
    """A tall regression whose columns span eight decades, as eq. 3.11's do."""
    rng = np.random.default_rng(11)
    A = rng.standard_normal((3000, 6)) * np.array([1e-2, 1.0, 1e2, 1e3, 1e5, 1e6])
    return A, A @ rng.standard_normal(6) + 1e-3 * rng.standard_normal(3000)


def test_lstsq_is_the_least_squares_solution_of_a_full_rank_system(regression):
    A, y = regression
    x = lstsq(A, y)
    assert np.allclose(x, np.linalg.lstsq(A, y, rcond=None)[0], rtol=1e-6, atol=0)
    assert np.abs(A.T @ (y - A @ x)).max() < 1e-9 * np.abs(A.T @ y).max()  # normal equations hold


def test_lstsq_gives_a_column_the_others_span_no_weight(regression):
    A, y = regression
    B = np.column_stack([A[:, :3], 2.0 * A[:, 1], A[:, 3:]])
    x = lstsq(B / np.linalg.norm(B, axis=0), y)
    assert x[3] == 0.0 and np.all(np.isfinite(x))


def test_lstsq_refuses_fewer_rows_than_columns():
    with pytest.raises(ValueError, match="rows"):
        lstsq(np.ones((2, 3)), np.ones(2))


def test_qr_r_is_the_triangular_factor_with_a_positive_diagonal(regression):
    A, _y = regression
    R = qr_r(A)
    assert R.shape == (6, 6) and np.all(np.diag(R) > 0) and np.array_equal(R, np.triu(R))
    assert np.allclose(R.T @ R, A.T @ A, rtol=1e-10, atol=1e-6)


def test_solve_upper_inverts_a_triangular_matrix_for_vectors_and_columns(regression):
    A, y = regression
    R = qr_r(A)
    b = R @ np.arange(1.0, 7.0)
    assert np.allclose(solve_upper(R, b), np.arange(1.0, 7.0), rtol=1e-10)
    B = np.column_stack([b, 2 * b])
    assert np.allclose(solve_upper(R, B), np.column_stack([np.arange(1.0, 7.0), 2 * np.arange(1.0, 7.0)]), rtol=1e-10)


def test_matvec_and_norm_sum_each_row_left_to_right(regression):
    A, y = regression
    x = np.arange(1.0, 7.0)
    expected = np.array([sum(float(a) * float(b) for a, b in zip(row, x)) for row in A[:50]])
    assert np.array_equal(matvec(A[:50], x), expected)  # the written order, bit for bit
    assert norm(y) == pytest.approx(float(np.linalg.norm(y)), rel=1e-14)


@pytest.mark.parametrize("k", [1, 2, 5, 50, 51])
def test_moving_mean_is_numpys_centred_convolution_with_a_box(k):
    y = np.random.default_rng(3).standard_normal(400)
    assert np.allclose(moving_mean(y, k), np.convolve(y, np.ones(k) / k, mode="same"), rtol=0, atol=1e-15)

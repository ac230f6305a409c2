"""Elementary functions whose bits do not depend on the CPU's SIMD extensions (ident.portable_math)."""

import math

import numpy as np
import pytest

from ident.portable_math import exp, geomspace, log


def test_exp_and_log_are_the_c_librarys_values_element_by_element():
    x = np.linspace(-30.0, 30.0, 2001)
    assert np.array_equal(exp(x), np.array([math.exp(v) for v in x]))
    xp = np.abs(x) + 1e-3
    assert np.array_equal(log(xp), np.array([math.log(v) for v in xp]))


def test_exp_and_log_keep_the_shape_and_give_a_float_for_a_scalar():
    assert exp(np.zeros((2, 3))).shape == (2, 3)
    assert exp(0.0) == 1.0 and isinstance(exp(0.0), float)
    assert log(1.0) == 0.0


def test_log_of_zero_is_minus_infinity_and_of_a_negative_number_nan():
    out = log(np.array([0.0, -1.0]))
    assert out[0] == -math.inf and math.isnan(out[1])


def test_geomspace_has_its_ends_exactly_and_even_ratios_between():
    g = geomspace(10.0, 300.0, 8)
    assert g[0] == 10.0 and g[-1] == 300.0 and g.size == 8
    assert np.allclose(g, np.geomspace(10.0, 300.0, 8), rtol=1e-14)
    assert np.allclose(np.diff(np.log(g)), math.log(30.0) / 7, rtol=1e-12)


def test_geomspace_refuses_ends_that_are_not_positive():
    with pytest.raises(ValueError, match="positive"):
        geomspace(0.0, 1.0, 3)

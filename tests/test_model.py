"""DriveModel and Bounds (ident/model.py): parametrisations of eq. 3.3, 3.7, 3.10, 3.14."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import signal

from core.errors import IdentificationError, InputError
from ident.model import (Bounds, DriveModel, alphas_from_search, alphas_jacobian, canonical_search,
                         factorisations)

TWO_PI = 2 * math.pi

#: Table 3.4 (PID, X axis, "Actual") and Table 3.3 (P-PI, X axis, "Actual").
PID_X = DriveModel(a1=192.65, a2=44356.23, a3=316830.21, b0=0.0, b1=190.10, b2=44356.23, d0=441.0, d1=-302.0)
PPI_X = DriveModel(a1=372.76, a2=62009.83, a3=1527104.87, b0=0.0, b1=0.0, b2=11106.33, d0=441.0, d1=-302.0)
#: Table 4.5, X axis: three real poles.
DMG_X = DriveModel(a1=2948.25, a2=526359.32, a3=18813165.66, b0=0.83, b1=-2027.0, b2=289780.0, d0=4443.5, d1=832.84)


def _params(m: DriveModel) -> np.ndarray:
    return np.array([m.a1, m.a2, m.a3, m.b0, m.b1, m.b2, m.d0, m.d1])


# ---- theta (eq. 3.10-3.11) -------------------------------------------------------------
@pytest.mark.parametrize("model", [PID_X, PPI_X, DMG_X])
def test_theta_round_trip(model):
    assert np.allclose(_params(DriveModel.from_theta(model.theta)), _params(model), rtol=1e-12, atol=1e-12)


def test_theta_follows_eq_3_10_order():
    th = PID_X.theta
    a2 = PID_X.a2
    assert th == pytest.approx([PID_X.a3 / a2, PID_X.a1 / a2, 1 / a2, PID_X.b2 / a2, PID_X.b1 / a2,
                                PID_X.b0 / a2, PID_X.d0 / a2, PID_X.d1 / a2])


def test_from_theta_rejects_bad_vectors():
    with pytest.raises(InputError, match="8 entries"):
        DriveModel.from_theta([1.0, 2.0])
    with pytest.raises(IdentificationError, match="alpha_2"):
        DriveModel.from_theta([1, 1, 0, 1, 1, 1, 1, 1])
    with pytest.raises(IdentificationError, match="non-finite"):
        DriveModel.from_theta([1, 1, np.nan, 1, 1, 1, 1, 1])
    with pytest.raises(InputError, match="a1"):
        DriveModel(a1=float("nan"), a2=1, a3=1, b0=0, b1=0, b2=1, d0=0, d1=0)


# ---- search variables (eq. 3.7, 3.14) -------------------------------------------------
def test_alphas_from_search_matches_eq_3_14_and_broadcasts():
    wn, zeta, p = 200.0, 0.45, 7.4
    ai, a1, a2 = alphas_from_search(wn, zeta, p)
    den = wn**2 + 2 * p * zeta * wn
    assert (ai, a1, a2) == pytest.approx((p * wn**2 / den, (p + 2 * zeta * wn) / den, 1 / den))
    W, Z, P = np.meshgrid([10.0, 100.0], [0.3, 1.5, 2.0], [1.0, 50.0, 300.0, 900.0], indexing="ij")
    out = alphas_from_search(W, Z, P)
    assert all(o.shape == (2, 3, 4) for o in out)


def test_alphas_jacobian_is_G_of_eq_3_15():
    wn, zeta, p = 150.0, 0.6, 20.0
    d = (wn + 2 * p * zeta) ** 2
    # thesis G, columns (p, wn, zeta)
    G = np.array([[wn**2, 2 * p**2 * zeta, -2 * p**2 * wn],
                  [1 - 4 * zeta**2, -2 * (zeta * wn**2 + p * wn + p**2 * zeta) / wn**2, -2 * (p**2 - wn**2) / wn],
                  [-2 * zeta / wn, -2 * (wn + p * zeta) / wn**2, -2 * p / wn]]) / d
    J = alphas_jacobian(wn, zeta, p)  # columns (wn, zeta, p)
    assert np.allclose(J[:, [2, 0, 1]], G, rtol=1e-12)
    # and a finite-difference check
    h = 1e-6
    for k, e in enumerate(np.eye(3)):
        v = np.array([wn, zeta, p])
        fd = (np.array(alphas_from_search(*(v + h * v * e))) - np.array(alphas_from_search(*(v - h * v * e)))) / (2 * h * v[k])
        assert np.allclose(J[:, k], fd, rtol=1e-6)


@pytest.mark.parametrize("wn_hz,zeta,p_hz", [(33.0, 0.45, 1.17), (36.26, 0.75, 4.68), (80.0, 0.2, 400.0),
                                             (5.0, 0.999, 5.0)])
def test_search_round_trip_complex_pair(wn_hz, zeta, p_hz):
    m = DriveModel.from_search(TWO_PI * wn_hz, zeta, TWO_PI * p_hz, 1.0, 0.004, 0.0, 0.01, -0.007)
    wn, z, p = m.search_variables()
    assert (wn / TWO_PI, z, p / TWO_PI) == pytest.approx((wn_hz, zeta, p_hz), rel=1e-7)
    assert m.theta[3:] == pytest.approx([1.0, 0.004, 0.0, 0.01, -0.007])


def test_search_variables_of_three_real_poles_follow_table_4_5():
    wn, zeta, p = DMG_X.search_variables()
    assert (round(wn / TWO_PI, 2), round(zeta, 2), round(p / TWO_PI, 2)) == (13.14, 1.14, 439.27)
    assert len(DMG_X.factorisations()) == 3


def test_real_pole_factorisations_describe_the_same_model_and_smallest_zeta_is_chosen():
    # a non-canonical factorisation: pair 100 / 4 rad/s (zeta 2.6), p = 40 rad/s
    m = DriveModel.from_search(20.0, 2.6, 40.0, 1.0, 0.0, 0.0, 0.0, 0.0)
    cands = m.factorisations()
    assert len(cands) == 3
    for wn, z, p in cands:
        assert np.allclose(_params(DriveModel.from_search(wn, z, p, 1.0, 0, 0, 0, 0)), _params(m), rtol=1e-9)
    chosen = m.search_variables()
    assert chosen[1] == pytest.approx(min(c[1] for c in cands))
    assert chosen[1] < 2.6
    # the same canonical point comes out of the vectorised helper
    assert np.allclose(np.array(canonical_search(20.0, 2.6, 40.0), dtype=float), chosen, rtol=1e-9)


def test_search_variables_prefer_a_feasible_factorisation():
    # poles at 1000, 9 and 1 rad/s; the smallest-zeta factorisation pairs 9 and 1 (wn = 3 rad/s,
    # zeta 1.67, p = 1000); pairing 1000 and 9 gives wn = 94.9 rad/s, zeta 5.3, p = 1 rad/s.
    m = DriveModel.from_search(3.0, 10 / 6, 1000.0, 1.0, 0, 0, 0, 0)
    assert m.search_variables() == pytest.approx((3.0, 10 / 6, 1000.0))
    b = Bounds(p_min_hz=0.1, wn_min_hz=1.0, zeta_max=6.0, f_max_hz=500)  # wn = 3 rad/s < 6.28 rad/s
    wn, z, p = m.search_variables(b)
    assert (wn, z, p) == pytest.approx((math.sqrt(9000.0), 1009 / (2 * math.sqrt(9000.0)), 1.0))
    assert b.check(m) == []
    # with p_min = 0.2 Hz (1.26 rad/s) no factorisation is feasible
    assert Bounds(p_min_hz=0.2, wn_min_hz=1.0, zeta_max=6.0, f_max_hz=500).check(m) != []


def test_factorisations_of_unstable_polynomial_report_negative_values():
    (wn, zeta, p), = factorisations(*np.poly([1 + 2j, 1 - 2j, -3])[1:].real)
    assert zeta < 0 and p == pytest.approx(3.0)


# ---- poles, zeros, transfer functions -------------------------------------------------
def test_poles_and_zeros_of_table_3_4_pid_x_actual():
    poles = [(round(f, 2), round(d, 2)) for f, d in PID_X.poles()]
    assert poles == [(33.0, 0.45), (33.0, 0.45), (1.17, 1.0)]
    zeros = [(round(f, 2), round(d, 2)) for f, d in PID_X.zeros()]
    assert zeros == [(35.96, 1.0), (1.17, 1.0)]  # b0 = 0: two zeros, as the table's "-"


def test_poles_and_zeros_of_table_3_3_ppi_x_actual():
    assert [(round(f, 2), round(d, 2)) for f, d in PPI_X.poles()] == [(36.26, 0.75), (36.26, 0.75), (4.68, 1.0)]
    assert [(round(f, 2), round(d, 2)) for f, d in PPI_X.zeros()] == [(21.88, 1.0)]


def test_right_half_plane_zero_has_damping_minus_one():
    m = DriveModel(a1=214.13, a2=60040.19, a3=685295.65, b0=-0.35, b1=203.86, b2=60043.78, d0=620, d1=-280)
    f, d = m.zeros()[0]
    assert d == pytest.approx(-1.0) and f > 90


def test_frequency_responses_match_scipy_and_dc_gains():
    f = np.array([0.1, 1.0, 10.0, 33.0, 200.0])
    Ht, Hd = PID_X.freqresp(f)
    _, Ht_ref = signal.freqs(*PID_X.tracking_tf(), worN=TWO_PI * f)
    _, Hd_ref = signal.freqs(*PID_X.disturbance_tf(), worN=TWO_PI * f)
    assert np.allclose(Ht, Ht_ref) and np.allclose(Hd, Hd_ref)
    assert abs(PID_X.freqresp(1e-6)[0]) == pytest.approx(1.0, abs=1e-6)
    assert PID_X.dc_gains() == (1.0, 0.0)
    no_integral = DriveModel(a1=100, a2=4e4, a3=0, b0=0, b1=0, b2=2e4, d0=1, d1=-1)
    assert no_integral.dc_gains() == pytest.approx((0.5, 1 / 4e4))


def test_to_dict_has_spec_keys_and_is_json():
    d = PID_X.to_dict(Bounds())
    json.dumps(d)
    assert set(d["model"]) == {"a1", "a2", "a3", "b0", "b1", "b2", "d0", "d1"}
    assert d["search_variables"]["wn_hz"] == pytest.approx(33.0, abs=0.01)
    assert d["search_variables"]["p_hz"] == pytest.approx(1.17, abs=0.01)
    assert len(d["poles"]) == 3 and {"freq_hz", "damping"} == set(d["poles"][0])


# ---- Bounds -----------------------------------------------------------------------------
def test_bounds_convert_hz_to_rad_s_and_nyquist():
    b = Bounds()
    assert b.p_min == pytest.approx(TWO_PI * 0.2) and b.wn_min == pytest.approx(TWO_PI * 0.2)
    assert b.f_max() == math.inf
    assert b.f_max(1e-3) == pytest.approx(TWO_PI * 500)
    assert b.with_sample_period(1e-3).f_max_hz == pytest.approx(500)
    lo, hi = b.box(1e-3)
    assert lo == pytest.approx([TWO_PI * 0.2, 0.2, TWO_PI * 0.2]) and hi == pytest.approx([TWO_PI * 500, 2.0, TWO_PI * 500])
    with pytest.raises(InputError, match="upper frequency bound"):
        b.box()


@pytest.mark.parametrize("kwargs,match", [({"zeta_min": 2.0, "zeta_max": 1.0}, "zeta_max"),
                                          ({"p_min_hz": -1.0}, "p_min_hz"),
                                          ({"f_max_hz": 0.1}, "f_max_hz"),
                                          ({"wn_min_hz": float("nan")}, "wn_min_hz")])
def test_bounds_reject_inconsistent_values(kwargs, match):
    with pytest.raises(InputError, match=match):
        Bounds(**kwargs)


def test_bounds_check_names_each_violated_constraint():
    assert Bounds().check(PID_X, sample_period=1e-3) == []
    assert Bounds(zeta_max=0.4).check(PID_X) == ["zeta_max"]
    assert Bounds(zeta_min=0.5).check(PID_X) == ["zeta_min"]
    assert Bounds(p_min_hz=2.0).check(PID_X) == ["p_min"]
    assert Bounds(wn_min_hz=40.0).check(PID_X) == ["wn_min"]
    assert Bounds(f_max_hz=20.0).check(PID_X) == ["f_max"]
    assert Bounds().check(PID_X, sample_period=1 / 50) == ["f_max"]  # Nyquist 25 Hz < 33 Hz


def test_bounds_active_reports_constraints_on_the_boundary():
    b = Bounds(f_max_hz=100.0)
    assert b.active(b.wn_min, 0.5, 30.0) == ("wn_min",)
    assert b.active(50.0, 2.0, b.p_min) == ("p_min", "zeta_max")
    assert b.active(b.f_max(), 0.2, 30.0) == ("zeta_min", "f_max")

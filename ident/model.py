"""The closed-loop drive model of thesis eq. 3.3 and its pole constraints (eq. 3.8).

Model (thesis eq. 3.3, multiplied through by s)::

    (s^3 + a1 s^2 + a2 s + a3) x = (b0 s^3 + b1 s^2 + b2 s + a3) x_r - s d
    d = d0 PV(xdot) + d1 NV(xdot)                                    (eq. 3.2)

with x, x_r in mm and d the control-equivalent Coulomb friction in mm/s^2.  Units of the
parameters: a1 1/s, a2 1/s^2, a3 1/s^3, b0 -, b1 1/s, b2 1/s^2, d0 and d1 mm/s^2.

Three equivalent parametrisations are used across the project:

* physical ``(a1, a2, a3, b0, b1, b2, d0, d1)`` -- :class:`DriveModel`;
* normalised regression vector ``theta`` of eq. 3.10-3.11 (everything divided by a2)::

      theta = [alpha_i, alpha_1, alpha_2, beta_0, beta_1, beta_2, delta_plus, delta_minus]
            = [a3/a2,   a1/a2,   1/a2,    b2/a2,  b1/a2,  b0/a2,  d0/a2,      d1/a2]

* search variables ``(wn, zeta, p)`` of the characteristic polynomial (eq. 3.7)::

      s^3 + a1 s^2 + a2 s + a3 = (s + p)(s^2 + 2 zeta wn s + wn^2)

  which fix the denominator, ``theta_1 = [alpha_i, alpha_1, alpha_2]`` (eq. 3.14).

Factorisation convention (three real poles).  When the polynomial has a complex pair the
factorisation is unique: the pair gives (wn, zeta < 1), the real pole gives p.  With three
real poles -r1, -r2, -r3 any two can form the "pair" (wn = sqrt(r_a r_b), zeta =
(r_a + r_b) / (2 wn) >= 1) and the third is p, so up to three factorisations describe the
same model.  :meth:`DriveModel.search_variables` picks

1. if ``bounds`` are given, only factorisations with the least constraint violation
   (a feasible one whenever it exists, so a model is inside the bounds iff some
   factorisation is), then
2. among those, the one with the smallest zeta (the two closest poles, in ratio, form the
   pair), which is the thesis's choice in Table 4.5 (pair 22.2 / 7.8 Hz, p = 439 Hz).

Pole and zero lists follow the thesis tables (e.g. Table 3.4): per root its frequency |s|
in Hz and its damping -Re(s)/|s| (1 for a stable real root, -1 for a real root in the
right half plane), sorted by decreasing frequency.

Constraints (eq. 3.8 plus the upper frequency bound of section 4.2)::

    p >= p_min,  wn >= wn_min,  zeta_min <= zeta <= zeta_max,  wn <= f_max,  p <= f_max

:class:`Bounds` holds them in Hz (user units) and converts to rad/s once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from core.errors import IdentificationError, InputError

__all__ = [
    "DriveModel",
    "BASE_KEYS",
    "base_vector",
    "Bounds",
    "CONSTRAINT_NAMES",
    "THETA_NAMES",
    "alphas_from_search",
    "alphas_jacobian",
    "canonical_search",
    "factorisations",
]

TWO_PI = 2.0 * math.pi

#: Names of the entries of theta, in the order of eq. 3.11.
THETA_NAMES = ("alpha_i", "alpha_1", "alpha_2", "beta_0", "beta_1", "beta_2", "delta_plus", "delta_minus")

#: Constraint names used in reports and ``active_constraints`` (eq. 3.8, section 4.2).
CONSTRAINT_NAMES = ("p_min", "wn_min", "zeta_min", "zeta_max", "f_max")


# --------------------------------------------------------------------------------------
# search variables <-> normalised denominator (eq. 3.14, 3.15)
# --------------------------------------------------------------------------------------
def alphas_from_search(wn, zeta, p) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normalised denominator parameters of eq. 3.14, vectorised (numpy broadcasting).

    Parameters
    ----------
    wn : float or array
        Natural frequency of the pole pair, rad/s.
    zeta : float or array
        Damping ratio of the pair, dimensionless (zeta >= 1: two real poles).
    p : float or array
        Real pole, rad/s (the pole is at s = -p).

    Returns
    -------
    alpha_i, alpha_1, alpha_2 : arrays
        a3/a2 (1/s), a1/a2 (s), 1/a2 (s^2), with a1 = p + 2 zeta wn, a2 = wn^2 + 2 p zeta wn,
        a3 = p wn^2.
    """
    wn = np.asarray(wn, dtype=float)
    zeta = np.asarray(zeta, dtype=float)
    p = np.asarray(p, dtype=float)
    a2 = wn * wn + 2.0 * p * zeta * wn
    inv_a2 = 1.0 / a2
    return p * wn * wn * inv_a2, (p + 2.0 * zeta * wn) * inv_a2, inv_a2


def alphas_jacobian(wn, zeta, p) -> np.ndarray:
    """Jacobian d(alpha_i, alpha_1, alpha_2)/d(wn, zeta, p), shape (..., 3, 3).

    This is the matrix G of eq. 3.15 with its columns reordered from (p, wn, zeta) to the
    search-variable order (wn, zeta, p) of eq. 4.1.  Units follow :func:`alphas_from_search`.
    """
    wn = np.asarray(wn, dtype=float)
    zeta = np.asarray(zeta, dtype=float)
    p = np.asarray(p, dtype=float)
    a1 = p + 2.0 * zeta * wn
    a2 = wn * wn + 2.0 * p * zeta * wn
    a3 = p * wn * wn
    # partial derivatives of (a1, a2, a3) w.r.t. (wn, zeta, p)
    da1 = np.stack(np.broadcast_arrays(2.0 * zeta, 2.0 * wn, np.ones_like(p)), axis=-1)
    da2 = np.stack(np.broadcast_arrays(2.0 * wn + 2.0 * p * zeta, 2.0 * p * wn, 2.0 * zeta * wn), axis=-1)
    da3 = np.stack(np.broadcast_arrays(2.0 * p * wn, np.zeros_like(zeta), wn * wn), axis=-1)
    inv = (1.0 / a2)[..., None]
    inv2 = inv * inv
    d_alpha_i = da3 * inv - a3[..., None] * da2 * inv2
    d_alpha_1 = da1 * inv - a1[..., None] * da2 * inv2
    d_alpha_2 = -da2 * inv2
    return np.stack([d_alpha_i, d_alpha_1, d_alpha_2], axis=-2)


def factorisations(a1: float, a2: float, a3: float) -> list[tuple[float, float, float]]:
    """All real factorisations (wn, zeta, p) of s^3 + a1 s^2 + a2 s + a3 (eq. 3.7), rad/s.

    One entry for a complex pair; up to three for three real poles (every choice of the
    "pair" whose pole product is positive).  Unstable roots give negative p or zeta.
    """
    roots = np.roots([1.0, a1, a2, a3])
    # A double real root comes out of np.roots as a pair with |imag| ~ sqrt(eps) |s|; such
    # near-real pairs are treated as real (pole positions change by < 1e-6 relative).
    cplx = [r for r in roots if abs(r.imag) > 1e-6 * abs(r)]
    if cplx:
        s = cplx[0]
        real = [r for r in roots if abs(r.imag) <= 1e-6 * abs(r)]
        wn = abs(s)
        zeta = -s.real / wn if wn > 0 else math.nan
        p = -real[0].real if real else math.nan
        return [(float(wn), float(zeta), float(p))]
    r = [-float(x.real) for x in roots]  # pole magnitudes (positive for stable poles)
    out = []
    for k in range(len(r)):
        pair = [r[m] for m in range(len(r)) if m != k]
        prod = pair[0] * pair[1]
        if prod <= 0.0:
            continue
        wn = math.sqrt(prod)
        out.append((wn, (pair[0] + pair[1]) / (2.0 * wn), r[k]))
    return out


def canonical_search(wn, zeta, p, lower=None, upper=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Re-express search variables in the canonical factorisation, vectorised.

    Where zeta >= 1 the three poles are real (p and wn (zeta -+ sqrt(zeta^2 - 1))) and the
    same polynomial has other factorisations (module docstring).  Returns, per point, the
    factorisation with the smallest zeta among those inside the box [lower, upper] over
    (wn rad/s, zeta, p rad/s) (any, if no box is given); points with zeta < 1, or without a
    feasible alternative, are returned unchanged.  The cost of eq. 3.12 is identical.

    Why: (wn, zeta, p) -> (a1, a2, a3) folds where p equals a pole of the pair (det G = 0 in
    eq. 3.16, denominator p^2 - 2 p zeta wn + wn^2), and a local search sitting on such a fold
    cannot reach the complex-pole region next to it.  In the smallest-zeta factorisation the
    pair is formed by the two closest poles, so a fold can only occur at a triple pole.
    """
    wn, zeta, p = (np.array(v, dtype=float) for v in np.broadcast_arrays(wn, zeta, p))
    real = zeta >= 1.0
    if not np.any(real):
        return wn, zeta, p
    s = np.sqrt(np.maximum(zeta[real] ** 2 - 1.0, 0.0))
    q = np.sort(np.stack([wn[real] * (zeta[real] - s), wn[real] * (zeta[real] + s), p[real]]), axis=0)
    opts = [(wn[real], zeta[real], p[real])]
    for a, b, c in ((q[0], q[1], q[2]), (q[1], q[2], q[0])):
        w = np.sqrt(a * b)
        opts.append((w, (a + b) / (2.0 * w), c))
    best_w, best_z, best_p = (np.array(x) for x in opts[0])
    for w, z, c in opts[1:]:
        ok = z < best_z
        if lower is not None:
            lo = np.asarray(lower, dtype=float)
            ok &= (w >= lo[0] * (1 - 1e-12)) & (z >= lo[1] - 1e-12) & (c >= lo[2] * (1 - 1e-12))
        if upper is not None:
            hi = np.asarray(upper, dtype=float)
            ok &= (w <= hi[0] * (1 + 1e-12)) & (z <= hi[1] + 1e-12) & (c <= hi[2] * (1 + 1e-12))
        best_w, best_z, best_p = np.where(ok, w, best_w), np.where(ok, z, best_z), np.where(ok, c, best_p)
    if lower is not None or upper is not None:  # remove rounding excursions past the bounds
        lo = -np.inf * np.ones(3) if lower is None else np.asarray(lower, dtype=float)
        hi = np.inf * np.ones(3) if upper is None else np.asarray(upper, dtype=float)
        best_w, best_z, best_p = np.clip(best_w, lo[0], hi[0]), np.clip(best_z, lo[1], hi[1]), np.clip(best_p, lo[2], hi[2])
    wn[real], zeta[real], p[real] = best_w, best_z, best_p
    return wn, zeta, p


def _root_list(coeffs: np.ndarray) -> list[tuple[float, float]]:
    """Roots of a polynomial as (freq_hz, damping), sorted by decreasing frequency."""
    coeffs = np.asarray(coeffs, dtype=float)
    nz = np.flatnonzero(coeffs != 0.0)
    if nz.size == 0:
        return []
    roots = np.roots(coeffs[nz[0]:])
    out = []
    for s in roots:
        mag = abs(s)
        out.append((mag / TWO_PI, (-s.real / mag) if mag > 0 else 1.0))
    out.sort(key=lambda fd: -fd[0])
    return [(float(f), float(d)) for f, d in out]


def _json_float(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


# --------------------------------------------------------------------------------------
# the model
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DriveModel:
    """Closed-loop axis model of eq. 3.3.

    Attributes
    ----------
    a1 : float  -- 1/s      a2 : float  -- 1/s^2     a3 : float -- 1/s^3
    b0 : float  -- (none)   b1 : float  -- 1/s       b2 : float -- 1/s^2
    d0 : float  -- mm/s^2, control-equivalent Coulomb friction while moving positive
    d1 : float  -- mm/s^2, the same while moving negative (normally < 0)
    """

    a1: float
    a2: float
    a3: float
    b0: float
    b1: float
    b2: float
    d0: float
    d1: float

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            try:
                v = float(v)
            except (TypeError, ValueError) as exc:
                raise InputError(f"drive model parameter {f.name} must be a number, got {v!r}") from exc
            if not math.isfinite(v):
                raise InputError(f"drive model parameter {f.name} is not finite: {v}")
            object.__setattr__(self, f.name, v)

    # ---- theta (eq. 3.10-3.11) -------------------------------------------------------
    @property
    def theta(self) -> np.ndarray:
        """Normalised parameter vector of eq. 3.11, shape (8,), order :data:`THETA_NAMES`."""
        if self.a2 == 0.0:
            raise IdentificationError("model has a2 = 0: cannot normalise by a2 (eq. 3.10)")
        return np.array([self.a3, self.a1, 1.0, self.b2, self.b1, self.b0, self.d0, self.d1]) / self.a2

    @classmethod
    def from_theta(cls, theta) -> "DriveModel":
        """Inverse of eq. 3.10: ``theta`` in the order of eq. 3.11 -> physical parameters."""
        theta = np.asarray(theta, dtype=float).reshape(-1)
        if theta.shape != (8,):
            raise InputError(f"theta must have 8 entries (eq. 3.11), got {theta.size}")
        if not np.all(np.isfinite(theta)):
            raise IdentificationError(f"theta has non-finite entries: {theta.tolist()}")
        alpha_i, alpha_1, alpha_2, beta_0, beta_1, beta_2, delta_p, delta_m = theta
        if alpha_2 == 0.0:
            raise IdentificationError("alpha_2 = 1/a2 is zero: theta does not describe a drive model")
        a2 = 1.0 / alpha_2
        return cls(a1=alpha_1 * a2, a2=a2, a3=alpha_i * a2, b0=beta_2 * a2, b1=beta_1 * a2,
                   b2=beta_0 * a2, d0=delta_p * a2, d1=delta_m * a2)

    # ---- search variables (eq. 3.7, 3.14) ------------------------------------------
    @classmethod
    def from_search(cls, wn: float, zeta: float, p: float, beta0: float, beta1: float, beta2: float,
                    delta_plus: float, delta_minus: float) -> "DriveModel":
        """Model from search variables (wn rad/s, zeta, p rad/s) and the normalised theta_2.

        ``beta0, beta1, beta2`` (-, s, s^2) and ``delta_plus, delta_minus`` (mm/s^2 / a2 = mm)
        are the last five entries of theta (eq. 4.8).
        """
        alpha_i, alpha_1, alpha_2 = (float(v) for v in alphas_from_search(wn, zeta, p))
        return cls.from_theta([alpha_i, alpha_1, alpha_2, beta0, beta1, beta2, delta_plus, delta_minus])

    def factorisations(self) -> list[tuple[float, float, float]]:
        """Every (wn rad/s, zeta, p rad/s) with (s+p)(s^2+2 zeta wn s+wn^2) = the denominator."""
        return factorisations(self.a1, self.a2, self.a3)

    def search_variables(self, bounds: "Bounds | None" = None,
                         sample_period: float | None = None) -> tuple[float, float, float]:
        """(wn rad/s, zeta, p rad/s) of eq. 3.7, with the convention of the module docstring.

        Parameters
        ----------
        bounds : Bounds, optional
            If given, prefer a factorisation that satisfies them (three real poles only).
        sample_period : float, optional
            Sample period in s, for the Nyquist bound when ``bounds.f_max_hz`` is None.
        """
        cands = self.factorisations()
        if not cands:
            return (math.nan, math.nan, math.nan)
        if bounds is not None and len(cands) > 1:
            viol = [bounds.violation(*c, sample_period=sample_period) for c in cands]
            best = min(viol)
            cands = [c for c, v in zip(cands, viol) if v <= best + 1e-12]
        return min(cands, key=lambda c: c[1])

    # ---- poles, zeros, transfer functions ------------------------------------------
    @property
    def denominator(self) -> np.ndarray:
        """Characteristic polynomial [1, a1, a2, a3] (eq. 3.7), highest power first."""
        return np.array([1.0, self.a1, self.a2, self.a3])

    @property
    def numerator(self) -> np.ndarray:
        """Tracking numerator [b0, b1, b2, a3], highest power first."""
        return np.array([self.b0, self.b1, self.b2, self.a3])

    def poles(self) -> list[tuple[float, float]]:
        """Closed-loop poles as (freq_hz, damping), decreasing frequency (thesis Table 3.4)."""
        return _root_list(self.denominator)

    def zeros(self) -> list[tuple[float, float]]:
        """Zeros of b0 s^3 + b1 s^2 + b2 s + a3 as (freq_hz, damping); two when b0 = 0."""
        return _root_list(self.numerator)

    def tracking_tf(self) -> tuple[np.ndarray, np.ndarray]:
        """G_track = (b0 s^3 + b1 s^2 + b2 s + a3) / (s^3 + a1 s^2 + a2 s + a3), (num, den)."""
        return self.numerator, self.denominator

    def disturbance_tf(self) -> tuple[np.ndarray, np.ndarray]:
        """G_dist = s / (s^3 + a1 s^2 + a2 s + a3), (num, den).

        Acts on the control-equivalent friction d in mm/s^2: x = G_track x_r - G_dist d.
        """
        return np.array([1.0, 0.0]), self.denominator

    def freqresp(self, f_hz) -> tuple[np.ndarray, np.ndarray]:
        """Complex frequency responses (H_track [mm/mm], H_dist [mm/(mm/s^2)]) at ``f_hz`` (Hz)."""
        s = 1j * TWO_PI * np.asarray(f_hz, dtype=float)
        den = np.polyval(self.denominator, s)
        return np.polyval(self.numerator, s) / den, s / den

    def dc_gains(self) -> tuple[float, float]:
        """Steady-state gains (tracking mm/mm, disturbance mm/(mm/s^2)).

        With integral action (a3 != 0) tracking is 1 and constant friction is rejected (0).
        Without it (a3 = 0) the common factor s cancels: b2/a2 and 1/a2.
        """
        if self.a3 != 0.0:
            return 1.0, 0.0
        if self.a2 == 0.0:
            return math.nan, math.inf
        return self.b2 / self.a2, 1.0 / self.a2

    # ---- JSON ----------------------------------------------------------------------------
    def to_dict(self, bounds: "Bounds | None" = None, sample_period: float | None = None) -> dict[str, Any]:
        """The per-axis "model" part of SPEC section 6 (search variables in Hz)."""
        wn, zeta, p = self.search_variables(bounds, sample_period)
        track_dc, dist_dc = self.dc_gains()
        return {
            "model": {f.name: float(getattr(self, f.name)) for f in fields(self)},
            "search_variables": {"wn_hz": _json_float(wn / TWO_PI), "zeta": _json_float(zeta),
                                 "p_hz": _json_float(p / TWO_PI)},
            "poles": [{"freq_hz": _json_float(f), "damping": _json_float(d)} for f, d in self.poles()],
            "zeros": [{"freq_hz": _json_float(f), "damping": _json_float(d)} for f, d in self.zeros()],
            "dc_gain": {"tracking": _json_float(track_dc), "disturbance_mm_per_mm_s2": _json_float(dist_dc)},
        }


#: The eight parameters of eq. 3.3 in the order every vector of them uses (the fields of
#: :class:`DriveModel`; the simulator's θ, the uncertainty's columns, the JSON's ``base``).
BASE_KEYS: tuple[str, ...] = tuple(f.name for f in fields(DriveModel))


def base_vector(model: Any) -> np.ndarray:
    """θ = (a1, a2, a3, b0, b1, b2, d0, d1) of eq. 3.3, (8,), from a DriveModel-like object or a mapping.

    Raises TypeError naming the parameters when one is missing or not a number.
    """
    get = model.__getitem__ if isinstance(model, dict) else (lambda k: getattr(model, k))
    try:
        return np.array([float(get(k)) for k in BASE_KEYS])
    except (KeyError, AttributeError, TypeError, ValueError) as exc:
        raise TypeError(f"model needs the parameters {', '.join(BASE_KEYS)} of eq. 3.3: {exc}") from exc


# --------------------------------------------------------------------------------------
# constraints (eq. 3.8)
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Bounds:
    """Pole constraints of eq. 3.8 plus the upper frequency bound of section 4.2.

    Attributes
    ----------
    p_min_hz : float
        Lower bound on the real pole p, Hz (default 0.2 Hz).
    wn_min_hz : float
        Lower bound on the natural frequency of the pair, Hz (default 0.2 Hz).
    zeta_min, zeta_max : float
        Damping-ratio bounds of the pair (defaults 0.2 and 2.0; zeta >= 1 = two real poles).
    f_max_hz : float or None
        Upper bound on both wn and p, Hz.  None means the Nyquist frequency 1/(2 T_s),
        resolved wherever a sample period is known (:meth:`with_sample_period`).
    """

    p_min_hz: float = 0.2
    wn_min_hz: float = 0.2
    zeta_min: float = 0.2
    zeta_max: float = 2.0
    f_max_hz: float | None = None

    def __post_init__(self) -> None:
        for name in ("p_min_hz", "wn_min_hz", "zeta_min", "zeta_max"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"bound {name} must be a positive number, got {v!r}")
        if not self.zeta_max > self.zeta_min:
            raise InputError(f"bound zeta_max = {self.zeta_max} must exceed zeta_min = {self.zeta_min}")
        if self.f_max_hz is not None:
            v = self.f_max_hz
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"bound f_max_hz must be a positive number or None, got {v!r}")
            if v <= max(self.p_min_hz, self.wn_min_hz):
                raise InputError(f"bound f_max_hz = {v} Hz must exceed p_min_hz and wn_min_hz "
                                 f"({self.p_min_hz}, {self.wn_min_hz} Hz)")

    # ---- unit conversions, once --------------------------------------------------------
    @property
    def p_min(self) -> float:
        """p_min in rad/s."""
        return TWO_PI * self.p_min_hz

    @property
    def wn_min(self) -> float:
        """wn_min in rad/s."""
        return TWO_PI * self.wn_min_hz

    def f_max(self, sample_period: float | None = None) -> float:
        """Upper frequency bound in rad/s (``f_max_hz`` or Nyquist of ``sample_period`` s); inf if neither."""
        hz = self.f_max_hz_for(sample_period)
        return math.inf if hz is None else TWO_PI * hz

    def f_max_hz_for(self, sample_period: float | None = None) -> float | None:
        """Upper frequency bound in Hz: ``f_max_hz`` if set, else 1/(2 sample_period), else None."""
        if self.f_max_hz is not None:
            return float(self.f_max_hz)
        if sample_period is None:
            return None
        if not (math.isfinite(sample_period) and sample_period > 0):
            raise InputError(f"sample period must be a positive number of seconds, got {sample_period!r}")
        return 0.5 / sample_period

    def with_sample_period(self, sample_period: float) -> "Bounds":
        """Copy with ``f_max_hz`` set to the Nyquist frequency 1/(2 T_s) if it was None."""
        return replace(self, f_max_hz=self.f_max_hz_for(sample_period))

    def box(self, sample_period: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Search box (lower, upper) over (wn rad/s, zeta, p rad/s), section 4.2 / Fig. 4.1.

        Raises InputError if the upper frequency bound is unknown (no f_max_hz, no sample period).
        """
        fmax = self.f_max(sample_period)
        if not math.isfinite(fmax):
            raise InputError("the search box needs an upper frequency bound: set Bounds.f_max_hz "
                             "or pass sample_period (Nyquist)")
        return (np.array([self.wn_min, self.zeta_min, self.p_min]),
                np.array([fmax, self.zeta_max, fmax]))

    # ---- checks ------------------------------------------------------------------------
    def violation(self, wn: float, zeta: float, p: float, sample_period: float | None = None) -> float:
        """Sum of relative constraint violations of (wn rad/s, zeta, p rad/s); 0 when feasible."""
        if not all(math.isfinite(v) for v in (wn, zeta, p)):
            return math.inf
        fmax = self.f_max(sample_period)
        v = max(0.0, (self.p_min - p) / self.p_min) + max(0.0, (self.wn_min - wn) / self.wn_min)
        v += max(0.0, self.zeta_min - zeta) + max(0.0, zeta - self.zeta_max)
        if math.isfinite(fmax):
            v += max(0.0, (wn - fmax) / fmax) + max(0.0, (p - fmax) / fmax)
        return v

    def violated(self, wn: float, zeta: float, p: float, sample_period: float | None = None,
                 rtol: float = 1e-9) -> list[str]:
        """Names (:data:`CONSTRAINT_NAMES`) of the constraints (wn, zeta, p) violate beyond ``rtol``."""
        if not all(math.isfinite(v) for v in (wn, zeta, p)):
            return list(CONSTRAINT_NAMES[:4])
        fmax = self.f_max(sample_period)
        out = []
        if p < self.p_min * (1 - rtol):
            out.append("p_min")
        if wn < self.wn_min * (1 - rtol):
            out.append("wn_min")
        if zeta < self.zeta_min - rtol:
            out.append("zeta_min")
        if zeta > self.zeta_max + rtol:
            out.append("zeta_max")
        if max(wn, p) > fmax * (1 + rtol):
            out.append("f_max")
        return out

    def active(self, wn: float, zeta: float, p: float, sample_period: float | None = None,
               rtol: float = 1e-7) -> tuple[str, ...]:
        """Names of the constraints (wn rad/s, zeta, p rad/s) lie on, within ``rtol``."""
        fmax = self.f_max(sample_period)
        out = []
        if abs(p - self.p_min) <= rtol * self.p_min:
            out.append("p_min")
        if abs(wn - self.wn_min) <= rtol * self.wn_min:
            out.append("wn_min")
        if abs(zeta - self.zeta_min) <= rtol:
            out.append("zeta_min")
        if abs(zeta - self.zeta_max) <= rtol:
            out.append("zeta_max")
        if math.isfinite(fmax) and (abs(wn - fmax) <= rtol * fmax or abs(p - fmax) <= rtol * fmax):
            out.append("f_max")
        return tuple(out)

    def check(self, model: DriveModel, sample_period: float | None = None) -> list[str]:
        """Violated constraints of ``model`` (empty list: every pole inside the bounds).

        With three real poles the model is feasible if any factorisation is; the names
        returned belong to the least-violating factorisation.
        """
        wn, zeta, p = model.search_variables(self, sample_period)
        return self.violated(wn, zeta, p, sample_period)

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

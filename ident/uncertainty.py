"""95 % confidence intervals of an identified drive model, from its output-error fit.

The refined model minimises the free-run output error (:mod:`ident.refine`)::

    r(a) = x̂(a) − x,      a = (a1, a2, a3, b0, b1, b2, d0, d1)       (eq. 3.3)

Linearised at the estimate â, r(a) ≈ r(â) + J (a − â) with J = ∂x̂/∂a (N × 8, central
differences of the simulation, :func:`output_error_jacobian`).  The Gauss–Newton
covariance σ²(JᵀJ)⁻¹ assumes independent residuals; an output-error residual is not:
noise and unmodelled dynamics pass through the closed loop and stay correlated over
many samples, and σ²(JᵀJ)⁻¹ then understates the spread by about the correlation time
(two to three times on the thesis's drives).  This module uses the covariance that holds
for correlated residuals, the linearised delete-one-block jackknife::

    δ_b = (JᵀJ − J_bᵀJ_b)⁻¹ J_bᵀ r_b,        Cov(â) = (B − 1)/B Σ_b δ_b δ_bᵀ

over B contiguous blocks of L samples (blocks never span a segment seam): δ_b is the
Gauss–Newton move of the estimate when block b is left out.  It is the least-squares
sandwich (JᵀJ)⁻¹ S (JᵀJ)⁻¹ with each block's score corrected for that block's own
leverage (the CR3 cluster estimator) — the correction matters for friction, whose
information sits in few blocks (reversals, segment starts) that the fit has already
absorbed — and the linearisation of a block bootstrap/jackknife over the same blocks,
deterministic.  L is chosen from the data: five integrated
autocorrelation times of the scores J_k r_k (Sokal's automatic window, c = 5), capped so
that at least 5 n blocks remain (n = 8 parameters).  Intervals are â ± t_{0.975, B−n} · se
(Student's t with the blocks as independent draws); ``effective_samples`` = N / τ is how
many independent samples the recording is worth.

The simulation starts each segment from the *recorded* position, so the noise of that one
sample runs through the whole start transient (it moves the integrator and the friction
offset together); its effect, (JᵀJ)⁻¹ Jᵀ J₀ σ² J₀ᵀ J (JᵀJ)⁻¹ with J₀ = ∂x̂/∂x̂(start) and
σ² the residual variance, is added to the covariance.

Derived quantities by the delta method (first-order propagation ∇g Cov ∇gᵀ, gradients
by central differences): the search variables (ω_n, ζ, p) of eq. 3.7, every pole and
zero (frequency in Hz, damping; roots matched to the estimate's by nearness).

Constraints.  Where the estimate sits on a bound of eq. 3.8 (``Bounds.active``) the
estimator is the equality-constrained one, and its covariance is projected onto the
constraint surface: C ← C − C c (cᵀ C c)⁻¹ cᵀ C with c the gradient of the active
search variable.  The bound, not the data, places that variable: it is marked
``at_bound`` and its interval is the single value.

What the data do not determine.  A parameter whose interval is wider than its value
(the interval includes 0) is marked; so is every direction of the relative covariance
D⁻¹ C D⁻¹ (D the parameters' scales) along which the 95 % half-width exceeds 100 %:
the parameters with large components move together there without changing the fit,
and only combinations across that direction are determined.

Equivalent model.  When poles sit on bounds, parameters or directions are not
determined, friction pushes the axis along its motion (d0 < 0 or d1 > 0), or a pole and
a zero nearly cancel with that pole not determined, the parameters are those of an
*equivalent* model: what is identified is the tracking response over the band the
recording excites, not the drive's physical gains — as the thesis found for its P-PI
drive (Table 3.3: a 36 Hz pair identified as real poles at 369 and 48 Hz, friction 17×
off, the FRF matched to 30 Hz).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np
from scipy.special import stdtrit

from ident.gauss_newton import to_stationary_point
from ident.model import BASE_KEYS, Bounds, DriveModel
from ident.preprocessing import segment_slices

__all__ = ["PARAMETER_NAMES", "Interval", "RootInterval", "WeakDirection", "Uncertainty",
           "output_error_jacobian", "estimate_uncertainty", "stationary_point", "block_length"]

#: The eight parameters of eq. 3.3, in the order of J's columns.
PARAMETER_NAMES = BASE_KEYS
#: The search variables of eq. 3.7, as reported (Hz, -, Hz).
SEARCH_NAMES = ("wn_hz", "zeta", "p_hz")
_TWO_PI = 2.0 * math.pi
#: A pole and a zero "nearly cancel" when |s_pole − s_zero| < this fraction of |s_pole|.
_CANCEL_REL = 0.05
#: Sokal's window constant: sum the autocorrelation up to the first lag M >= c·τ(M).
_SOKAL_C = 5.0
#: Blocks are this many integrated autocorrelation times long.
_BLOCK_TAUS = 5.0
#: At least this many blocks per parameter.
_BLOCKS_PER_PARAMETER = 5


@dataclass(frozen=True)
class Interval:
    """A 95 % confidence interval of one quantity.

    Attributes
    ----------
    value : float
        The estimate (units of the quantity).
    lo, hi : float
        Interval ends; equal to ``value`` when a bound holds it.
    se : float
        Standard error (0 when a bound holds it).
    undetermined : bool
        The interval is wider than the value itself (it includes 0) and than a tenth of
        the parameter's natural size (:func:`_scales`): the data do not fix it.
    at_bound : str or None
        Name of the constraint of eq. 3.8 that holds it (``Bounds.active``), if any.
    near_zero : bool
        The interval includes 0 but is narrow against the parameter's natural size: the
        data determine it to be about 0 (b0 of a drive without acceleration feedforward).
    """

    value: float
    lo: float
    hi: float
    se: float
    undetermined: bool = False
    at_bound: str | None = None
    near_zero: bool = False

    def to_list(self) -> list[float | None]:
        return [_f(self.lo), _f(self.hi)]

    def mark(self) -> str:
        """"at bound (name)", "not determined" or ""."""
        if self.at_bound:
            return f"at bound ({self.at_bound})"
        if self.undetermined:
            return "not determined"
        return "≈ 0" if self.near_zero else ""


@dataclass(frozen=True)
class RootInterval:
    """A pole or zero (thesis Table 3.4 convention: frequency |s| in Hz, damping −Re s/|s|)."""

    freq_hz: float
    damping: float
    freq_hz_interval95: tuple[float, float]
    damping_interval95: tuple[float, float]
    undetermined: bool = False
    at_bound: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"freq_hz": _f(self.freq_hz), "damping": _f(self.damping),
                "freq_hz_interval95": [_f(v) for v in self.freq_hz_interval95],
                "damping_interval95": [_f(v) for v in self.damping_interval95],
                "undetermined": bool(self.undetermined), "at_bound": self.at_bound}

    def mark(self) -> str:
        if self.at_bound:
            return f"at bound ({self.at_bound})"
        return "not determined" if self.undetermined else ""


@dataclass(frozen=True)
class WeakDirection:
    """A combination of parameters the data do not determine.

    ``components`` are the direction's entries in relative units (δa_k / scale_k), only
    those above 0.25 in size; ``half_width`` the 95 % half-width along it (relative,
    1 = 100 %); ``text`` says in words what moves and what is determined.
    """

    components: dict[str, float]
    half_width: float
    text: str

    def to_dict(self) -> dict[str, Any]:
        return {"components": {k: round(v, 3) for k, v in self.components.items()},
                "half_width_relative": _f(self.half_width), "text": self.text}


@dataclass(frozen=True)
class Uncertainty:
    """Confidence intervals of one axis's model (module docstring).

    Attributes
    ----------
    parameters : dict
        :class:`Interval` per name of :data:`PARAMETER_NAMES` and :data:`SEARCH_NAMES`.
    poles, zeros : list of RootInterval
        In the order of :meth:`DriveModel.poles` / :meth:`DriveModel.zeros`.
    weak_directions : list of WeakDirection
    covariance : ndarray (8, 8)
        Of (a1 … d1), after projection onto any active constraint.
    n_samples, block_length, n_blocks : int
    effective_samples : float
        N / τ, τ the integrated autocorrelation time of the scores.
    residual_rms_mm : float
    is_equivalent : bool
    why : list of str
        The reasons the model is an equivalent one (empty if none).
    method : str
    """

    parameters: dict[str, Interval]
    poles: list[RootInterval]
    zeros: list[RootInterval]
    weak_directions: list[WeakDirection]
    covariance: np.ndarray
    n_samples: int
    block_length: int
    n_blocks: int
    effective_samples: float
    residual_rms_mm: float
    is_equivalent: bool
    why: list[str] = field(default_factory=list)
    method: str = ("output-error Gauss-Newton covariance, linearised delete-one-block jackknife for "
                   "correlated residuals; delta method for derived quantities")

    @property
    def undetermined(self) -> list[str]:
        """Names of the parameters and search variables the data do not determine."""
        return [k for k, v in self.parameters.items() if v.undetermined and not v.at_bound]

    @property
    def at_bound(self) -> list[str]:
        return [k for k, v in self.parameters.items() if v.at_bound]

    def equivalent_text(self) -> str:
        if not self.is_equivalent:
            return ("Every parameter is determined by the data and no bound holds a pole.  The intervals measure "
                    "the noise only: where the drive differs from eq. 3.3 (a sampled controller, a delay) the "
                    "parameters are those of the closest eq. 3.3 model and can differ from its physical gains by "
                    "more than the intervals.")
        return ("Equivalent model: " + "; ".join(self.why) + ". What is identified is the tracking response "
                "over the band the recording excites, not the drive's physical gains (as the thesis found for "
                "its P-PI drive, Table 3.3).")

    def rows(self) -> list[tuple[str, str, str, str]]:
        """(quantity, value, 95 % interval, mark) per parameter, search variable, pole and zero,
        as text for the summary and the report."""
        out = []
        for k, iv in self.parameters.items():
            out.append((k, _g(iv.value), f"[{_g(iv.lo)}, {_g(iv.hi)}]", iv.mark()))
        for kind, roots in (("pole", self.poles), ("zero", self.zeros)):
            for i, rt in enumerate(roots, 1):
                lo, hi = rt.freq_hz_interval95
                dlo, dhi = rt.damping_interval95
                out.append((f"{kind} {i}", f"{rt.freq_hz:.4g} Hz, ζ {rt.damping:.2f}",
                            f"[{_g(lo)}, {_g(hi)}] Hz, ζ [{dlo:.2f}, {dhi:.2f}]", rt.mark()))
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON additions of one axis (keys beside SPEC's "model", "poles", "zeros")."""
        return {
            "model_interval95": {k: self.parameters[k].to_list() for k in PARAMETER_NAMES},
            "search_variables_interval95": {k: self.parameters[k].to_list() for k in SEARCH_NAMES},
            "standard_error": {k: _f(v.se) for k, v in self.parameters.items()},
            "at_bound": {k: v.at_bound for k, v in self.parameters.items() if v.at_bound},
            "undetermined": self.undetermined,
            "near_zero": [k for k, v in self.parameters.items() if v.near_zero],
            "weak_directions": [w.to_dict() for w in self.weak_directions],
            "poles": [p.to_dict() for p in self.poles],
            "zeros": [z.to_dict() for z in self.zeros],
            "equivalent_model": {"is_equivalent": bool(self.is_equivalent), "why": self.equivalent_text(),
                                 "reasons": list(self.why)},
            "method": self.method,
            "samples": {"n": self.n_samples, "block_length": self.block_length, "blocks": self.n_blocks,
                        "effective": _f(self.effective_samples)},
            "residual_rms_mm": _f(self.residual_rms_mm),
        }


def _g(v: float) -> str:
    return f"{v:.4g}" if math.isfinite(v) else "unbounded"


def _f(v: float) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None


# --------------------------------------------------------------------------------------
# Jacobian of the free run
# --------------------------------------------------------------------------------------
def _scales(values: np.ndarray) -> np.ndarray:
    """Natural size of each parameter: |a_k|, with floors for ones that may be 0.

    b0 is dimensionless (1 for full acceleration feedforward), b1 is compared with a1,
    b2 with a2, the friction terms with the larger of the two.
    """
    a1, a2, a3, b0, b1, b2, d0, d1 = (abs(float(v)) for v in values)
    d = max(d0, d1, 1e-9)
    return np.array([max(a1, 1e-9), max(a2, 1e-9), max(a3, 1e-9), max(b0, 1.0), max(b1, a1, 1e-9),
                     max(b2, a2, 1e-9), max(d0, d), max(d1, d)])


def output_error_jacobian(simulate: Callable[[DriveModel], np.ndarray], model: DriveModel, x: np.ndarray,
                          rel_step: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
    """J = ∂x̂/∂(a1 … d1) (N, 8) by central differences, and the residual r = x̂ − x (N,), mm.

    Parameters
    ----------
    simulate : callable
        ``simulate(model) -> x̂`` (N,), the free run the refinement fitted (e.g.
        :class:`ident.simulation.FreeRun` of the shifted command).
    model : DriveModel
        The estimate.
    x : ndarray (N,)
        Recorded actual position, mm.
    rel_step : float
        Difference step relative to each parameter's scale (:func:`_scales`).
    """
    v = np.array([getattr(model, k) for k in PARAMETER_NAMES], dtype=float)
    x = np.asarray(x, dtype=float)
    r = simulate(model) - x
    h = rel_step * _scales(v)
    J = np.empty((r.size, 8))
    for j in range(8):
        vp, vm = v.copy(), v.copy()
        vp[j] += h[j]
        vm[j] -= h[j]
        J[:, j] = (simulate(DriveModel(*vp)) - simulate(DriveModel(*vm))) / (2.0 * h[j])
    return J, r


# --------------------------------------------------------------------------------------
# covariance for correlated residuals
# --------------------------------------------------------------------------------------
def _integrated_time(y: np.ndarray) -> float:
    """Integrated autocorrelation time τ = 1 + 2 Σ ρ_k, Sokal's window (first M >= c τ(M))."""
    y = np.asarray(y, dtype=float) - np.mean(y)
    n = y.size
    if n < 4 or not np.any(y):
        return 1.0
    f = np.fft.rfft(y, 2 * n)
    ac = np.fft.irfft(f * np.conj(f))[:n]
    rho = ac / ac[0]
    tau = 2.0 * np.cumsum(rho) - 1.0  # tau(M) = 1 + 2 sum_{k=1..M} rho_k
    m = np.arange(n)
    ok = m >= _SOKAL_C * tau
    M = int(np.argmax(ok)) if np.any(ok) else n - 1
    return float(max(tau[M], 1.0))


def block_length(scores: np.ndarray, n_params: int = 8) -> tuple[int, float]:
    """Block length L (samples) for the batch-means covariance, and the integrated time τ.

    τ is the largest integrated autocorrelation time of the score columns J_k r_k;
    L = 5 τ, at most N / (5 n) so that enough blocks remain, at least 1.
    """
    scores = np.atleast_2d(np.asarray(scores, dtype=float))
    n = scores.shape[0]
    tau = max(_integrated_time(scores[:, j]) for j in range(scores.shape[1]))
    cap = max(n // (_BLOCKS_PER_PARAMETER * n_params), 1)
    return int(min(max(math.ceil(_BLOCK_TAUS * tau), 1), cap)), tau


def _blocks(n: int, L: int, segment: np.ndarray | None) -> list[slice]:
    """Contiguous blocks of about L samples inside each segment (a short tail joins the last)."""
    out = []
    for sl in segment_slices(segment, n):
        start, stop = sl.start, sl.stop
        k = max((stop - start) // L, 1)
        edges = [start + i * L for i in range(k)] + [stop]
        out += [slice(a, b) for a, b in zip(edges[:-1], edges[1:])]
    return out


def _sandwich(J: np.ndarray, r: np.ndarray, segment: np.ndarray | None) -> tuple[np.ndarray, int, int, float]:
    """Block-jackknife covariance in the scaled parameters, with L, B and τ (module docstring).

    Leaving block b out moves the Gauss–Newton estimate by δ_b = (A − J_bᵀJ_b)⁻¹ J_bᵀ r_b
    (A = JᵀJ); the covariance is (B − 1)/B Σ_b δ_b δ_bᵀ.  This is the sandwich
    A⁻¹ S A⁻¹ with each block's score J_bᵀ r_b corrected for the block's own leverage —
    without it a parameter whose information sits in few blocks (friction: reversals and
    segment starts) gets a variance too small, because the fit has already absorbed most
    of those blocks' residual.
    """
    n, p = J.shape
    scores = J * r[:, None]
    L, tau = block_length(scores, p)
    blocks = _blocks(n, L, segment)
    B = len(blocks)
    A = J.T @ J
    D = np.empty((B, p))
    for i, b in enumerate(blocks):
        Jb = J[b]
        D[i] = np.linalg.lstsq(A - Jb.T @ Jb, scores[b].sum(axis=0), rcond=1e-14)[0]
    cov = D.T @ D * ((B - 1) / B)
    return 0.5 * (cov + cov.T), L, B, tau


# --------------------------------------------------------------------------------------
# derived quantities
# --------------------------------------------------------------------------------------
def _match(roots: np.ndarray, nominal: np.ndarray) -> np.ndarray:
    """``roots`` reordered to pair each nominal root with its nearest (greedy by distance)."""
    roots = list(roots)
    out = np.empty(len(nominal), dtype=complex)
    for i, s0 in enumerate(nominal):
        if not roots:
            out[i:] = np.nan
            break
        j = int(np.argmin([abs(s - s0) for s in roots]))
        out[i] = roots.pop(j)
    return out


def _roots(coeffs: np.ndarray) -> np.ndarray:
    coeffs = np.asarray(coeffs, dtype=float)
    nz = np.flatnonzero(coeffs != 0.0)
    return np.roots(coeffs[nz[0]:]) if nz.size else np.empty(0, dtype=complex)


def _sorted_roots(coeffs: np.ndarray) -> np.ndarray:
    """Roots in the order of :meth:`DriveModel.poles` (decreasing |s|)."""
    r = _roots(coeffs)
    return r[np.argsort(-np.abs(r), kind="stable")]


def _freq_damp(s: np.ndarray) -> np.ndarray:
    mag = np.abs(s)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.concatenate([mag / _TWO_PI, np.where(mag > 0, -s.real / mag, 1.0)])


def _search_from_roots(poles: np.ndarray, pair: tuple[int, int], real: int) -> np.ndarray:
    """(ω_n Hz, ζ, p Hz) of eq. 3.7 with the estimate's choice of which poles form the pair."""
    s1, s2 = poles[pair[0]], poles[pair[1]]
    wn = math.sqrt(max((s1 * s2).real, 0.0))
    zeta = -(s1 + s2).real / (2.0 * wn) if wn > 0 else math.nan
    return np.array([wn / _TWO_PI, zeta, -poles[real].real / _TWO_PI])


def _near_pairs(roots: np.ndarray, rel: float = 0.1) -> list[tuple[int, int]]:
    """Index pairs of roots closer than ``rel`` of their size (near-double roots)."""
    out: list[tuple[int, int]] = []
    used: set[int] = set()
    for i in range(roots.size):
        for j in range(i + 1, roots.size):
            if i in used or j in used:
                continue
            if abs(roots[i] - roots[j]) < rel * max(abs(roots[i]), 1e-300):
                out.append((i, j))
                used |= {i, j}
    return out


def _pair_wz(s1: complex, s2: complex) -> tuple[float, float]:
    """(ω_n Hz, ζ) of the quadratic with roots s1, s2: smooth in its coefficients."""
    prod, tot = (s1 * s2).real, (s1 + s2).real
    if prod <= 0.0:
        return math.nan, math.nan
    wn = math.sqrt(prod)
    return wn / _TWO_PI, -tot / (2.0 * wn)


def _pairing(poles: np.ndarray, wn: float, zeta: float, p: float) -> tuple[tuple[int, int], int]:
    """Which of the sorted poles are the pair (ω_n, ζ) and which the real pole p."""
    if not poles.size == 3:
        return (0, 1), 2
    real = int(np.argmin(np.abs(poles + p)))
    rest = tuple(i for i in range(3) if i != real)
    return (rest[0], rest[1]), real


def _gradient(fun: Callable[[np.ndarray], np.ndarray], v: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Central-difference Jacobian of a vector function of the 8 parameters."""
    cols = []
    for j in range(v.size):
        vp, vm = v.copy(), v.copy()
        vp[j] += h[j]
        vm[j] -= h[j]
        cols.append((fun(vp) - fun(vm)) / (2.0 * h[j]))
    return np.column_stack(cols)


def _project(cov: np.ndarray, grads: list[np.ndarray]) -> np.ndarray:
    """Covariance of the estimator with the constraints c_iᵀ δa = 0 imposed (active bounds)."""
    if not grads:
        return cov
    C = np.array(grads)
    M = C @ cov @ C.T
    K = cov @ C.T @ np.linalg.pinv(M)
    out = cov - K @ C @ cov
    return 0.5 * (out + out.T)


def _weak_text(comp: dict[str, float], scale: dict[str, float]) -> str:
    """Words for a weak direction: what moves, and (for two parameters) what is determined.

    Along δa = (c1 s1, c2 s2) the combination a1 − k a2 with k = c1 s1 / (c2 s2) stays put.
    """
    names = list(comp)
    if len(names) == 1:
        return f"{names[0]} is not determined by this recording"
    if len(names) == 2:
        (n1, c1), (n2, c2) = comp.items()
        k = c1 * scale[n1] / (c2 * scale[n2])
        return (f"{n1} and {n2} move together ({c1:+.2f}, {c2:+.2f} of their size) without changing the fit: "
                f"only {n1} {'−' if k > 0 else '+'} {abs(k):.3g}·{n2} is determined")
    moves = ", ".join(f"{k} {c:+.2f}" for k, c in comp.items())
    return (f"{', '.join(names[:-1])} and {names[-1]} move together ({moves} of their size) without changing "
            f"the fit: only combinations across that direction are determined")


# --------------------------------------------------------------------------------------
# the estimator
# --------------------------------------------------------------------------------------
def estimate_uncertainty(model: DriveModel, J: np.ndarray, r: np.ndarray, *, bounds: Bounds | None = None,
                         sample_period: float | None = None, segment: np.ndarray | None = None,
                         J_start: np.ndarray | None = None, level: float = 0.95) -> Uncertainty:
    """Confidence intervals of ``model`` from its output-error Jacobian and residual.

    Parameters
    ----------
    model : DriveModel
        The estimate (a stationary point of ½‖r‖², or a bounded one).
    J : ndarray (N, 8)
        ∂x̂/∂(a1 … d1), mm per parameter unit (:func:`output_error_jacobian`).
    r : ndarray (N,)
        Residual x̂ − x at the estimate, mm.
    bounds : Bounds, optional
        Constraints of eq. 3.8; active ones mark ``at_bound`` and project the covariance.
    sample_period : float, optional
        T_s in s (Nyquist for ``bounds.f_max_hz = None``).
    segment : ndarray of int (N,), optional
        Segment ids of the rows (blocks do not span a seam).
    J_start : ndarray (N, n_segments), optional
        ∂x̂/∂x̂_0: how the free run responds to the start position of each segment.  The
        simulation starts from the *recorded* position, whose noise then runs through the
        whole start transient; that error is added to the covariance as a term
        (JᵀJ)⁻¹ Jᵀ J_start σ² J_startᵀ J (JᵀJ)⁻¹, σ² the residual's variance.
    level : float
        Confidence level (0.95).

    Returns
    -------
    Uncertainty
    """
    J = np.asarray(J, dtype=float)
    r = np.asarray(r, dtype=float)
    if J.ndim != 2 or J.shape != (r.size, 8):
        raise ValueError(f"J must have shape ({r.size}, 8) to match r, got {J.shape}")
    v = np.array([getattr(model, k) for k in PARAMETER_NAMES], dtype=float)
    scale = _scales(v)
    cov_s, L, B, tau = _sandwich(J * scale, r, segment)
    if J_start is not None:  # noise of the recorded start positions (see J_start)
        Js = J * scale
        K = np.linalg.pinv(Js.T @ Js, rcond=1e-14, hermitian=True) @ (Js.T @ np.asarray(J_start, dtype=float))
        cov_s = cov_s + float(np.mean(r * r)) * (K @ K.T)
    cov = cov_s * np.outer(scale, scale)
    tq = float(stdtrit(max(B - 8, 1), 0.5 + level / 2.0))
    h = 1e-6 * scale

    # search variables and their active bounds
    bounds_hz = bounds.with_sample_period(sample_period) if (bounds is not None and sample_period) else bounds
    wn, zeta, p = model.search_variables(bounds_hz, sample_period) if bounds_hz is not None else \
        model.search_variables()
    active = bounds_hz.active(wn, zeta, p, sample_period, rtol=1e-6) if bounds_hz is not None else ()
    pole0 = _sorted_roots(model.denominator)
    pair, real = _pairing(pole0, wn, zeta, p)

    # p one of two near-equal real poles, the other in the pair: which is which is not
    # resolved (nor smooth): both are taken at their geometric mean, and the interval widened
    # by the difference (below)
    straddle = [pr for pr in _near_pairs(pole0) if real in pr and pole0.size == 3]

    def search_of(a: np.ndarray) -> np.ndarray:
        poles = _match(_sorted_roots(np.array([1.0, a[0], a[1], a[2]])), pole0)
        if poles.size != 3:
            return np.full(3, np.nan)
        for i, j in straddle:
            w, _ = _pair_wz(poles[i], poles[j])
            poles[i] = poles[j] = -_TWO_PI * w
        return _search_from_roots(poles, pair, real)

    Gs = _gradient(search_of, v, h) if pole0.size == 3 else np.full((3, 8), np.nan)
    holds: dict[str, str] = {}
    grads = []
    for name in active:
        which = {"p_min": "p_hz", "wn_min": "wn_hz", "zeta_min": "zeta", "zeta_max": "zeta"}.get(name)
        if name == "f_max":
            fmax = bounds_hz.f_max(sample_period)
            which = "p_hz" if abs(p - fmax) <= 1e-6 * fmax else "wn_hz"
        idx = SEARCH_NAMES.index(which)
        holds[which] = name
        if np.all(np.isfinite(Gs[idx])):
            grads.append(Gs[idx])
    cov = _project(cov, grads)

    def interval(value: float, g: np.ndarray | None, var: float | None = None, bound: str | None = None,
                 size: float | None = None, extra: float = 0.0) -> Interval:
        if bound is not None:
            return Interval(value, value, value, 0.0, False, bound)
        var = float(g @ cov @ g) if var is None else var
        se = math.sqrt(max(var, 0.0)) if math.isfinite(var) else math.inf
        hw = tq * se + extra
        wide = not hw < abs(value)
        small = size is not None and hw < 0.1 * size
        return Interval(value, value - hw, value + hw, se, bool(wide and not small), None, bool(wide and small))

    params = {k: interval(float(v[i]), None, cov[i, i], size=float(scale[i])) for i, k in enumerate(PARAMETER_NAMES)}
    sv = np.array([wn / _TWO_PI, zeta, p / _TWO_PI])
    # the constraint region of eq. 3.8: no interval reaches past a bound
    box_lo, box_hi = np.full(3, -np.inf), np.full(3, np.inf)
    if bounds_hz is not None and bounds_hz.f_max_hz is not None:
        lo_, hi_ = bounds_hz.box()
        box_lo, box_hi = lo_ / [_TWO_PI, 1.0, _TWO_PI], hi_ / [_TWO_PI, 1.0, _TWO_PI]
    smooth = search_of(v) if pole0.size == 3 else sv
    for i, k in enumerate(SEARCH_NAMES):
        iv = interval(float(sv[i]), Gs[i], bound=holds.get(k), extra=abs(float(sv[i] - smooth[i])))
        params[k] = replace(iv, lo=max(iv.lo, box_lo[i]), hi=min(iv.hi, box_hi[i]))
    f_top = float(box_hi[0]) if math.isfinite(box_hi[0]) else math.inf

    # poles and zeros: frequency and damping by the delta method
    def roots_block(coeff_of, nominal, at_bound_of) -> list[RootInterval]:
        if nominal.size == 0:
            return []
        fd0 = _freq_damp(nominal)
        n = nominal.size
        # Near a double root each root moves as the square root of a coefficient change and
        # the delta method fails; such two roots are resolved as a pair: (ω_n, ζ) from their
        # product and sum, which are smooth (see _near_pairs).
        pairs = _near_pairs(nominal)

        def fd(a: np.ndarray) -> np.ndarray:
            roots = _match(_sorted_roots(coeff_of(a)), nominal)
            out = _freq_damp(roots)
            for i, j in pairs:
                out[i], out[n + i] = _pair_wz(roots[i], roots[j])
                out[j], out[n + j] = out[i], out[n + i]
            return out

        G = _gradient(fd, v, h)
        var = np.einsum("ij,jk,ik->i", G, cov, G)
        centre = fd(v)
        out = []
        for i in range(n):
            f, d = fd0[i], fd0[n + i]
            se_f, se_d = (math.sqrt(max(x, 0.0)) if math.isfinite(x) else math.inf for x in (var[i], var[n + i]))
            if any(i in pr for pr in pairs):  # the pair's ω_n and ζ ranges, around this root
                se_f += abs(f - centre[i]) / tq
                se_d += abs(d - min(centre[n + i], 1.0)) / tq
            bound = at_bound_of(i)
            fi = (max(f - tq * se_f, 0.0), f + tq * se_f)
            di = (max(d - tq * se_d, -1.0), min(d + tq * se_d, 1.0))
            out.append(RootInterval(float(f), float(d), fi, di, bool(not tq * se_f < f) and bound is None, bound))
        return out

    def pole_bound(i: int) -> str | None:
        if pole0.size != 3:
            return None
        if i == real:
            return holds.get("p_hz")
        return holds.get("wn_hz") or holds.get("zeta")

    poles = [replace(pi, freq_hz_interval95=(pi.freq_hz_interval95[0], min(pi.freq_hz_interval95[1], f_top)))
             for pi in roots_block(lambda a: np.array([1.0, a[0], a[1], a[2]]), pole0, pole_bound)]
    zero0 = _sorted_roots(model.numerator)
    zeros = roots_block(lambda a: np.array([a[3], a[4], a[5], a[2]]), zero0, lambda i: None)

    # weak directions of the relative covariance
    rel = cov / np.outer(scale, scale)
    w, V = np.linalg.eigh(rel)
    weak = []
    for k in np.argsort(-w):
        hw = tq * math.sqrt(max(w[k], 0.0))
        if not hw > 1.0:
            break
        vec = V[:, k] * np.sign(V[np.argmax(np.abs(V[:, k])), k])
        comp = {PARAMETER_NAMES[i]: float(vec[i]) for i in np.argsort(-np.abs(vec)) if abs(vec[i]) > 0.25}
        weak.append(WeakDirection(comp, hw, _weak_text(comp, dict(zip(PARAMETER_NAMES, scale)))))

    why = _equivalence_reasons(model, params, poles, zeros, pole0, zero0, weak, f_top)
    return Uncertainty(parameters=params, poles=poles, zeros=zeros, weak_directions=weak, covariance=cov,
                       n_samples=int(r.size), block_length=int(L), n_blocks=int(B),
                       effective_samples=float(r.size / tau), residual_rms_mm=float(np.sqrt(np.mean(r * r))),
                       is_equivalent=bool(why), why=why)


def _equivalence_reasons(model: DriveModel, params: dict[str, Interval], poles: list[RootInterval],
                         zeros: list[RootInterval], pole0: np.ndarray, zero0: np.ndarray,
                         weak: list[WeakDirection], f_max_hz: float) -> list[str]:
    why = []
    for k, iv in params.items():
        if iv.at_bound and k in SEARCH_NAMES:
            unit = "" if k == "zeta" else " Hz"
            why.append(f"{k} = {iv.value:.4g}{unit} sits on the bound {iv.at_bound}: the constraint, not the data, "
                       f"places it")
    und = [k for k in PARAMETER_NAMES if params[k].undetermined]
    if und:
        why.append("the data do not determine " + ", ".join(und) + " (interval wider than the value)")
    for wd in weak:
        if len(wd.components) > 1:
            why.append(wd.text)
    if model.d0 < 0 or model.d1 > 0:
        why.append(f"the friction terms push the axis along its motion (d0 = {model.d0:.4g}, d1 = {model.d1:.4g} "
                   "mm/s²; physical Coulomb friction has d0 ≥ 0 ≥ d1): they absorb something other than friction")
    rhp = [z for z in zeros if z.damping_interval95[1] < 0 and z.freq_hz_interval95[1] < f_max_hz]
    if rhp:
        where = "; ".join(dict.fromkeys(f"{z.freq_hz:.4g} Hz, ζ {z.damping:.2f}" for z in rhp))
        why.append(f"zeros in the right half-plane ({where}), below the frequency bound: with usual gains the "
                   "drives of eq. 3.4/3.5 have their zeros in the left half-plane; the model makes a delay "
                   "(sampled control, DAC, the preview shift) with them")
    for i, sp in enumerate(pole0):
        for sz in zero0:
            if abs(sp - sz) < _CANCEL_REL * abs(sp) and poles[i].undetermined:
                why.append(f"the pole at {abs(sp) / _TWO_PI:.3g} Hz nearly cancels the zero at {abs(sz) / _TWO_PI:.3g} Hz "
                           "and is not determined: it barely shows in the tracking response")
                break
    return why


def stationary_point(simulate: Callable[[DriveModel], np.ndarray], model: DriveModel, x: np.ndarray, *,
                     bounds: Bounds | None = None, sample_period: float | None = None, max_steps: int = 3,
                     ) -> tuple[DriveModel, np.ndarray, np.ndarray]:
    """Gauss–Newton steps on every sample until the output-error cost stops falling.

    The covariance of :func:`estimate_uncertainty` holds at a stationary point of ½‖r‖² on
    the data it is computed from.  The refinement (:mod:`ident.refine`) searches on every
    k-th residual with a coarser friction simulator and stops at a relative decrease of
    1e-6, which can leave the estimate a standard error or so from that point; these
    steps (:func:`ident.gauss_newton.to_stationary_point`: each halved until the cost falls
    and the poles stay inside ``bounds``) close the gap.  Returns the model with its
    Jacobian and residual.
    """
    x = np.asarray(x, dtype=float)

    def jacobian(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return output_error_jacobian(simulate, DriveModel(*v), x)

    def residual(v: np.ndarray) -> np.ndarray | None:
        cand = DriveModel(*v)
        if bounds is not None and bounds.check(cand, sample_period):
            return None  # a pole outside the bounds
        return simulate(cand) - x

    v0 = np.array([getattr(model, k) for k in PARAMETER_NAMES], dtype=float)
    v, J, r = to_stationary_point(v0, jacobian, residual, scale=_scales, max_steps=max_steps, rel_decrease=1e-9)
    return (model if v is v0 else DriveModel(*v)), J, r  # v0 itself: no step was taken

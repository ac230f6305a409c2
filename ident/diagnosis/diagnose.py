"""Mismatch diagnosis: compare, locate, explain, model, and say it in words (issue 5).

:func:`diagnose` takes a recording of one axis and the drive model identified from it
(thesis eq. 3.3) and

1. **compares** them in free run (SPEC §5): residual ``r = e − ê``; against a simulated
   recording of the same program when ``against`` is given;
2. **locates** where ``r`` concentrates (:func:`ident.diagnosis.residuals.localise`);
3. **explains and models**: for each effect of SPEC §7 (an object of
   :mod:`ident.diagnosis.effects`) an augmented model fitted by the one output-error search
   of :mod:`ident.diagnosis.candidates`, started where that evidence points, on top of the
   base — eq. 3.3 with a continuous or a sampled control law, the sampled one's
   feed-forward reading the command's derivatives ahead or causally, whichever fits best
   (starts on the next best too: an effect may have its valley there only);
   each is scored on held-out data — the validation recording when given, otherwise
   two-fold cross-validation over the halves of every segment — against the base model
   re-fitted by the same procedure, so re-fitting alone earns nothing;
4. **accepts** an effect by one statistical rule (:func:`evidence`): the held-out
   likelihood ratio under a slow and a fast (AR-whitened) noise model exceeds the χ²
   quantile of the parameters it adds (``config.alpha``), it removes at least
   ``config.min_relevant`` of the held-out residual and more than the measurement noise
   (:func:`_above_noise`), and its parameters are the physics its
   name means (:func:`_plausible`: definitions, no signature veto, no refusal of a
   parameter on its fit's bound — that one is told as not resolved); of those that pass, the
   one removing the largest share of the held-out residual wins; greedy forward selection
   then tries a second one on top by the same rule; the accepted model's parameters are
   then estimated by maximum likelihood with a noise variance of each segment's own
   (:func:`~ident.diagnosis.candidates.segment_variance_fit`): a segment the model cannot
   follow in phase no longer pulls them, and every accepted parameter gets a 95 %
   confidence interval (:mod:`ident.diagnosis.intervals`) or a "not resolved" mark;
5. **describes** the equivalent input disturbance (:mod:`ident.diagnosis.disturbance`) on
   the identification and validation recordings, and names an ``external_force`` when it
   comes in time blocks the motion does not explain;
6. **tells** the user: ``Diagnosis.summary``, with where the model fails on held-out data.
"""

from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any, Callable

import numpy as np
from scipy.signal import lfilter
from threadpoolctl import threadpool_limits

from core.effects import EFFECTS as REGISTRY
from core.effects import parameter_units
from core.errors import InputError
from ident.diagnosis.augmented import CONTROLLERS, EFFECTS, MODE_SLOTS, segment_starts
from ident.diagnosis.candidates import (base_variants, fit_spec, refit_base, search, segment_variance_fit,
                                        softened_base)
from ident.diagnosis.config import DEFAULT, DiagnosisConfig
from ident.diagnosis.effects import EFFECT_MODELS, TimeDelay, effect_parameters
from ident.diagnosis.intervals import at_bound, effect_intervals
from ident.diagnosis.spec import Chunk, ModelSpec, make_chunk, residual, rest_residual, simulate_spec, sse
from ident.diagnosis.disturbance import analyse_disturbance, block_input, equivalent_disturbance
from ident.diagnosis.residuals import localise
from ident.axis_model import AxisModel
from ident.fixed_order import dot, lstsq, matvec, norm, sum_squares
from ident.model import BASE_KEYS, base_vector

__all__ = ["Candidate", "Diagnosis", "diagnose"]


@dataclass(frozen=True)
class Candidate:
    """One effect tried: its fitted parameters and held-out fit without/with it.

    fit_before_pct / fit_after_pct : held-out tracking-error fit % (SPEC §5) of the model
    it was added to and of the augmented model; score : the evidence (signature) and the
    acceptance figures; intervals : 95 % confidence interval [lo, hi] per parameter of an
    accepted effect (of the final model, :mod:`ident.diagnosis.intervals`); unresolved :
    parameter → why the data do not resolve it (on its fit's bound, an interval including 0).
    """

    effect: str
    parameters: dict
    fit_before_pct: float
    fit_after_pct: float
    accepted: bool
    score: dict
    intervals: dict = field(default_factory=dict)
    unresolved: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {
            "effect": self.effect,
            "parameters": _jsonable(self.parameters),
            # the unit of each number above, from the effect registry (core.effects)
            "parameter_units": parameter_units(self.effect, self.parameters) if self.effect in REGISTRY else {},
            "parameters_interval95": _jsonable(self.intervals),
            "unresolved": dict(self.unresolved),
            "fit_before_pct": float(self.fit_before_pct),
            "fit_after_pct": float(self.fit_after_pct),
            "accepted": bool(self.accepted),
            "score": _jsonable(self.score),
        }


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose` (SPEC §6 "diagnosis").

    verdict : an effect of SPEC §7, "none", or a list of effects when several matter.
    mismatch : where the residual concentrates (JSON-ready).
    candidates : every effect tried, in the order tried.
    summary : the words for the user.
    fit_before_pct, fit_after_pct : held-out tracking-error fit % of the base model and of
    the model with the accepted effects.
    elapsed_s : wall time of the diagnosis, s.
    augmented_model : base parameters and the parameters of the accepted effects (and of
    those the given model carried), fitted on all the identification data.
    traces : arrays for before/after overlays (not in ``to_dict``): ``t`` (s), ``x_r``,
    ``x``, ``x_hat_before``, ``x_hat_after`` (mm), and the same with a ``validation_``
    prefix when a validation recording was given.
    """

    verdict: str | list[str]
    mismatch: dict
    candidates: list[Candidate]
    summary: str
    fit_before_pct: float
    fit_after_pct: float
    elapsed_s: float
    augmented_model: dict = field(default_factory=dict)
    traces: dict = field(default_factory=dict, repr=False, compare=False)
    #: the same localisation on the validation recording, when one was given
    mismatch_validation: dict | None = None
    #: the equivalent input disturbance, analysed (ident.diagnosis.disturbance); a
    #: ``validation`` key holds the same for the validation recording
    disturbance: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {
            "verdict": self.verdict,
            "mismatch": _jsonable(self.mismatch),
            "mismatch_validation": _jsonable(self.mismatch_validation) if self.mismatch_validation else None,
            "disturbance": _jsonable(self.disturbance),
            "candidates": [c.to_dict() for c in self.candidates],
            "summary": self.summary,
            "fit_before_pct": float(self.fit_before_pct),
            "fit_after_pct": float(self.fit_after_pct),
            "augmented_model": _jsonable(self.augmented_model),
            "elapsed_s": float(self.elapsed_s),
        }


def _jsonable(obj: Any) -> Any:
    """Drop array-valued keys ending in ``_`` and turn numpy scalars into Python ones."""
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items() if not (isinstance(k, str) and k.endswith("_"))
                and not isinstance(v, np.ndarray)}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def _theta(model: Any) -> np.ndarray:
    try:
        th = base_vector(model)
    except TypeError as exc:
        raise InputError(str(exc)) from exc
    if not np.all(np.isfinite(th)):
        raise InputError(f"model parameters must be finite, got {th.tolist()}")
    return th


def _given(model: Any) -> ModelSpec:
    """The model the diagnosis starts from: eq. 3.3, with the effects and control law an
    :class:`AxisModel` carries (a saved virtual machine's, ``agent identify --model``): those
    are part of every reference, not candidates — the diagnosis looks for what it lacks."""
    if not isinstance(model, AxisModel):
        return ModelSpec(_theta(model))
    _, _, ep, modes = model.spec_arrays()
    return ModelSpec(_theta(model.model), tuple(e for e in EFFECTS if e in model.effects), ep, modes)


def _check(name: str, x_r: np.ndarray, x: np.ndarray, segment: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    x_r = np.asarray(x_r, dtype=float).ravel()
    x = np.asarray(x, dtype=float).ravel()
    if x_r.shape != x.shape:
        raise InputError(f"{name}: commanded has {x_r.size} samples but actual has {x.size}")
    if x_r.size < 200:
        raise InputError(f"{name}: {x_r.size} samples are too few to diagnose (need at least 200)")
    if not (np.all(np.isfinite(x_r)) and np.all(np.isfinite(x))):
        raise InputError(f"{name}: commanded or actual position contains NaN or inf")
    if segment is not None and np.asarray(segment).shape != x_r.shape:
        raise InputError(f"{name}: segment has {np.asarray(segment).size} entries, expected {x_r.size}")
    if np.ptp(x_r) == 0.0:
        raise InputError(f"{name}: the commanded position never moves")
    return x_r, x


def _fit_pct(e: np.ndarray, r: np.ndarray) -> float:
    den = norm(e - e.mean())
    return 100.0 * (1.0 - norm(r) / den) if den > 0 else float("nan")


def _fold_masks(starts: np.ndarray, blocks: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Two interleaved folds: alternate blocks of every segment (each fold sees both sets)."""
    n = starts.size
    bounds = np.append(np.flatnonzero(starts), n)
    first = np.zeros(n, dtype=bool)
    for s, e in zip(bounds[:-1], bounds[1:]):
        edges = np.linspace(s, e, blocks + 1).astype(int)
        for i in range(0, blocks, 2):
            first[edges[i] : edges[i + 1]] = True
    return first, ~first


@dataclass
class _Scored:
    """Fold-fitted specs with their weighted (test_r) and raw (raw_r, mm) held-out residuals
    and their weighted training costs (train_sse, one per fold).  The held-out residuals are
    those the acceptance judges: the free run's, or with ``DiagnosisConfig.accept_on_windows``
    the held-out windows' (k-step-ahead), the free run's then kept in ``free_run``."""

    specs: list[ModelSpec]
    test_r: list[np.ndarray]
    raw_r: list[np.ndarray]
    train_sse: list[float]
    free_run: "_Scored | None" = None
    #: computes the same models on the held-out data restarted at rest
    #: (``DiagnosisConfig.accept_on_rests``, :func:`~ident.diagnosis.spec.rest_residual`)
    rest_reading: "Callable[[], _Scored] | None" = None

    @cached_property
    def at_rest(self) -> "_Scored | None":
        """The held-out data restarted at rest (when first asked for); None where no fold holds a dwell."""
        return self.rest_reading() if self.rest_reading is not None else None

    @property
    def free(self) -> "_Scored":
        """The same models scored by the free run of the held-out data."""
        return self if self.free_run is None else self.free_run

    @property
    def sse(self) -> float:
        v = float(sum(self.fold_sse()))
        return v if math.isfinite(v) else math.inf

    def fold_sse(self) -> list[float]:
        with np.errstate(all="ignore"):
            return [sum_squares(r) if np.all(np.isfinite(r)) else math.inf for r in self.test_r]

    @property
    def raw_sse(self) -> float:
        with np.errstate(all="ignore"):
            v = float(sum(sum_squares(r) for r in self.raw_r))
        return v if math.isfinite(v) else math.inf

    @property
    def raw_rms(self) -> float:
        """Held-out residual rms over every fold's test samples, mm."""
        n = sum(r.size for r in self.raw_r)
        return math.sqrt(self.raw_sse / n) if n else math.inf

    def raw_fold_sse(self) -> list[float]:
        with np.errstate(all="ignore"):
            return [sum_squares(r) if np.all(np.isfinite(r)) else math.inf for r in self.raw_r]


def _best_reference(scs: list["_Scored"], keep: tuple[str, ...], folds, pool: ThreadPoolExecutor, scored,
                    cfg: DiagnosisConfig, test_sse: Callable[[ModelSpec, int], float]) -> "_Scored":
    """The reference model (effects ``keep`` only) with the lowest training cost per fold.

    Candidates for the reference: the given one (``scs[0]``) and a re-fit of it started
    from every other scored spec's parameters with the extra effects removed.  A re-fit
    that wins on training cost but predicts a fold's held-out data worse than the given
    one is not taken for that fold (a reference that is poor on held-out data would credit
    any effect with the difference; ``test_sse(spec, fold)`` is the held-out cost the
    acceptance judges by).  The re-fits are jobs of ``pool``.
    """
    ref = scs[0]

    def refit(i: int, s0: ModelSpec):
        s0 = s0.copy()
        s0.effects = tuple(e for e in s0.effects if e in keep)
        return fit_spec(s0, folds[i][0], max_iter=cfg.reference_iter, cfg=cfg)

    jobs = [(i, pool.submit(refit, i, sc.specs[i])) for sc in scs[1:] for i in range(len(folds))]
    best = list(ref.specs)
    best_v = list(ref.train_sse)
    for i, job in jobs:
        s1 = job.result()
        v = sse(s1, folds[i][0])
        if v < best_v[i]:
            best[i], best_v[i] = s1, v
    # the given reference's held-out cost per fold, as the ceiling of a replacement
    given = ref.fold_sse()
    for i, s1 in enumerate(best):
        if s1 is not ref.specs[i] and not test_sse(s1, i) <= given[i]:
            best[i] = ref.specs[i]
    return ref if all(b is r for b, r in zip(best, ref.specs)) else scored(best)


def fit_base(spec: ModelSpec, chunk: Chunk, pool: ThreadPoolExecutor | None = None, *,
             cfg: DiagnosisConfig) -> ModelSpec:
    """The base model of eq. 3.3 re-fitted in free run on ``chunk``, from two starts.

    From the given parameters and from :func:`softened_base` (the two faster poles moved
    to 150/s·(1 ms/Ts)): the identified model often sits in a poorer valley of the free-run
    cost (e.g. an integrator nearly cancelled by a zero).  Each start is fitted twice (the
    restart re-scales the parameters after the first long move); the lower cost wins.
    The starts are fitted in ``pool``'s threads when given.
    """
    starts = [spec]
    soft = softened_base(spec, chunk.Ts, force=True)
    if soft is not None:
        starts.append(soft)

    def fit(s: ModelSpec) -> ModelSpec:
        return refit_base(s, chunk, cfg=cfg)

    fits = list(pool.map(fit, starts)) if pool is not None else [fit(s) for s in starts]
    return min(fits, key=lambda f: sse(f, chunk))


def noise_floor(x: np.ndarray, v_r: np.ndarray, Ts: float, settle_s: float = 0.1) -> float:
    """Measurement noise of the recorded position (mm rms) from samples long at rest.

    Second differences of x where the command has been still for ``settle_s`` (they
    cancel the slow settling motion): for white noise of rms σ they have rms σ·√6.
    0.0 when the recording never rests that long.
    """
    still = np.abs(v_r) < 1e-9
    k = max(int(round(settle_s / Ts)), 1)
    run = np.convolve(still.astype(float), np.ones(k), mode="full")[: still.size]
    rest = run >= k
    three = rest[2:] & rest[1:-1] & rest[:-2]
    d = np.diff(x, 2)[three]
    if d.size < 50:
        return 0.0
    return float(np.std(d) / math.sqrt(6.0))


def _above_noise(sc: "_Scored", ref: "_Scored", noise: float, cfg: DiagnosisConfig) -> tuple[bool, str]:
    """Does the augmented model explain more of the held-out residual than the measurement noise?

    What it explains is √(rms_ref² − rms²) of the held-out residual (mm): the size of the
    systematic error it removes.  Below ``cfg.noise_factor`` × the noise rms (SPEC §7
    "none": the residual is consistent with noise and quantization) the effect changes the
    prediction by less than the sensor scatters.  Returns (passes, why not).
    """
    explained = math.sqrt(max(ref.raw_rms ** 2 - sc.raw_rms ** 2, 0.0))
    if explained > cfg.noise_factor * noise:
        return True, ""
    return False, (f"it explains {1e3 * explained:.3f} µm rms of the held-out residual, within the "
                   f"measurement noise ({1e3 * noise:.3f} µm)")


def _gain(sc: _Scored, ref: _Scored) -> tuple[float, bool, float]:
    """Share of the held-out residual norm an augmented model removes.

    Returns (gain, every fold improved, gain in mm).  The gain in mm is on the residual
    itself (the SPEC §5 metric, dominated by the high-speed set); the weighted gain uses the
    per-segment weights of the fit (so the low-speed set, where friction and backlash
    show, counts as much).  An effect is credited with the larger of the two — every fold
    must improve on the metric that credits it — but never when the fit in mm gets worse.
    """
    def one(a: float, b: float) -> float:
        return 1.0 - math.sqrt(a / b) if b > 0 and math.isfinite(a) else -math.inf

    g_raw = one(sc.raw_sse, ref.raw_sse)
    g_w = one(sc.sse, ref.sse)
    folds_raw = all(x < y for x, y in zip(sc.raw_fold_sse(), ref.raw_fold_sse()))
    folds_w = all(x < y for x, y in zip(sc.fold_sse(), ref.fold_sse()))
    if g_w > g_raw and g_raw > 0.0:
        return g_w, folds_w, g_raw
    return g_raw, folds_raw, g_raw


def _lag_products(r: np.ndarray) -> np.ndarray:
    """``Σ_t r̃(t)·r̃(t+k)`` for lags k = 0 … N−1 of ``r̃ = r − mean(r)`` (by FFT, zero-padded
    to at least 2N so no lag wraps around — to a length of small prime factors: 2N itself
    can be 2·2·41·277, 1.6 times slower): N times the biased autocovariance."""
    from scipy.fft import next_fast_len

    r = np.asarray(r, dtype=float) - float(np.mean(r))
    m = next_fast_len(2 * r.size, real=True)
    f = np.fft.rfft(r, m)
    return np.fft.irfft(f * np.conj(f), m)[: r.size]


def correlation_time(r: np.ndarray) -> float:
    """Integrated autocorrelation time of ``r``, samples (Geyer's initial positive sequence).

    τ = −1 + 2·Σ_m (ρ(2m) + ρ(2m+1)), summed while the pair sums stay positive; a white
    residual has τ = 1, a residual that is a slow wave has τ of the order of its period.
    """
    n = np.size(r)
    if n < 4:
        return 1.0
    acf = _lag_products(r)
    if acf[0] <= 0.0:  # r constant
        return 1.0
    acf = acf / acf[0]
    tau = -1.0
    for m in range(0, n // 2 - 1):
        pair = acf[2 * m] + acf[2 * m + 1]
        if pair <= 0:
            break
        tau += 2.0 * pair
    return float(min(max(tau, 1.0), n / 4.0))


def ar_whitener(r: np.ndarray, max_order: int) -> np.ndarray:
    """Prediction-error filter ``A(q) = 1 + a1 q⁻¹ + … + ap q⁻ᵖ`` of an AR(p) model of ``r``.

    Yule–Walker equations solved by Levinson recursion (``scipy.linalg.solve_toeplitz``),
    the order p ≤ ``max_order`` the one of least BIC ``N·ln σ²_p + p·ln N``.  ``A(q) r`` is
    then close to white: the coloured residual's likelihood under that noise model.
    """
    from scipy.linalg import solve_toeplitz

    n = np.size(r)
    if n < 4 * max_order:
        return np.ones(1)
    acf = _lag_products(r)[: max_order + 1] / n
    if acf[0] <= 0.0:  # r constant
        return np.ones(1)
    best, best_bic = np.ones(1), n * math.log(max(acf[0], 1e-300))
    for p in range(1, max_order + 1):
        try:
            phi = solve_toeplitz(acf[:p], acf[1 : p + 1])
        except np.linalg.LinAlgError:
            break
        s2 = float(acf[0] - dot(phi, acf[1 : p + 1]))
        if s2 <= 0:
            break
        bic = n * math.log(s2) + p * math.log(n)
        if bic < best_bic:
            best, best_bic = np.concatenate(([1.0], -phi)), bic
    return best


def _minus_log10_sf(x: float, k: int) -> float:
    """−log10 of the χ²(k) survival function at ``x``, finite where the p-value underflows.

    Past ~1400 (k = 2) ``chi2.logsf`` returns −inf and strong effects would tie; there the
    leading terms of the incomplete gamma function's asymptotic series,
    ``ln Q(a, y) ≈ (a−1)·ln y − y − ln Γ(a) + ln(1 + (a−1)/y)`` with a = k/2, y = x/2, take over.
    """
    from scipy.special import gammaln
    from scipy.stats import chi2

    ls = float(chi2.logsf(x, k))
    if not math.isfinite(ls):
        a, y = 0.5 * k, 0.5 * x
        ls = (a - 1.0) * math.log(y) - y - float(gammaln(a)) + math.log1p((a - 1.0) / y)
    return -ls / math.log(10.0)


def evidence(sc: "_Scored", ref: "_Scored", k: int, cfg: DiagnosisConfig) -> dict:
    """The acceptance criterion: held-out likelihood ratio against its χ² threshold.

    For Gaussian white residuals the log-likelihood ratio of two models is
    ``n·ln(SSE_ref/SSE)``.  Tracking-error residuals are strongly coloured, and how much a
    held-out gain weighs depends on the noise model the residual is scored under; two
    are used, each fitted to the augmented model's residual r₁:

    * slow: the raw residuals, ``n = N/τ`` effective samples per fold, τ the correlation
      time of r₁ (:func:`correlation_time`) — a gain as slow as the residual (friction
      at low speed) is heard, a sharp one is under-counted;
    * fast: both residuals whitened by the prediction-error filter A(q) of an AR model of
      r₁ (:func:`ar_whitener`, order ≤ ``cfg.ar_order_max`` by BIC; 0 leaves it out), ``n``
      the samples whitened — each model's likelihood under AR noise, as the
      prediction-error method scores models (Ljung, *System Identification*, §7.3): a
      sharp gain (a gap's steps at reversals) is heard, a slow one is under-counted.

    Each is taken on the held-out residual in mm (the SPEC §5 metric) and on the weighted
    one (the low-speed set heard next to the high-speed set, as the fits weigh it).  The
    largest of these statistics is compared with the ``1 − alpha/m`` quantile of χ² with
    ``k`` degrees of freedom (``cfg.alpha``, m statistics: Bonferroni; k = parameters the
    effect adds), never credited when the residual in mm grows.

    The effect's model contains the reference (the effect switched off), so it must also
    fit the training data at least as well (``cfg.nested_training``): one that fits them
    worse sits in another valley of the base parameters, and its held-out gain compares two
    valleys, not the model with and without the effect.
    """
    from scipy.stats import chi2

    def one(new: list[np.ndarray], old: list[np.ndarray], whiten: bool) -> tuple[float, float]:
        lr, n_eff = 0.0, 0.0
        for r1, r0 in zip(new, old):
            if not (np.all(np.isfinite(r1)) and np.all(np.isfinite(r0))):
                return -math.inf, 0.0
            if whiten:
                a = ar_whitener(r1, cfg.ar_order_max)
                p = a.size - 1
                r1 = lfilter(a, [1.0], r1)[p:]
                r0 = lfilter(a, [1.0], r0)[p:]
                ne = float(r1.size)
            else:
                ne = r1.size / correlation_time(r1)
            s0, s1 = sum_squares(r0), sum_squares(r1)
            if s0 > 0 and s1 > 0:
                lr += ne * math.log(s0 / s1)
                n_eff += ne
        return lr, n_eff

    # the statistic under each noise model (slow: N/τ; fast: AR-whitened) on each residual
    # (mm, weighted): the largest counts, its level Bonferroni-divided among them
    noise_models = (False, True) if cfg.ar_order_max > 0 else (False,)
    stats = [(*one(new, old, wh), f"{'AR-whitened' if wh else 'N/τ samples'}, {what}")
             for wh in noise_models
             for new, old, what in ((sc.raw_r, ref.raw_r, "mm"), (sc.test_r, ref.test_r, "weighted"))]
    lr, n_eff, statistic = max(stats, key=lambda t: t[0])
    threshold = float(chi2.ppf(1.0 - cfg.alpha / len(stats), max(k, 1)))
    raw_ok = sc.raw_sse < ref.raw_sse
    nested = not cfg.nested_training or all(a <= b for a, b in zip(sc.train_sse, ref.train_sse))
    # the strength of the evidence, comparable between effects adding different numbers of
    # parameters: −log10 of the test's p-value (log form: a strong effect's p underflows)
    strength = _minus_log10_sf(lr, max(k, 1)) if math.isfinite(lr) else -math.inf
    return {"likelihood_ratio": float(lr), "statistic": statistic, "threshold": threshold,
            "effective_samples": float(n_eff),
            "minus_log10_p": strength, "significant": bool(lr > threshold and raw_ok and nested),
            "fits_training": bool(nested)}


def _readings(sc: "_Scored", ref: "_Scored", effect: str,
              cfg: DiagnosisConfig) -> list[tuple[str, "_Scored", "_Scored", DiagnosisConfig]]:
    """The readings of the held-out data the rule may judge ``effect`` by: (name, model,
    reference, config).

    The free run (or the windows of ``accept_on_windows``); for an effect of
    ``cfg.rest_effects``, with ``accept_on_rests`` and a dwell in the held-out data, also the
    run restarted at rest (:func:`~ident.diagnosis.spec.rest_residual`).  Two readings of
    the same data: each at half the level (Bonferroni), so the rule's family-wise error
    stays ``cfg.alpha``.  Only while every effect of both models reads at a rest: a restart
    at rest forgets what a rest does not show of the others (which side of a gap the motor
    rests on, a delay's history), and the effect judged would be credited with that misread
    of the reference.
    """
    present = {e for m in (sc, ref) for spec in m.specs for e in spec.effects}
    if (effect not in cfg.rest_effects or not present <= set(cfg.rest_effects)
            or sc.at_rest is None or ref.at_rest is None):
        return [("free run", sc, ref, cfg)]
    half = replace(cfg, alpha=cfg.alpha / 2.0)
    return [("free run", sc, ref, half), ("restarted at rest", sc.at_rest, ref.at_rest, half)]


def _passes(sc: "_Scored", ref: "_Scored", effect: str, cfg: DiagnosisConfig
            ) -> tuple[bool, float, bool, dict, "_Scored", "_Scored"]:
    """The held-out part of the rule on the first reading (:func:`_readings`) it holds on,
    else on the free run: (passes, gain, improves every fold, evidence, model and reference
    as read there).  Evidence significant and ``cfg.min_relevant`` of the residual removed;
    the evidence names the reading (``held_out_judged_on``) with the others' figures beside it."""
    told = []
    for name, a, b, c in _readings(sc, ref, effect, cfg):
        gain, folds_ok, _gw = _gain(a, b)
        ev = evidence(a, b, EFFECT_MODELS[effect].added, c)
        told.append((name, gain, folds_ok, ev, a, b))
    name, gain, folds_ok, ev, a, b = next((t for t in told if t[3]["significant"] and t[1] >= cfg.min_relevant),
                                         told[0])
    if len(told) > 1:
        other = [t for t in told if t[0] != name][0]
        key = "held_out_rests" if other[0] == "restarted at rest" else "held_out_free_run"
        ev = {**ev, "held_out_judged_on": name,
              "held_out_rms_before_mm": b.raw_rms, "held_out_rms_after_mm": a.raw_rms,
              f"{key}_residual_reduction": other[1], f"{key}_likelihood_ratio": other[3]["likelihood_ratio"],
              f"{key}_significant": other[3]["significant"],
              f"{key}_rms_before_mm": other[5].raw_rms, f"{key}_rms_after_mm": other[4].raw_rms}
    return bool(ev["significant"] and gain >= cfg.min_relevant), gain, folds_ok, ev, a, b


def _earns(sc: "_Scored", ref: "_Scored", effect: str, cfg: DiagnosisConfig) -> bool:
    """Does ``effect`` in ``sc`` pass the acceptance rule against ``ref`` on held-out evidence
    alone (:func:`_passes`: evidence significant and ``cfg.min_relevant`` of the residual
    removed, on the free run or restarted at rest)?"""
    return _passes(sc, ref, effect, cfg)[0]


def _judge(eff: str, sc: "_Scored", ref: "_Scored", chunk: Chunk, noise: float,
           cfg: DiagnosisConfig) -> tuple[bool, float, bool, dict, str]:
    """Step 4's rule for ``eff`` in ``sc`` against ``ref``, the same for a first and a second effect.

    Accepted when :func:`evidence` is significant, at least ``cfg.min_relevant`` of the
    held-out residual is removed (:func:`_gain`), the fit is the physics its name means
    (:func:`_plausible`) and it explains more than the noise (:func:`_above_noise`).
    Returns (accepted, gain, improves every fold, evidence, why not plausible).
    """
    ok, gain, folds_ok, ev, a, b = _passes(sc, ref, eff, cfg)
    plaus, why = _plausible(eff, sc, chunk, cfg)
    if plaus:
        plaus, why = _above_noise(a, b, noise, cfg)
    return bool(ok and plaus), gain, folds_ok, ev, why


def _plausible(eff: str, sc: "_Scored", chunk: Chunk, cfg: DiagnosisConfig) -> tuple[bool, str]:
    """Is the fitted effect, in every fold, the physics its name means (:meth:`Effect.implausible
    <ident.diagnosis.effects.Effect.implausible>`: part of its definition, not a signature test)?"""
    for spec in sc.specs:
        why = EFFECT_MODELS[eff].implausible(spec, chunk, cfg)
        if why:
            return False, why
    return True, ""


def _signatures(loc: dict) -> dict[str, dict]:
    """Per effect, the localisation figures that would betray it (SPEC §7 signatures)."""
    return {name: e.signature(loc) for name, e in EFFECT_MODELS.items()}


def _where_words(loc: dict) -> str:
    """One sentence: where the residual energy concentrates, and how it depends on speed."""
    options = []

    def add(share_key: str, time_key: str, words: str) -> None:
        s, t = loc.get(share_key, 0.0), loc.get(time_key, 0.0)
        if t > 0 and s > 0:
            options.append((s / t, s, words))

    add("after_reversal_30ms_share", "after_reversal_30ms_time_share", "within 30 ms after reversals")
    add("after_reversal_100ms_share", "after_reversal_100ms_time_share", "within 100 ms after reversals")
    add("after_jerk_30ms_share", "after_jerk_30ms_time_share", "within 30 ms after acceleration changes")
    add("low_speed_share", "low_speed_time_share", "at low speed (< 10 % of the maximum)")
    add("at_rest_share", "at_rest_time_share", "while the command is at rest")
    add("high_acceleration_share", "high_acceleration_time_share", "in the fastest accelerations")
    per = loc.get("position_periodic", {})
    peaks = loc.get("spectrum_peaks", [])
    parts = []
    meaningful = [o for o in options if o[1] >= 0.25 and o[0] >= 1.5]
    if meaningful:
        ratio, share, words = max(meaningful, key=lambda o: o[0] * o[1])
        parts.append(f"{100 * share:.0f} % of residual energy {words}")
    if per.get("explained_share", 0.0) >= 0.2:
        parts.append(f"{100 * per['explained_share']:.0f} % of it periodic in position (period {per['period_mm']:.3g} mm)")
    if peaks and peaks[0]["power_share"] >= 0.2 and peaks[0]["prominence"] >= 10:
        parts.append(f"spectrum peak at {peaks[0]['freq_hz']:.0f} Hz ({100 * peaks[0]['power_share']:.0f} % of residual power)")
    if not parts:
        worst = loc.get("worst_windows", [])
        parts.append("residual spread over the whole run" + (
            f" (worst 50 ms at t = {worst[0]['t_start_s']:.2f} s)" if worst else ""))
    ratio = loc.get("fast_to_slow_rms_ratio", 1.0)
    if ratio > 1.5:
        parts.append("growing with speed")
    elif ratio < 1 / 1.5:
        parts.append("larger at low speed")
    else:
        parts.append("independent of speed")
    return ", ".join(parts)


def _validation_where_words(loc: dict, dist: dict | None) -> str:
    """Where the model fails on the validation recording: in time blocks when the disturbance
    there is time-localised (a load the motion does not cause), else by operating condition."""
    tb = loc.get("time_blocks", {})
    if not (dist and dist.get("time_localised") and tb.get("count")):
        return _where_words(loc)
    when = ", ".join(f"{b['t_start_s']:.2f}–{b['t_end_s']:.2f} s" for b in tb["blocks"][:6])
    more = " …" if tb["count"] > 6 else ""
    return (f"{100 * tb['energy_share']:.0f} % of residual energy in {tb['count']} time "
            f"block{'s' if tb['count'] != 1 else ''} ({100 * tb['time_share']:.0f} % of the time: {when}{more})")


def _param_words(effect: str, p: dict, intervals: dict | None = None, unresolved: dict | None = None) -> str:
    return EFFECT_MODELS[effect].words(p, intervals, unresolved) if effect in EFFECT_MODELS else effect


def diagnose(
    x_r: np.ndarray,
    x: np.ndarray,
    Ts: float,
    model: Any,
    *,
    segment: np.ndarray | None = None,
    validation: tuple[np.ndarray, np.ndarray, np.ndarray | None] | None = None,
    against: np.ndarray | None = None,
    effects: tuple[str, ...] = EFFECTS,
    progress: Callable[[str], None] | None = None,
    config: DiagnosisConfig | None = None,
    reference: float = 0.0,
) -> Diagnosis:
    """Diagnose the mismatch between a recording of one axis and its drive model.

    Parameters
    ----------
    x_r, x : ndarray (N,)
        Commanded and recorded actual position, mm.
    Ts : float
        Sample period, s.
    model : DriveModel (or mapping) with a1, a2, a3, b0, b1, b2, d0, d1 of eq. 3.3, or an
        AxisModel: the effects it carries are then in the reference and not tried again.
    segment : ndarray of int (N,), optional
        Program/segment index per sample; the simulation restarts at each change.
    validation : (x_r2, x2, segment2), optional
        A second recording (mm) to score candidates on; otherwise two-fold
        cross-validation over the halves of every segment.
    against : ndarray (N,), optional
        Actual position (mm) of a simulated recording of the same program (the ``against`` recording):
        the mismatch is then localised on ``against − x``.
    effects : the effects of SPEC §7 to try (all by default).
    progress : called with a short description of each stage as it starts (for a
        progress line; the diagnosis takes seconds).
    config : the tunables (:class:`ident.diagnosis.config.DiagnosisConfig`); default ``DEFAULT``.
    reference : the position (mm) that was removed from every position given
        (:func:`ident.preprocessing.remove_reference`): a cyclic error's phase is told in
        absolute position, ``x + reference``.  Nothing else depends on it.

    Raises
    ------
    InputError
        Mismatched or too short arrays, NaN, a command that never moves, a bad model.
    """
    t0 = time.perf_counter()
    cfg = config or DEFAULT
    if not (isinstance(Ts, (int, float)) and math.isfinite(Ts) and Ts > 0):
        raise InputError(f"sample period must be a positive number of seconds, got {Ts!r}")
    x_r, x = _check("recording", x_r, x, segment)
    unknown = [e for e in effects if e not in EFFECTS]
    if unknown:
        raise InputError(f"unknown effect {unknown[0]!r}; known: {', '.join(EFFECTS)}")
    given = _given(model)
    effects = tuple(e for e in effects if e not in given.effects)
    starts = segment_starts(x_r.size, segment)
    full = make_chunk(x_r, x, Ts, starts)

    say = progress or (lambda _msg: None)
    # the fits of the search are independent of each other: two worker threads (the
    # simulation kernel releases the GIL) run them side by side
    pool = ThreadPoolExecutor(max_workers=2)
    # one BLAS thread: the few BLAS/LAPACK calls left (least-squares starts) then do their
    # sums in the same order whatever the machine's thread count (the search's own linear
    # algebra is in ident.fixed_order)
    try:
        with threadpool_limits(limits=1, user_api="blas"):
            return _absolute_phase(_diagnose(x_r, x, Ts, given, segment, starts, full, validation, against,
                                             effects, cfg, say, pool, t0), reference)
    finally:
        pool.shutdown()


def _diagnose(x_r: np.ndarray, x: np.ndarray, Ts: float, given: ModelSpec, segment, starts: np.ndarray,
              full: Chunk, validation, against, effects: tuple[str, ...], cfg: DiagnosisConfig,
              say: Callable[[str], None], pool: ThreadPoolExecutor, t0: float) -> Diagnosis:
    """Steps 1–6 of :func:`diagnose` on checked input, every independent fit a job of ``pool``;
    ``given`` the model to start from, its effects (``given.effects``) kept in every reference."""
    say("re-fitting the base model in free run")
    # 1. compare: the base model re-fitted in free run on all identification data
    # (twice: the restart re-scales the parameters after a long first move)
    base = fit_base(given, full, pool, cfg=cfg)
    # the base model is eq. 3.3 with a continuous control law or the same law sampled and
    # held (a digital drive), its feed-forward taking the command's derivatives as an
    # interpolator hands them over or causally, as the drive receives the commands:
    # whichever fits the identification recording best in free run is the base of every
    # candidate, the next best a second start of each search
    base, other = base_variants(base, full, pool, cfg=cfg)[:2]
    x_hat0 = simulate_spec(base, full)
    if against is not None:
        against = np.asarray(against, dtype=float).ravel()
        if against.shape != x.shape:
            raise InputError(f"against: simulated recording has {against.size} samples, expected {x.size}")
        r_cmp = against - x
    else:
        r_cmp = x_hat0 - x
    # 2. locate
    v_r, a_r = full.derivs
    loc = localise(r_cmp, x_r, x, v_r, a_r, Ts, starts)
    loc["compared_with"] = "simulated recording" if against is not None else "identified model"
    loc["fit_pct"] = _fit_pct(x_r - x, r_cmp)
    sigs = _signatures(loc)
    noise = noise_floor(x, v_r, Ts)

    # long recordings: one hold-out fold, and only the best other effect is tried as a
    # second one (time budget)
    long_rec = x_r.size * Ts > cfg.long_s
    # held-out scheme: (training chunk, test chunk) per fold
    if validation is not None:
        try:
            vx_r, vx, vseg = validation
        except (TypeError, ValueError) as exc:
            raise InputError("validation must be a tuple (x_r, x, segment)") from exc
        vx_r, vx = _check("validation recording", vx_r, vx, vseg)
        folds = [(full, make_chunk(vx_r, vx, Ts, segment_starts(vx_r.size, vseg)))]
        scheme = "validation recording"
    else:
        first, second = _fold_masks(starts)
        folds = [(full.scored(first), full.scored(second))]
        if not long_rec:
            folds.append((full.scored(second), full.scored(first)))
            scheme = "two-fold cross-validation over interleaved blocks"
        else:  # long recordings: one fold keeps the diagnosis within its time budget
            scheme = "hold-out of interleaved blocks"
    e_test = np.concatenate([te.x_r[te.score] - te.x[te.score] for _, te in folds])

    def per_fold(fn, *lists):
        """Run fn(fold_index, train, test, *items) for every fold, in parallel threads."""
        jobs = [pool.submit(fn, i, tr, te, *[l[i] for l in lists]) for i, (tr, te) in enumerate(folds)]
        return [j.result() for j in jobs]

    # with multiple shooting on, each candidate is also scored on the held-out data in its
    # windows, each simulated from the recorded state (k-step-ahead): told beside the
    # free-run figure, which judges — or, with accept_on_windows, judging, the free-run
    # figure told beside it
    shots = ([te.shots(cfg.shooting_window_s, cfg.shooting_lead_s) for _, te in folds]
             if cfg.shooting_window_s > 0 else [])

    # the held-out data restarted at rest at the end of every dwell of the command (every
    # fold's, or none: the two readings are then taken on every fold alike)
    rest_chunks = [te.rests(cfg.rest_restart_s) for _, te in folds] if cfg.accept_on_rests else []
    if any(rc is None for rc in rest_chunks):
        rest_chunks = []

    def window_residual(s: ModelSpec, i: int) -> np.ndarray:
        # the restart states every model misreads, estimated per window for reference and
        # candidate alike: shared nuisance parameters, no degree of freedom of the effect
        return residual(s, shots[i], shared_states=True)

    def scored(specs: list[ModelSpec]) -> _Scored:
        # one simulation of each held-out chunk: the weighted residual (spec.residual) is
        # its raw residual times the chunk's weights
        raw = [simulate_spec(s, te)[te.score] - te.x[te.score] for s, (_, te) in zip(specs, folds)]
        rs = [te.w[te.score] * r for r, (_, te) in zip(raw, folds)]
        train = [sse(s, tr) for s, (tr, _) in zip(specs, folds)]
        free = _Scored(specs, rs, raw, train)
        if rest_chunks:  # the same held-out data restarted at rest, the held force profiled
            def rest_reading() -> _Scored:
                rraw = [rest_residual(s, rc, cfg.rest_force_grid, cfg.rest_force_span)
                        for s, rc in zip(specs, rest_chunks)]
                return _Scored(specs, [rc.w[rc.score] * r for r, rc in zip(rraw, rest_chunks)], rraw, train)
            free.rest_reading = rest_reading
        if not cfg.accept_on_windows:
            return free
        ws = [window_residual(s, i) for i, s in enumerate(specs)]
        # a window lies in one segment, whose weight is one number: its raw residual (mm,
        # the states estimated in the weighted metric) is the weighted one over that weight
        wraw = [r / sh.w[sh.score] for r, sh in zip(ws, shots)]
        return _Scored(specs, ws, wraw, train, free_run=free)

    def test_sse(s: ModelSpec, i: int) -> float:
        if cfg.accept_on_windows:
            r = window_residual(s, i)
            with np.errstate(all="ignore"):
                v = sum_squares(r)
            return v if math.isfinite(v) else math.inf
        return sse(s, folds[i][1])

    def fit_of(sc: _Scored) -> float:
        return _fit_pct(e_test, np.concatenate(sc.free.raw_r))

    def with_shots(ev: dict, sc: _Scored, ref: _Scored, k: int) -> dict:
        if not shots:
            return ev
        if cfg.accept_on_windows:  # the windows judged: the free run's figures beside them
            fr = evidence(sc.free, ref.free, k, cfg)
            return {**ev, "held_out_scored_on": f"windows of {cfg.shooting_window_s:g} s from the recorded state "
                                                "(k-step-ahead)",
                    "held_out_windows_s": cfg.shooting_window_s,
                    "held_out_free_run_residual_reduction": _gain(sc.free, ref.free)[0],
                    "held_out_free_run_likelihood_ratio": fr["likelihood_ratio"],
                    "held_out_free_run_significant": fr["significant"],
                    "held_out_free_run_rms_before_mm": ref.free.raw_rms,
                    "held_out_free_run_rms_after_mm": sc.free.raw_rms}
        new, old = (sum(sse(s, sh) for s, sh in zip(x.specs, shots)) for x in (sc, ref))
        return {**ev, "held_out_scored_on": "free run", "held_out_windows_s": cfg.shooting_window_s,
                "held_out_windows_residual_reduction": 1.0 - math.sqrt(new / old) if old > 0 else math.nan}

    if validation is not None:  # the training data are all the data: base is fitted already
        base_sc = scored([base])
    else:
        base_sc = scored(per_fold(lambda i, tr, te: refit_base(base, tr, cfg=cfg)))
    # 3. each effect alone, on top of the base model
    candidates: list[Candidate] = []
    singles: dict[str, _Scored] = {}
    current_sc, accepted = base_sc, []
    best_name, best_gain, dropped = None, 0.0, None
    # every (effect, fold) fit is independent: spread them over the worker threads
    def fit_one(eff: str, i: int, tr: Chunk) -> ModelSpec:
        return search(base_sc.specs[i], eff, tr, loc, cfg, others=(other,))

    # the longest searches first, so both threads end together: a two-mass model's (more
    # states and variants) and one not restartable mid-move (raced on windows from rests,
    # or on whole segments where the recording shows none)
    heavy_first = sorted(effects, key=lambda e: not (EFFECT_MODELS[e].two_mass or not EFFECT_MODELS[e].restartable))
    jobs = {(eff, i): pool.submit(fit_one, eff, i, tr) for eff in heavy_first for i, (tr, _te) in enumerate(folds)}
    say(f"fitting {len(effects)} effects")
    # while the workers search: the equivalent input disturbance of the base model, and
    # where the base fails on held-out data (the searches need neither)
    disturbance = _disturbance(base, full)
    loc_val = None
    if validation is not None:
        te0 = folds[0][1]
        r_val = simulate_spec(base, te0) - te0.x
        loc_val = localise(r_val, te0.x_r, te0.x, *te0.derivs, Ts, te0.starts)
        loc_val["fit_pct"] = _fit_pct(te0.x_r - te0.x, r_val)
        disturbance["validation"] = _disturbance(base, te0)
    for k, eff in enumerate(effects):
        singles[eff] = scored([jobs[(eff, i)].result() for i in range(len(folds))])
        say(f"fitted {eff} ({k + 1}/{len(effects)})")
    # the free-run cost of eq. 3.3 has several valleys: an augmented fit may simply have
    # carried the base parameters into a better one.  Re-fit the base model from every
    # candidate's base parameters (effect removed) and compare with the best base found,
    # so an effect is credited only with what the effect itself explains.
    base_sc = _best_reference([base_sc] + [singles[e] for e in effects], given.effects, folds, pool, scored, cfg,
                              test_sse)
    # the lag of sampling (at most a sample: TimeDelay.within_inherent_lag) is part of
    # the base, not an effect: when a dead time within it earns its parameter by
    # the acceptance rule, the base with that lag is the reference every effect must beat
    # (a mode or a gap must not be credited with standing in for it)
    lag = singles.get("time_delay")
    if (lag is not None and all(TimeDelay.within_inherent_lag(sp, full.Ts) for sp in lag.specs)
            and _earns(lag, base_sc, "time_delay", cfg)):
        base_sc = lag
        loc["reference"] = "base model with the lag of a digital loop"
    current_sc = base_sc
    loc["noise_floor_mm"] = noise
    loc["held_out_rms_mm"] = base_sc.free.raw_rms
    for eff in effects:
        sc = singles[eff]
        ok, gain, folds_ok, ev, why = _judge(eff, sc, base_sc, full, noise, cfg)
        rank = gain if cfg.rank_by_gain else ev["minus_log10_p"]
        if ok and rank > best_gain:
            best_name, best_gain = eff, rank
        candidates.append(_candidate(eff, sc, fit_of(base_sc), fit_of(sc), ok, gain, cfg.min_relevant, folds_ok,
                                     sigs, [], why, base_sc.raw_rms, with_shots(ev, sc, base_sc, EFFECT_MODELS[eff].added),
                                     Ts=Ts, chunk=full, cfg=cfg))
    # 4. greedy forward selection: the best single effect, then a second on top of it
    chosen_first = best_name  # by the forward step, whatever order the verdict names them in
    if best_name is not None:
        accepted = [best_name]
        current_sc = singles[best_name]
        # a second effect must matter on its own too: only singles that passed are tried
        others = [c.effect for c in sorted(candidates, key=lambda c: -c.score["minus_log10_p"])
                  if c.accepted and c.effect != best_name][: 1 if long_rec else 2]
        best2, best2_gain, best2_sc = None, 0.0, None
        round2 = []
        say(f"trying a second effect on top of {best_name}")

        # the pair is fitted jointly, searched from either single model (each effect's fit
        # alone moved the base into its own valley, where the other's starts may not reach
        # the pair's): the lower training cost wins.  A dead time held at the centre of the
        # delays that fit equally well alone is free again.  Both searches are jobs of their own.
        jobs = {(eff, i): (pool.submit(search, singles[best_name].specs[i].released(), eff, tr, loc, cfg),
                           pool.submit(search, singles[eff].specs[i].released(), best_name, tr, loc, cfg))
                for eff in others for i, (tr, _te) in enumerate(folds)}

        def fit_pair(eff: str, i: int) -> ModelSpec:
            a, b = (j.result() for j in jobs[(eff, i)])
            tr = folds[i][0]
            return a if sse(a, tr) <= sse(b, tr) else b

        pairs = {eff: scored([fit_pair(eff, i) for i in range(len(folds))]) for eff in others}
        if pairs:
            current_sc = _best_reference([current_sc] + list(pairs.values()), given.effects + (best_name,), folds,
                                         pool, scored, cfg, test_sse)
        for eff, sc in pairs.items():
            ok, gain, folds_ok, ev, why = _judge(eff, sc, current_sc, full, noise, cfg)
            round2.append((eff, sc, gain, folds_ok, ok, why, ev))
            if ok and ev["minus_log10_p"] > best2_gain:
                best2, best2_gain, best2_sc = eff, ev["minus_log10_p"], sc
        for eff, sc, gain, folds_ok, ok, why, ev in round2:
            candidates.append(_candidate(eff, sc, fit_of(current_sc), fit_of(sc), ok and eff == best2, gain,
                                         cfg.min_relevant, folds_ok, sigs, [best_name], why, current_sc.raw_rms,
                                         with_shots(ev, sc, current_sc, EFFECT_MODELS[eff].added),
                                         Ts=Ts, chunk=full, cfg=cfg))
        if best2 is not None:
            accepted.append(best2)
            current_sc = best2_sc
            # backward step of the stepwise selection: the first effect must still earn
            # its parameters, by the same rule, next to the second alone (a small gap
            # across a stiff contact can stand in for a mode it only mimics)
            alone = singles[best2]
            if not _earns(current_sc, alone, best_name, cfg):
                dropped, accepted, current_sc, chosen_first = best_name, [best2], alone, best2
            elif (evidence(current_sc, alone, EFFECT_MODELS[best_name].added, cfg)["minus_log10_p"]
                  < best2_gain):
                # both stay; the one whose removal would cost the more evidence is named first
                accepted = [best2, best_name]
    # "accepted" means in the final model; an effect that passed alone but lost the
    # stepwise selection says so in its score
    for j, c in enumerate(candidates):
        if "added_to" not in c.score:  # an effect alone on the base
            candidates[j] = replace(c, accepted=c.effect == chosen_first, score={**c.score, "passed_alone": c.accepted})
        elif dropped and c.accepted:  # the second effect, now standing alone
            why = f"{dropped} dropped: not significant next to {c.effect} alone"
            candidates[j] = replace(c, accepted=False, score={**c.score, "backward_step": why})

    # the accepted model's parameters by maximum likelihood with a variance per segment
    # (the selection above stays on the search's weights, under which it was stated)
    if accepted and cfg.segment_variance_steps:
        say("re-estimating the accepted model with a variance per segment")
        prev = current_sc
        current_sc = scored(per_fold(lambda i, tr, te: segment_variance_fit(prev.specs[i], tr, cfg)))
        for j, c in enumerate(candidates):
            if c.accepted:
                candidates[j] = replace(c, parameters=_fold_parameters(current_sc.specs, c.effect, Ts),
                                        score={**c.score, "parameters_estimated": "variance per segment"})
    # 5. a load the motion does not cause: described, and added as an input where it is
    external = _external_force(base, full, folds[0][1] if validation is not None else None, disturbance, cfg)
    if external is not None:
        candidates.append(external)
    say("final fit")
    # 6. the final augmented model on all identification data, and the words
    if accepted and cfg.segment_variance_steps:
        # with a validation recording the one fold trained on all identification data and
        # was re-estimated there above: that model is the final one
        final = current_sc.specs[0] if folds[0][0] is full else segment_variance_fit(current_sc.specs[0], full, cfg)
    elif accepted:
        final = fit_spec(current_sc.specs[0], full, max_iter=10, cfg=cfg)
    else:
        final = base
    # every accepted parameter with its 95 % interval, or why the data leave it open
    if accepted:
        say("confidence intervals of the accepted parameters")
        # (at the stationary point of the final fit's cost, which the search may stop short of:
        # the accepted effects' parameters are then those of the final model)
        final, told = effect_intervals(final, full, cfg, Ts, pool)
        for j, c in enumerate(candidates):
            if c.accepted and c.effect in told:
                iv, unres = told[c.effect]
                candidates[j] = replace(c, parameters=effect_parameters(final, c.effect, Ts), intervals=iv,
                                        unresolved=unres)
    x_hat1 = simulate_spec(final, full)
    fit_before = fit_of(base_sc)
    fit_after = fit_of(current_sc)
    traces = {
        "t": np.arange(x_r.size) * Ts,
        "x_r": x_r,
        "x": x,
        "x_hat_before": x_hat0 if against is None else against,
        "x_hat_after": x_hat1,
        "residual_before": r_cmp,
        "residual_after": x_hat1 - x,
    }
    if validation is not None:
        te = folds[0][1]
        traces.update({
            "validation_t": np.arange(te.n) * Ts,
            "validation_x_r": te.x_r,
            "validation_x": te.x,
            "validation_x_hat_before": simulate_spec(base_sc.specs[0], te),
            "validation_x_hat_after": simulate_spec(current_sc.specs[0], te),
        })
    aug = {"base": dict(zip(BASE_KEYS, map(float, final.theta))),
           "effects": {e: effect_parameters(final, e, Ts) for e in given.effects + tuple(accepted)},
           "controller": CONTROLLERS[int(final.modes[MODE_SLOTS["controller"]])],
           "held_out": scheme}
    named = accepted + (["external_force"] if external is not None and external.accepted else [])
    verdict: str | list[str]
    if not named:
        verdict = "none"
    elif len(named) == 1:
        verdict = named[0]
    else:
        verdict = list(named)
    loc["held_out_rms_after_mm"] = current_sc.free.raw_rms
    mismatch = dict(loc)
    mismatch["signatures"] = sigs
    mismatch["held_out"] = scheme
    # the external force is told on its own below: "best candidate" means a drive effect
    summary = _summary(loc, accepted, final, [c for c in candidates if c.effect != "external_force"],
                       fit_before, fit_after, scheme, Ts)
    if loc_val is not None:
        summary += f" On the validation recording: {_validation_where_words(loc_val, disturbance.get('validation'))}."
    if external is not None and external.accepted:
        summary += (f" An external force: {external.score['words']}; as an input it takes the "
                    f"{external.score['recording']} recording's fit {_fit_words(external.fit_before_pct, external.fit_after_pct)}.")
    elif not accepted:
        which = disturbance.get("validation", disturbance)
        summary += f" The model would need {which['words']}."
    return Diagnosis(
        verdict=verdict,
        mismatch=mismatch,
        candidates=candidates,
        summary=summary,
        fit_before_pct=fit_before,
        fit_after_pct=fit_after,
        elapsed_s=time.perf_counter() - t0,
        augmented_model=aug,
        traces=traces,
        mismatch_validation=loc_val,
        disturbance=disturbance,
    )


def _absolute_phase(d: Diagnosis, reference: float) -> Diagnosis:
    """``d`` with a cyclic error's phase moved from positions relative to ``reference`` to absolute ones.

    ``A·sin(2π(x − x₀)/P + φ) = A·sin(2πx/P + φ − 2πx₀/P)``: the phase in absolute position
    is φ − 2πx₀/P, wrapped to (−π, π].
    """
    def moved(p: dict) -> dict:
        if not reference or "phase_rad" not in p:
            return p
        phi = p["phase_rad"] - 2.0 * math.pi * reference / p["period_mm"]
        return {**p, "phase_rad": float(math.atan2(math.sin(phi), math.cos(phi)))}

    if not reference:
        return d
    aug = dict(d.augmented_model)
    aug["effects"] = {e: moved(p) if e == "cyclic_error" else p for e, p in aug.get("effects", {}).items()}
    return replace(d, candidates=[replace(c, parameters=moved(c.parameters)) if c.effect == "cyclic_error" else c
                                  for c in d.candidates], augmented_model=aug)


def _disturbance(spec: ModelSpec, chunk: Chunk) -> dict:
    """The equivalent input disturbance of ``spec`` along ``chunk``'s recording, analysed."""
    w = equivalent_disturbance(chunk.x_r, chunk.x, chunk.Ts, spec.theta, chunk.starts)
    return analyse_disturbance(w, chunk.x_r, chunk.x, *chunk.derivs, chunk.Ts, chunk.starts)


def _external_force(base: ModelSpec, full: Chunk, val: Chunk | None, disturbance: dict,
                    cfg: DiagnosisConfig) -> Candidate | None:
    """The ``external_force`` candidate when the disturbance comes in time blocks the motion does not explain.

    Looked for on the recording where the model fails on held-out data (the validation
    recording when given).  A time-localised load cannot be predicted on another
    recording; it is *described*, and added as a known input to that recording's
    simulation to show how much of the mismatch it explains: the load's scale and a
    constant input beside it by least squares (a base fitted on the same recording has
    taken up the load's mean).  Accepted when it removes at least
    ``cfg.min_gain + cfg.per_param·k`` of the residual norm, k = 2 parameters per block and
    the two of the scale and the constant.

    The load's effect is the difference of two free runs of eq. 3.3 (``ident.simulation``)
    that differ only by the input; it is added to the diagnosis's own free-run residual of
    ``base``.  Simulating ``base`` in ``ident.simulation`` alone would not do: it starts the
    integral state at zero where the diagnosis's simulator starts it at equilibrium, and
    on a loop without integral action (EMPS: a3 < 0, a slow real pole) that start leaves
    a 0.1 mm drift larger than the load's effect — the difference cancels it.
    """
    from ident.simulation import simulate

    chunk, analysis, name = (val, disturbance.get("validation"), "validation") if val is not None else \
        (full, disturbance, "identification")
    if not analysis or not analysis.get("time_localised"):
        return None
    model = dict(zip(BASE_KEYS, map(float, base.theta)))
    from ident.model import DriveModel

    dm = DriveModel(**model)
    seg = np.cumsum(chunk.starts) - 1
    w = block_input(chunk.n, analysis["blocks"], chunk.Ts)
    e = chunk.x_r - chunk.x
    with np.errstate(all="ignore"):
        r0 = simulate_spec(base, chunk) - chunk.x
        free = simulate(dm, chunk.x_r, chunk.Ts, segment=seg, x0=chunk.x)
        effect = simulate(dm, chunk.x_r, chunk.Ts, segment=seg, x0=chunk.x, disturbance=w) - free
        steady = simulate(dm, chunk.x_r, chunk.Ts, segment=seg, x0=chunk.x, disturbance=np.ones(chunk.n)) - free
    # the load's scale and a constant beside it by least squares: a base fitted on the same
    # recording has taken up the load's mean (as a friction offset, a gain), which the
    # constant gives back; with a base fitted elsewhere the scale is ~1 and the constant ~0
    E = np.column_stack([effect, steady])
    coef = lstsq(E, -r0) if np.all(np.isfinite(E)) and np.all(np.isfinite(r0)) else np.zeros(2)
    r1 = r0 + matvec(E, coef)
    n0, n1 = norm(r0), norm(r1)
    gain = 1.0 - n1 / n0 if n0 > 0 and np.isfinite(n1) else -math.inf
    blocks = analysis["blocks"]
    added = 2 * len(blocks) + 2
    need = cfg.min_gain + cfg.per_param * added
    params = {"force": float(abs(coef[0]) * np.median([abs(b["mean_mm_s2"]) for b in blocks])),
              "force_unit": "mm/s^2", "times": [[b["t_start_s"], b["t_end_s"]] for b in blocks], "recording": name}
    score = {"held_out_residual_reduction": float(gain), "required_reduction": float(need),
             "parameters_added": added, "words": analysis["words"], "recording": name,
             "load_scale": float(coef[0]), "constant_beside_mm_s2": float(coef[1]),
             "rms_before_mm": n0 / math.sqrt(chunk.n), "rms_after_mm": n1 / math.sqrt(chunk.n),
             "held_out_rms_before_mm": n0 / math.sqrt(chunk.n), "held_out_rms_after_mm": n1 / math.sqrt(chunk.n)}
    return Candidate("external_force", params, _fit_pct(e, r0), _fit_pct(e, r1), bool(gain >= need), score)


def _fold_parameters(specs: list[ModelSpec], eff: str, Ts: float) -> dict:
    """``eff``'s parameters in the fold models: the median over folds, of each end for a range."""
    ps = [effect_parameters(s, eff, Ts) for s in specs]
    params = dict(ps[0])
    for k in params:
        if isinstance(params[k], float):
            params[k] = float(np.median([p[k] for p in ps if isinstance(p.get(k), float)]))
        elif isinstance(params[k], list):
            ends = np.array([p[k] for p in ps if isinstance(p.get(k), list)], dtype=float)
            params[k] = [float(v) for v in np.median(ends, axis=0)]
    return params


def _candidate(eff: str, sc: _Scored, before: float, after: float, ok: bool, gain: float, need: float,
               folds_ok: bool, sigs: dict, added_to: list[str], implausible: str = "",
               rms_before: float = math.nan, ev: dict | None = None, *, Ts: float, chunk: Chunk,
               cfg: DiagnosisConfig) -> Candidate:
    params = _fold_parameters(sc.specs, eff, Ts)
    score = {
        "held_out_residual_reduction": float(gain),
        "required_reduction": float(need),
        "improves_every_fold": bool(folds_ok),
        "parameters_added": EFFECT_MODELS[eff].added,
        "signature": sigs.get(eff, {}),
        "size_test": "passed" if not implausible else f"failed: {implausible}",
        **(ev or {}),
        # the rms of the reading judged (given in ev when it is not the free run's)
        "held_out_rms_before_mm": float((ev or {}).get("held_out_rms_before_mm", rms_before)),
        "held_out_rms_after_mm": float((ev or {}).get("held_out_rms_after_mm", sc.raw_rms)),
    }
    if added_to:
        score["added_to"] = list(added_to)
    held = {k: why for s in sc.specs for k, why in at_bound(s, eff, chunk, cfg).items()}
    return Candidate(eff, params, float(before), float(after), bool(ok), score, unresolved=held)


def _fit_words(before: float, after: float) -> str:
    """"99.80 % → 99.86 %": one decimal, more when the change is smaller (fits near 100 % differ late)."""
    diff = abs(after - before)
    nd = 2 if not (math.isfinite(diff) and diff > 0) else min(max(-math.floor(math.log10(diff)), 1), 3)
    return f"{before:.{nd}f} % → {after:.{nd}f} %"


def _rms_words(before_mm: float, after_mm: float) -> str:
    """"residual rms 2.4 → 1.9 µm (−21 %)" from the held-out residual rms in mm."""
    if not (math.isfinite(before_mm) and math.isfinite(after_mm)) or before_mm <= 0:
        return "residual rms n/a"
    change = 100.0 * (after_mm / before_mm - 1.0)
    return f"residual rms {1e3 * before_mm:.3g} → {1e3 * after_mm:.3g} µm ({change:+.0f} %)".replace("-", "−")


def _why_not(c: Candidate) -> str:
    """Why a candidate was not named, in the order the rule of §4 asks: the evidence, the size,
    then what its name means — a mode whose damping is on a lightly damped mode's bound still
    says so, with what it removes, rather than only "not significant"."""
    sc = c.score
    if not sc.get("significant", False):
        return "not significant"
    gain, need = sc.get("held_out_residual_reduction", 0.0), sc.get("required_reduction", 0.0)
    if gain < need:
        return f"significant, but it removes {100 * gain:.0f} % of the held-out residual, under {100 * need:.0f} %"
    test = str(sc.get("size_test", ""))
    if test.startswith("failed: "):
        return f"significant, removes {100 * gain:.0f} % of the held-out residual, not named: {test[len('failed: '):]}"
    return "not named"


def _summary(loc: dict, accepted: list[str], final: ModelSpec, cands: list[Candidate], before: float,
             after: float, scheme: str, Ts: float) -> str:
    where = _where_words(loc)
    head = f"Mismatch: {where}."
    if accepted:
        by_name = {c.effect: c for c in cands if c.accepted}

        def one(e: str) -> str:
            c = by_name.get(e)
            words = _param_words(e, effect_parameters(final, e, Ts), c.intervals if c else None,
                                 c.unresolved if c else None)
            if c is not None:  # the evidence beside the statement
                words += f", removing {100 * c.score['held_out_residual_reduction']:.0f} % of the held-out residual"
                if c.score.get("held_out_judged_on") == "restarted at rest":
                    words += (f" restarted at rest after every dwell of the command "
                              f"({100 * c.score['held_out_free_run_residual_reduction']:.0f} % in free run)")
                elif "held_out_free_run_residual_reduction" in c.score:  # judged on the windows
                    words += (f" over windows of {c.score['held_out_windows_s']:g} s from the recorded state "
                              f"({100 * c.score['held_out_free_run_residual_reduction']:.0f} % in free run)")
            return words

        left = "; ".join(one(e) for e in accepted)
        # "reference fit": eq. 3.3 as the diagnosis re-fitted it, not the identified model (ident/headline.py)
        return (f"{head} Left out: {left}. Added to the model: reference fit "
                f"{_fit_words(before, after)}, {_rms_words(loc['held_out_rms_mm'], loc['held_out_rms_after_mm'])} "
                f"({scheme}).")
    best = max(cands, key=lambda c: c.fit_after_pct) if cands else None
    tail = ""
    if best is not None:
        # the free run's rms beside its fit (judged on windows the score's own is the windows')
        fr = "held_out_free_run_" if "held_out_free_run_rms_before_mm" in best.score else "held_out_"
        tail = (f" (best candidate {best.effect}: reference fit {_fit_words(best.fit_before_pct, best.fit_after_pct)}, "
                f"{_rms_words(best.score[fr + 'rms_before_mm'], best.score[fr + 'rms_after_mm'])}, "
                f"{_why_not(best)})")
    wh = loc.get("whiteness", {})
    white = "white" if wh.get("white") else "not white"
    return (f"{head} Left out: none — no effect of the vocabulary improves the held-out fit significantly"
            f"{tail}; reference fit {before:.2f} %, held-out residual rms "
            f"{1e3 * loc['held_out_rms_mm']:.3g} µm, {white}.")

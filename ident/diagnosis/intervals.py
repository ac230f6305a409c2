"""95 % confidence intervals of an accepted effect's parameters, and what the data leave open.

The accepted model (base θ of eq. 3.3 and the effects' parameters, fitted jointly by output
error, eq. 3.6) minimises ``½‖w·(x̂(p) − x)‖²`` over the scored samples.  Linearised at
the estimate, ``r(p) ≈ r(p̂) + J (p − p̂)`` with ``J = ∂(w·x̂)/∂p`` (the exact complex-step
sensitivities of the free-run simulation, :func:`~ident.diagnosis.augmented.sensitivities`:
the slope of the branch of every switch the estimate's run takes; every column one parameter
of the joint fit, base included, so an effect's interval carries its correlation with the
base).  The residual of a free run is
coloured — noise and unmodelled dynamics pass through the loop — so the covariance is the
one that holds for correlated residuals, the linearised delete-one-block jackknife of
:mod:`ident.uncertainty` (``_sandwich``: blocks of five integrated autocorrelation times of
the scores, i.e. the recording counted by its effective number of samples), and the
interval is ``p̂ ± t_{0.975, B−n}·se``.  Quantities the effect reports rather than fits
(a cyclic error's amplitude and phase, a two-mass mode's locked-motor frequency, a dead time
without the lag of sampling) get theirs by the delta method through
:meth:`Effect.parameters <ident.diagnosis.effects.Effect.parameters>`.

**Not resolved.**  A parameter the fit left on a bound of its box is held there by the box,
not placed by the data (a mode's damping at ``config.max_mode_damping``: the data want a
better-damped pole pair than a lightly damped mode allows): it gets no interval, and the
others are conditional on it (its column left out, as :mod:`ident.uncertainty` projects an
active constraint).  A parameter whose interval includes 0, or that the fit does not depend
on, is not resolved either.  Neither refuses the effect — the held-out likelihood ratio
decides that (:func:`ident.diagnosis.diagnose.evidence`); the words and the JSON say what is
and is not known.
"""

from __future__ import annotations

import math
from concurrent.futures import Executor

import numpy as np
from scipy.special import stdtrit

from ident.diagnosis.augmented import EP_INDEX, N_EP, sensitivities
from ident.diagnosis.config import DiagnosisConfig
from ident.diagnosis.effects import EFFECT_MODELS
from ident.diagnosis.spec import Chunk, ModelSpec, sim_substeps, simulate_spec
from ident.gauss_newton import to_stationary_point
from ident.uncertainty import _sandwich

__all__ = ["at_bound", "effect_intervals", "stationary_point"]

#: A parameter within this share of its box's width (or of the bound's size) of a bound is on it.
_ON_BOUND = 1e-3
#: A Gauss–Newton step that would lower the cost by less than this share is not taken: the
#: estimate is at the stationary point as far as the linearisation can tell.
_STATIONARY = 1e-4


def _box(spec: ModelSpec, effect: str, name: str, chunk: Chunk, cfg: DiagnosisConfig) -> tuple[float, float]:
    """The box the fit held ``name`` in: the effect's bounds narrowed by the start's (``spec.box``)."""
    lo, hi = EFFECT_MODELS[effect].bounds(name, float(spec.ep[EP_INDEX[name]]), chunk, cfg)
    if name in spec.box:
        lo, hi = max(lo, spec.box[name][0]), min(hi, spec.box[name][1])
    return float(lo), float(hi)


def at_bound(spec: ModelSpec, effect: str, chunk: Chunk, cfg: DiagnosisConfig) -> dict[str, str]:
    """The free parameters of ``effect`` in ``spec`` that sit on a bound of their fit's box,
    name → why ("held at the fit's bound 0.15"): the box, not the data, placed them."""
    out = {}
    for name in EFFECT_MODELS[effect].free(spec):
        v = float(spec.ep[EP_INDEX[name]])
        lo, hi = _box(spec, effect, name, chunk, cfg)
        for b in (lo, hi):
            if math.isfinite(b):
                width = (hi - lo) if math.isfinite(hi - lo) else abs(b)
                if abs(v - b) <= _ON_BOUND * max(width, abs(b), 1e-12):
                    out[name] = f"held at the fit's bound {b:.3g}"
    return out


def _parameters(spec: ModelSpec, names: list[str], z: np.ndarray, effect: str, Ts: float) -> dict:
    s = spec.copy()
    for name, v in zip(names, z):
        s.ep[EP_INDEX[name]] = v
    return EFFECT_MODELS[effect].parameters(s, Ts)


class _Columns:
    """The joint fit's parameters as Jacobian columns: θ of eq. 3.3 and every effect's free
    ones not held by a bound (a dead time the profile centred included: its interval is the
    curvature's there), with their scales."""

    def __init__(self, spec: ModelSpec, held: dict[str, dict[str, str]]):
        self.cols: list[tuple[str | None, int, str]] = [(None, j, "") for j in range(8)]
        for e in spec.effects:
            for name in EFFECT_MODELS[e].free(spec):
                if name not in held[e] and all(c[2] != name for c in self.cols):
                    self.cols.append((e, EP_INDEX[name], name))
        v0 = self.values(spec)
        a1, a2 = abs(float(spec.theta[0])) or 1.0, abs(float(spec.theta[1])) or 1.0
        base_floors = [1.0, 1.0, 1.0, 0.05, 0.01 * a1, 0.01 * a2, 1e-4 * a2, 1e-4 * a2]  # as candidates.fit_spec
        floors = np.array([base_floors[j] if e is None else EFFECT_MODELS[e].scale_floor.get(n, 1e-6)
                           for e, j, n in self.cols])
        self.scale = np.maximum(np.abs(v0), floors)

    def values(self, spec: ModelSpec) -> np.ndarray:
        return np.array([spec.theta[j] if e is None else spec.ep[j] for e, j, _ in self.cols], dtype=float)

    def moved(self, spec: ModelSpec, v: np.ndarray) -> ModelSpec:
        s = spec.copy()
        for (e, j, _), x in zip(self.cols, v):
            if e is None:
                s.theta[j] = x
            else:
                s.ep[j] = x
        return s


def _jacobian(spec: ModelSpec, chunk: Chunk, c: _Columns, pool: Executor | None) -> tuple[np.ndarray, np.ndarray]:
    """J = ∂(w·x̂)/∂(v/scale) on the scored samples (exact sensitivities) and r = w·(x̂ − x).

    The columns in two groups, jobs of ``pool`` when given (the kernel releases the GIL).
    """
    m = chunk.score
    w = chunk.w[m]
    nsub = sim_substeps(spec, chunk.Ts)

    def columns(ks: range) -> np.ndarray:
        d_th, d_ep = np.zeros((len(ks), 8)), np.zeros((len(ks), N_EP))
        for i, k in enumerate(ks):
            e, j, _ = c.cols[k]
            (d_th if e is None else d_ep)[i, j] = c.scale[k]
        return sensitivities(chunk.x_r, chunk.x, chunk.Ts, spec.theta, spec.ep, d_th, d_ep, flags=spec.flags(),
                             modes=spec.modes, starts=chunk.starts, derivs=chunk.derivs, nsub=nsub,
                             warm=chunk.warm)[:, m]

    n = len(c.cols)
    groups = [range(0, (n + 1) // 2), range((n + 1) // 2, n)]
    with np.errstate(all="ignore"):
        parts = list(pool.map(columns, groups)) if pool is not None else [columns(g) for g in groups]
        r = w * (simulate_spec(spec, chunk)[m] - chunk.x[m])
        J = w[:, None] * np.concatenate(parts, axis=0).T
    return J, r


def stationary_point(spec: ModelSpec, chunk: Chunk, cfg: DiagnosisConfig, pool: Executor | None = None,
                     max_steps: int = 3) -> tuple[ModelSpec, np.ndarray, np.ndarray, _Columns, dict]:
    """Gauss–Newton steps on every scored sample until the weighted cost stops falling.

    The covariance holds at a stationary point of the cost on the data it is computed from;
    the search stops on an iteration count or a relative decrease, which on a curved valley
    (a two-mass mode's ridge of equal f·√μ) can leave the estimate several standard errors
    from that point.  Each step ``−(JᵀJ)⁻¹Jᵀr`` is clipped to the fit's box and halved
    until the cost falls (:func:`ident.gauss_newton.to_stationary_point`, as
    :func:`ident.uncertainty.stationary_point` does for the base model).  Returns the model,
    its Jacobian per unit of each column's scale and residual, the columns and the
    parameters held by a bound (effect → name → why).
    """
    held = {e: at_bound(spec, e, chunk, cfg) for e in spec.effects}
    c = _Columns(spec, held)
    boxes = [(-np.inf, np.inf) if e is None else _box(spec, e, n, chunk, cfg) for e, _, n in c.cols]
    lo, hi = np.array([b[0] for b in boxes]), np.array([b[1] for b in boxes])
    m = chunk.score

    def per_unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # J per unit of each parameter
        J, r = _jacobian(c.moved(spec, v), chunk, c, pool)
        return J / c.scale[None, :], r

    def residual(v: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            return chunk.w[m] * (simulate_spec(c.moved(spec, v), chunk)[m] - chunk.x[m])

    v, J, r = to_stationary_point(c.values(spec), per_unit, residual,
                                  scale=lambda _v: c.scale, project=lambda v: np.clip(v, lo, hi),
                                  max_steps=max_steps, rel_decrease=1e-6, min_linear_decrease=_STATIONARY)
    spec = c.moved(spec, v)
    J = J * c.scale[None, :]  # per unit of each parameter's scale, as the covariance is formed
    return spec, J, r, c, held


def effect_intervals(spec: ModelSpec, chunk: Chunk, cfg: DiagnosisConfig, Ts: float,
                     pool: Executor | None = None, level: float = 0.95) -> tuple[ModelSpec, dict[str, tuple[dict, dict]]]:
    """The accepted model at its stationary point, and per effect (intervals, not resolved)
    of its reported parameters.

    ``spec`` is the accepted model fitted on ``chunk`` (its weights: the final fit's, a
    variance of each segment's own when ``cfg.segment_variance_steps``), moved to the
    stationary point of that cost (:func:`stationary_point`).  Intervals: reported name →
    [lo, hi] at ``level`` (module docstring); not resolved: name → why.  The Jacobian's
    simulations are jobs of ``pool`` when given (the kernel releases the GIL).
    """
    if cfg.segment_variance_steps:
        chunk = chunk.reweighted(simulate_spec(spec, chunk) - chunk.x)
    spec, J, r, c, held = stationary_point(spec, chunk, cfg, pool)
    cols, scale, v0 = c.cols, c.scale, c.values(spec)
    m = chunk.score
    out: dict[str, tuple[dict, dict]] = {}
    ok = bool(np.all(np.isfinite(J)) and np.all(np.isfinite(r)))
    if ok:
        seg = np.cumsum(chunk.starts)[m] - 1
        # a column the fit does not depend on: left out (its parameter is not resolved)
        norms = np.linalg.norm(J, axis=0)
        live = norms > 1e-9 * max(float(norms.max()), 1e-300)
        cov = np.full((len(cols), len(cols)), np.nan)
        cov_s, _L, B, _tau = _sandwich(J[:, live], r, seg)
        cov[np.ix_(live, live)] = cov_s * np.outer(scale[live], scale[live])
        tq = float(stdtrit(max(B - int(live.sum()), 1), 0.5 + level / 2.0))
    for e in spec.effects:
        names = [n for ee, _, n in cols if ee == e]
        idx = [k for k, (ee, _, _n) in enumerate(cols) if ee == e]
        p0 = EFFECT_MODELS[e].parameters(spec, Ts)
        unresolved = {**held[e], **at_bound(spec, e, chunk, cfg)}  # a step may have ended on a bound
        iv: dict[str, list[float]] = {}
        if ok and names:
            C = cov[np.ix_(idx, idx)]
            z0 = v0[idx]
            h = 1e-6 * scale[idx]
            grads = {}
            for i in range(len(idx)):  # ∂(reported)/∂(fitted) by central differences
                zp, zm = z0.copy(), z0.copy()
                zp[i] += h[i]
                zm[i] -= h[i]
                pp, pm = _parameters(spec, names, zp, e, Ts), _parameters(spec, names, zm, e, Ts)
                for key, val in p0.items():
                    if isinstance(val, float) and isinstance(pp.get(key), float):
                        d = (pp[key] - pm[key]) / (2.0 * h[i])
                        if key == "phase_rad":  # unwrap across ±π
                            d = math.remainder(pp[key] - pm[key], 2.0 * math.pi) / (2.0 * h[i])
                        grads.setdefault(key, np.zeros(len(idx)))[i] = d
            for key, g in grads.items():
                if key in unresolved or not np.any(g):
                    continue  # held by a bound, or not estimated (a structural share)
                var = float(g @ C @ g)
                val = p0[key]
                if not (math.isfinite(var) and var >= 0.0):
                    unresolved[key] = "the fit does not depend on it"
                    continue
                half = tq * math.sqrt(var)
                lo, hi = val - half, val + half
                if val != 0.0 and lo <= 0.0 <= hi and key != "phase_rad":
                    unresolved[key] = "its 95 % interval includes 0"
                if key in names:  # within the box the fit held it in (a damping ≥ its floor)
                    b_lo, b_hi = _box(spec, e, key, chunk, cfg)
                    lo, hi = max(lo, b_lo), min(hi, b_hi)
                iv[key] = [lo, hi]
        out[e] = (iv, unresolved)
    return spec, out

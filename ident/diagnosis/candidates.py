"""Candidate explanations: fit the base model plus one effect by output error (eq. 3.6).

One search for every effect (:func:`search`), the effect itself only supplying its starts,
bounds and scales (:mod:`ident.diagnosis.effects`):

1. **starts** — the effect's :meth:`~ident.diagnosis.effects.Effect.starts`: a grid over its
   main nonlinear parameter (gap, breakaway ratio, frequency, delay, period, limit), led by
   the localisation where it can be (residual spectrum peaks, position periodogram, |u|
   percentiles, the regression that knows a delay), times every structural variant;
2. **screen** — each start's free-run cost with the base held, on the ``race_seconds`` of
   windows the race ends on; the best of every structural variant and the cheapest
   others up to ``config.screened_starts`` go on;
3. **race** (successive halving over the share of the recording fitted) — every start
   still in the race gets a few iterations of the joint fit of base and effect (bounded
   Levenberg–Marquardt with the coarse difference step: contact, stick and clipping
   events make the cost ripple on a fine scale) on ¼ of ``config.race_seconds`` of the
   recording, in windows spread over all of it, each restarted mid-move on the recorded
   state (:meth:`Chunk.windows <ident.diagnosis.spec.Chunk.windows>`); the better half
   by training cost (and the best of every variant) goes on to ½, then to all of those
   seconds (``race_seconds`` 0: the first ¼, ½ and all of every segment instead,
   :meth:`Chunk.part <ident.diagnosis.spec.Chunk.part>`).  Ranking starts after a short
   fit is unreliable — the base identified without the effect has absorbed it, and the
   right start can cost the most until the base has moved back — and early rounds on
   part of the recording are cheap, so every start gets enough iterations for that
   before it is compared;
4. **polish** — the winner's joint fit continued on the whole chunk (every sample), then
   with the fine difference step.

A weakly determined dead time is then moved to the middle of the delays that fit equally
well (:func:`centre_delay`).  Once the diagnosis has accepted an effect, its model is
re-estimated by maximum likelihood with a noise variance per segment
(:func:`segment_variance_fit`).  Every fit works in scaled coordinates ``z = p / s`` (s = |start|
or a floor) so one difference step suits parameters as different as a3 ≈ 1e6 1/s³ and b0 ≈ 1.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ident.diagnosis.augmented import EP_INDEX, MODE_SLOTS, N_EP, simulate_augmented, simulate_augmented_many
from ident.diagnosis.config import DiagnosisConfig
from ident.diagnosis.effects import EFFECT_MODELS, cascade_motor_share, effect_parameters
from ident.diagnosis.spec import (Chunk, ModelSpec, estimated_states, make_chunk, residual, residual_jacobian,
                                  restart_responses, sim_substeps, simulate_spec, sse)
from ident.fixed_order import weighted_rows
from ident.least_squares import bounded_lm, secant_lm
from ident.portable_math import exp, log

if TYPE_CHECKING:
    from ident.regression import Regression

__all__ = ["Chunk", "ModelSpec", "make_chunk", "simulate_spec", "residual", "sse", "fit_spec", "search",
           "sampled_base", "refit_base", "base_variants", "softened_base", "effect_parameters", "cascade_motor_share",
           "chunk_regression", "delayed_regression_start", "centre_delay", "scan_motor_fraction", "race_part",
           "held_force", "shoot", "polish", "segment_variance_fit", "profile_gap"]


def fit_spec(spec: ModelSpec, chunk: Chunk, *, fit_base: bool = True, fit_effects: bool = True,
             max_iter: int = 25, bounds: dict[str, tuple[float, float]] | None = None,
             fd_step: float | None = None, polish: bool = True, secant_nfev: int = 0, search: bool = False,
             cfg: DiagnosisConfig) -> ModelSpec:
    """Output-error fit (eq. 3.6 on the free-run simulation) of base and effect parameters.

    Starts from ``spec``; base parameters move jointly with the effects' parameters
    (:meth:`Effect.free <ident.diagnosis.effects.Effect.free>`, inside their bounds) when
    ``fit_base``; ``bounds`` narrows the box of named effect parameters; parameters named in
    ``spec.ranges`` (weakly determined, centred by :func:`centre_delay`) are held.
    ``fd_step``: the forward-difference step (scaled units; default ``cfg.fd_step``); a
    step coarser than ``cfg.fd_step`` is followed by a polish at the fine step (half the
    iterations) when ``polish``.  With ``cfg.exact_fine`` (``cfg.exact_rough``) the fine
    (coarse) step is not a difference: it stands for the exact Jacobian, the complex-step
    sensitivities of the simulation (:func:`~ident.diagnosis.spec.residual_jacobian`).
    With ``cfg.fit_log`` an effect parameter whose box lies above zero is
    fitted by its logarithm.  ``secant_nfev`` > 0:
    the secant Levenberg–Marquardt (:func:`ident.least_squares.secant_lm`) with that many
    simulations instead, no polish.  ``search``: a fit of an effect's search (the race and its
    polish), for ``cfg.fit_beta``, whose Jacobian is taken in its own thread.  Returns the
    fitted copy; a fit that fails to improve
    returns ``spec``.
    """
    if fd_step is None:
        fd_step = cfg.fd_step
    names, own = [], []
    if fit_effects:
        for e in spec.effects:
            eff = EFFECT_MODELS[e]
            for p in eff.free(spec):
                if p not in spec.ranges and p not in names:
                    names.append(p)
                    own.append(eff)
    idx = [EP_INDEX[p] for p in names]
    th0 = spec.theta.astype(float)
    a2 = abs(th0[1]) or 1.0
    a1 = abs(th0[0]) or 1.0
    floors = np.array([1.0, 1.0, 1.0, 0.05, 0.01 * a1, 0.01 * a2, 1e-4 * a2, 1e-4 * a2])
    s_th = np.maximum(np.abs(th0), floors)
    # β = b2 − a2 in place of b2 (cfg.fit_beta): b2 and a2 multiply positions of ~100 mm
    # and nearly cancel, so a step on b2 alone moves u by far more than one on a2
    beta = fit_base and (cfg.fit_beta == "all" or (cfg.fit_beta == "searches" and search))
    if beta:
        th0 = th0.copy()
        th0[5] -= th0[1]
        s_th[5] = max(abs(th0[5]), 1e-4 * a2)
    ep0 = spec.ep.astype(float)
    s_ep = []
    logs = []
    lo, hi = [], []
    for p, i, eff in zip(names, idx, own):
        b = eff.bounds(p, ep0[i], chunk, cfg)
        for narrow in (spec.box, bounds or {}):
            if p in narrow:
                b = (max(b[0], narrow[p][0]), min(b[1], narrow[p][1]))
        floor = eff.scale_floor.get(p, 1e-6)
        s = max(abs(ep0[i]), floor)
        if p.startswith("amplitude"):
            s = max(abs(ep0[EP_INDEX["amplitude_sin"]]), abs(ep0[EP_INDEX["amplitude_cos"]]), floor)
        s_ep.append(s)
        ep0[i] = min(max(ep0[i], b[0]), b[1])
        # a parameter whose box lies above zero (a frequency, a damping, a gap, a dead time,
        # a limit, a Stribeck velocity) fitted by its logarithm (cfg.fit_log): a step moves
        # it by a factor, and a Gauss–Newton step cannot leap to the floor of its box, where
        # the effect vanishes and the cost is flat (a Stribeck curve of zero width)
        logs.append(cfg.fit_log and b[0] > 0.0)
        lo.append(math.log(b[0] / s) if logs[-1] else b[0] / s)
        hi.append(math.log(b[1] / s) if logs[-1] else b[1] / s)
    s_ep = np.array(s_ep)
    nb = 8 if fit_base else 0
    logs = np.array(logs, dtype=bool)
    ze = ep0[idx] / s_ep if idx else np.zeros(0)
    ze[logs] = log(ze[logs])
    z0 = np.concatenate([th0[:nb] / s_th[:nb], ze])
    lb = np.concatenate([np.full(nb, -np.inf), lo]) if idx else np.full(nb, -np.inf)
    ub = np.concatenate([np.full(nb, np.inf), hi]) if idx else np.full(nb, np.inf)
    if z0.size == 0:
        return spec.copy()
    z0 = np.minimum(np.maximum(z0, lb), ub)

    def steps(h: float) -> np.ndarray:  # difference step per scaled parameter
        return np.full(nb + len(names), h)

    nsub = sim_substeps(spec, chunk.Ts)
    m = chunk.score
    cols = None if m.all() else np.flatnonzero(m)  # None: every sample, weighted in place
    w = chunk.w if cols is None else chunk.w[cols]
    x_m = chunk.x if cols is None else chunk.x[cols]
    flags = spec.flags()

    def unpack_many(Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # the parameter sets of the rows of Z
        TH = np.repeat(th0[None, :], len(Z), axis=0)
        if nb:
            TH[:] = Z[:, :8] * s_th
            if beta:
                TH[:, 5] += TH[:, 1]
        EP = np.repeat(ep0[None, :], len(Z), axis=0)
        if idx:
            ZE = Z[:, nb:].copy()
            ZE[:, logs] = exp(ZE[:, logs])
            EP[:, idx] = ZE * s_ep
        return TH, EP

    def unpack(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        TH, EP = unpack_many(z[None, :])
        return TH[0], EP[0]

    # multiple-shooting windows: the restart states are estimated per window along the
    # responses of the start's model (held through the fit: they barely move with it)
    restarts = restart_responses(spec, chunk)

    def weighted(y: np.ndarray) -> np.ndarray:
        # in place where every sample is scored: y is the simulation's own array, not read again
        return weighted_rows(y[None, :], cols, x_m, w)[0]

    def resid(z: np.ndarray) -> np.ndarray:
        th, ep = unpack(z)
        r = weighted(simulate_augmented(chunk.x_r, chunk.x, chunk.Ts, th, flags=flags, ep=ep, modes=spec.modes,
                                        starts=chunk.starts, derivs=chunk.derivs, nsub=nsub, warm=chunk.warm))
        return estimated_states(r, spec.effects, ep, spec.modes, chunk, restarts)

    def resid_many(Z: np.ndarray) -> np.ndarray:  # row p is resid(Z[p]), bit for bit
        TH, EP = unpack_many(Z)
        Y = simulate_augmented_many(chunk.x_r, chunk.x, chunk.Ts, TH, EP, flags=flags, modes=spec.modes,
                                    starts=chunk.starts, derivs=chunk.derivs, nsub=nsub, warm=chunk.warm)
        R = weighted_rows(Y, cols, x_m, w)  # element by element as weighted() does
        if restarts is not None:  # estimated_states returns r itself otherwise
            with np.errstate(all="ignore"):  # also in a helper thread (numpy's error state is per thread)
                for r, ep in zip(R, EP):
                    r[:] = estimated_states(r, spec.effects, ep, spec.modes, chunk, restarts)
        return R

    def jac(z: np.ndarray, which: list[int]) -> np.ndarray:  # ∂resid/∂z_j for j in which, exact
        th, ep = unpack(z)
        d_th, d_ep = np.zeros((len(which), 8)), np.zeros((len(which), N_EP))
        for i, j in enumerate(which):  # unpack's linear map, column j
            if j < nb:
                d_th[i, j] = s_th[j]
                if beta and j == 1:
                    d_th[i, 5] = s_th[1]  # b2 = β + a2
            else:
                d_ep[i, idx[j - nb]] = s_ep[j - nb] * (math.exp(z[j]) if logs[j - nb] else 1.0)
        moved = spec.copy()
        moved.theta, moved.ep = th, ep
        return residual_jacobian(moved, chunk, d_th, d_ep, restarts=restarts, nsub=nsub)

    def how(h: float) -> dict:  # the Jacobian of a fit at difference step h
        exact = cfg.exact_fine if h <= cfg.fd_step else cfg.exact_rough
        # the columns simulated together (one lockstep run), and split over two threads
        # (ident.least_squares._jacobian; the kernel runs outside the GIL) only outside a
        # search: the searches run side by side in the diagnosis's two workers, and a split
        # there puts three or four threads on two cores and halves the sets a lockstep run
        # interleaves (bench_diagnosis_speed.py: 0.95x the time unsplit).  The base, reference
        # and final fits may run alone and split theirs.  The same result either way.
        return dict(parallel=not search, resid_many=resid_many, step=steps(h), jac=jac if exact else None)

    with np.errstate(all="ignore"):  # diverging trial steps are expected and rejected
        if secant_nfev > 0:
            fit = secant_lm(resid, z0, lb, ub, max_nfev=secant_nfev, **how(fd_step))
        else:
            fit = bounded_lm(resid, z0, lb, ub, max_iter=max_iter, **how(fd_step))
        # polish: the coarse step stops short of the valley's floor
        if polish and fd_step > cfg.fd_step and secant_nfev <= 0:
            fit = bounded_lm(resid, fit.z, lb, ub, max_iter=max(max_iter // 2, 1), **how(cfg.fd_step))
    z, cost0 = fit.z, fit.cost
    if not np.isfinite(cost0):
        return spec.copy()
    th, ep = unpack(z)
    out = spec.copy()
    out.theta = th
    out.ep = ep
    return out


def _variant(spec: ModelSpec) -> tuple:
    """The valley a start stands for: its variants (``modes``), whether evidence boxed it,
    and the evidence that gave it a base of its own."""
    return tuple(int(m) for m in spec.modes) + (bool(spec.box), spec.origin)


def _best_per_variant(specs: list[ModelSpec], costs: list[float], k: int) -> list[int]:
    """Indices of the cheapest spec of every structural variant, then the cheapest others up to ``k``.

    Variants are different valleys of the cost, and a short fit ranks them unreliably
    against each other (a controller without anti-windup or a semi-closed two-mass drive
    pays only once the base has moved): each keeps its best start.
    """
    order = [i for i in np.argsort(costs) if np.isfinite(costs[i])]
    keep: list[int] = []
    seen: set = set()
    for i in order:
        v = _variant(specs[i])
        if v not in seen:
            seen.add(v)
            keep.append(int(i))
    for i in order:
        if len(keep) >= k:
            break
        if i not in keep:
            keep.append(int(i))
    return keep


def search(base: ModelSpec, effect: str, chunk: Chunk, evidence: dict,
           cfg: DiagnosisConfig, others: tuple[ModelSpec, ...] = ()) -> ModelSpec:
    """``base`` plus ``effect``, fitted by output error on ``chunk`` (the module's four steps).

    ``evidence``: the localisation of :func:`ident.diagnosis.residuals.localise` (spectrum
    peaks, position periodogram) the effect's starts are led by; ``others``: further bases
    to start from (the other controller representation: an effect's valley may exist on
    the sampled controller only, a gap rattling in a digital loop).  Screen and race keep
    the best start of every structural variant (:func:`_best_per_variant`).  Returns the
    model with the lowest weighted training cost found, after the effect's own
    :meth:`~ident.diagnosis.effects.Effect.finish` (a dead time moved to the middle of the
    delays that fit equally well, :func:`centre_delay`; a two-mass mode scanned along its
    ridge of equal locked-motor frequency, :func:`scan_motor_fraction`).
    """
    starts = [s for b in (base,) + tuple(others) for s in EFFECT_MODELS[effect].starts(b, chunk, evidence, cfg)]
    # 2. screen: free-run cost with the base held (diverging starts drop out), on what the
    # race's last round sees
    restart = EFFECT_MODELS[effect].restartable
    held = None if restart else held_force(base, chunk)
    look = race_part(chunk, 1.0, cfg, restart, held)
    costs = [sse(s, look) for s in starts]
    alive = [starts[i] for i in _best_per_variant(starts, costs, cfg.screened_starts)]
    if not alive:
        return base.with_effect(effect)
    # 3. race: joint fits on a growing share of race_seconds of the recording (of all of it
    # when 0), the worse half dropped after each round
    for r, (frac, it) in enumerate(zip(cfg.race_fidelity, cfg.race_iter)):
        part = race_part(chunk, frac, cfg, restart, held)
        nfev = cfg.race_evals[r] if cfg.race_evals else 0
        alive = [fit_spec(s, part, max_iter=it, fd_step=cfg.fd_step_rough, polish=False, secant_nfev=nfev,
                          search=True, cfg=cfg)
                 for s in alive]
        costs = [sse(s, part) for s in alive]
        if r == len(cfg.race_fidelity) - 1 or len(alive) == 1:
            break
        alive = [alive[i] for i in _best_per_variant(alive, costs, max(cfg.joint_starts, len(alive) // 2))]
    # 4. polish the winner on the whole chunk, from its multiple-shooting fit when asked
    best = polish(shoot(alive[int(np.argmin(costs))], chunk, cfg), chunk, cfg)
    return EFFECT_MODELS[effect].finish(best, chunk, cfg)


def held_force(base: ModelSpec, chunk: Chunk) -> np.ndarray:
    """The control-equivalent acceleration u (mm/s²) ``base`` applies at each sample of its
    free run on ``chunk`` (0 where the run is not finite): at a rest, the force its
    integral holds against friction, the state a window restarted there starts in
    (:meth:`Chunk.rest_windows`)."""
    u = np.zeros(chunk.n)
    simulate_spec(base, chunk, u_out=u)
    return np.where(np.isfinite(u), u, 0.0)


def race_part(chunk: Chunk, frac: float, cfg: DiagnosisConfig, restart: bool = True,
              held: np.ndarray | None = None) -> Chunk:
    """What a race round at fidelity ``frac`` fits on: ``frac`` × ``cfg.race_seconds`` of
    windows spread over the whole recording, or the first ``frac`` of every segment
    (:meth:`Chunk.part`; all of it at 1).

    The windows restart mid-move on the recorded state (:meth:`Chunk.windows`) for models
    whose state a restart can read from the recording (``restart``,
    :attr:`Effect.restartable`), else at rests (:meth:`Chunk.rest_windows`, holding the
    force ``held``, see :func:`held_force`); a recording without a rest the recording
    shows is raced on :meth:`Chunk.part`.  Windows only where they cut the work at least
    in half: on a recording barely longer than race_seconds they cost what it costs and
    only add restarts (a 6.8 s LinuxCNC capture lost its 20 µm gap to them).
    """
    if 0 < 2 * cfg.race_seconds <= chunk.n * chunk.Ts:
        if restart:
            return chunk.windows(frac * cfg.race_seconds, cfg.race_window_s, cfg.race_lead_s)
        rested = chunk.rest_windows(frac * cfg.race_seconds, cfg.race_window_s, cfg.rest_restart_s, held)
        if rested is not None:
            return rested
    return chunk.part(frac)


def shoot(spec: ModelSpec, chunk: Chunk, cfg: DiagnosisConfig) -> ModelSpec:
    """``spec`` fitted by multiple shooting: on every scored sample of ``chunk`` in windows of
    ``cfg.shooting_window_s``, each simulated from the recorded state
    (:meth:`Chunk.shots <ident.diagnosis.spec.Chunk.shots>`), ``cfg.shooting_iter``
    iterations of :func:`fit_spec` at the coarse difference step.

    The output-error cost of eq. 3.6 summed over short windows instead of whole segments:
    the error cannot drift in phase over a window, so the cost is smooth where the free
    run's ripples (a lightly damped mode, stick-slip) and a local solve from the race's
    winner reaches the valley the free-run polish (:func:`polish`) then refines.  Returns
    ``spec`` itself when shooting is off (``shooting_window_s`` 0).
    """
    if cfg.shooting_window_s <= 0 or cfg.shooting_iter <= 0:
        return spec
    return fit_spec(spec, chunk.shots(cfg.shooting_window_s, cfg.shooting_lead_s), max_iter=cfg.shooting_iter,
                    fd_step=cfg.fd_step_rough, polish=False, search=True, cfg=cfg)


def polish(spec: ModelSpec, chunk: Chunk, cfg: DiagnosisConfig) -> ModelSpec:
    """A search's winner fitted on the whole ``chunk`` (half of ``cfg.joint_iter``, then the fine step)."""
    return fit_spec(spec, chunk, max_iter=max(cfg.joint_iter // 2, 1), fd_step=cfg.fd_step_rough, search=True,
                    cfg=cfg)


def segment_variance_fit(spec: ModelSpec, chunk: Chunk, cfg: DiagnosisConfig) -> ModelSpec:
    """``spec`` re-fitted by maximum likelihood with a noise variance of each segment's own.

    The search's cost weighs each segment by its tracking error (:func:`make_chunk`), as if
    the model's error were alike everywhere.  Where a segment's response is one no model
    of its kind can follow in phase — a full-closed loop's integrator hunting across a gap
    in the low-speed set, stick-slip in a limit cycle (docs/diagnosis.md, Known limits) — least
    squares shrinks the parameters that make the oscillation (a smaller gap oscillates
    less, wherever its phase), and that bias is set by how much the segment weighs.  The
    Gaussian likelihood with variance σ_seg² per segment weighs each by 1/σ_seg², σ_seg
    the model's own residual there: iteratively reweighted least squares
    (:meth:`Chunk.reweighted`, then ``cfg.segment_variance_iter`` iterations of
    :func:`fit_spec`), until no segment's weight moves by more than
    ``cfg.segment_variance_tol`` or after ``cfg.segment_variance_steps`` re-weightings.
    The first fit is always made, so ``spec`` is fitted on ``chunk`` even where it has one
    segment (one variance: the weights of the search).  A gap is then profiled under the
    last weights (:func:`profile_gap`), and with ``cfg.estimate_exact`` the model is
    polished there with exact Jacobians (:func:`~ident.diagnosis.spec.residual_jacobian`):
    the differences' steps stop where the difference quotient stops telling the slope, the
    exact slope goes on to the stationary point of the cost the estimate and its intervals
    (:mod:`ident.diagnosis.intervals`) stand for.
    """
    fitted_on = chunk  # the weights of the last fit
    for step in range(cfg.segment_variance_steps):
        weighted = chunk.reweighted(simulate_spec(spec, chunk) - chunk.x)
        if step and np.max(np.abs(weighted.w / fitted_on.w - 1.0)) < cfg.segment_variance_tol:
            break
        spec, fitted_on = fit_spec(spec, weighted, max_iter=cfg.segment_variance_iter, cfg=cfg), weighted
    spec = profile_gap(spec, fitted_on, cfg)
    if cfg.estimate_exact:
        # the floor of the valley the differences found: a local fit only goes downhill, so
        # the polish keeps what the differences reached (on a two-mass gap, exact slopes
        # from the search's point instead stopped in a ripple of the hunting's cost)
        exact = replace(cfg, exact_fine=True, exact_rough=True, fit_log=True)
        spec = fit_spec(spec, fitted_on, max_iter=cfg.segment_variance_iter, cfg=exact)
    return spec


def profile_gap(spec: ModelSpec, chunk: Chunk, cfg: DiagnosisConfig) -> ModelSpec:
    """``spec``'s backlash gap moved to the lowest point of the cost's profile over it.

    Over the gap the output-error cost (eq. 3.6) is rippled on the fine scale — every
    contact event of the free run falls on a sub-step boundary that moves with the gap —
    so a local fit at a difference step stops in a ripple short of the valley's floor
    (drive-zoo-dev2 case_023: the cost with the gap held at the labelled 20 µm and the rest
    re-fitted is 0.68 × that of the search's 21 µm, ``benchmarks/bench_gap_profile.py``).
    The profile: the gap held at each of ``cfg.gap_profile_ratios`` × the fitted one, every
    other parameter re-fitted (``cfg.gap_profile_iter`` iterations); from the cheapest point,
    if cheaper than ``spec``, the gap is released and fitted again, and that model returned
    when it still costs less than ``spec``.  ``spec`` itself when it holds no gap or the
    profile finds nothing lower.
    """
    k = EP_INDEX["gap_mm"]
    g_hat = float(spec.ep[k])
    if "backlash" not in spec.effects or not g_hat > 0.0 or not cfg.gap_profile_ratios:
        return spec
    c_spec = sse(spec, chunk)
    best = fit_spec(spec, chunk, max_iter=cfg.gap_profile_iter, cfg=cfg)
    c_best = sse(best, chunk)
    for r in cfg.gap_profile_ratios:
        s0 = best.copy()
        g = r * g_hat
        s0.ep[k] = g
        s1 = fit_spec(s0, chunk, max_iter=cfg.gap_profile_iter, bounds={"gap_mm": (0.999 * g, 1.001 * g)},
                      cfg=cfg)
        c1 = sse(s1, chunk)
        if c1 < c_best:
            best, c_best = s1, c1
    free = fit_spec(best, chunk, max_iter=cfg.gap_profile_iter, cfg=cfg)
    c_free = sse(free, chunk)
    if c_free <= c_best:
        best, c_best = free, c_free
    return best if c_best < c_spec else spec


def centre_delay(spec: ModelSpec, chunk: Chunk, cfg: DiagnosisConfig) -> ModelSpec:
    """``spec``'s dead time moved to the middle of the delays that fit equally well.

    A capture delay on a stiff loop (P-PI) is weakly determined: a shorter trial delay is
    made up by a slower loop, so the profile of the training cost over the delay (base
    re-fitted at each) is flat below the truth up to a cliff a little above it, where no
    causal loop can take the surplus back.  Its minimum then lies anywhere in the flat
    part (seed 10 004: 0.59 × the truth, 0.3 % below the cost at the truth).  The edges of
    the interval where the cost stays within ``cfg.delay_profile_tol`` of the lowest seen are searched on
    both sides of the fitted delay (``cfg.delay_scan_range``); the returned model has the
    delay at the middle of that interval (base re-fitted there, the delay then held by
    :func:`fit_spec`) and the interval in ``ranges["delay_s"]``.  On a sharp profile (a
    PID loop, an actuation delay) the first step either way is outside: the interval is
    that step wide and the delay stays where the fit put it.
    """
    k = EP_INDEX["delay_s"]
    d_hat = float(spec.ep[k])
    if "time_delay" not in spec.effects or not d_hat > 0.0:
        return spec
    tol = cfg.delay_profile_tol
    iters = cfg.delay_profile_iter
    fits: dict[float, tuple[float, ModelSpec]] = {1.0: (sse(spec, chunk), spec)}

    def inside(r: float) -> bool:
        if r not in fits:
            near = min(fits, key=lambda q: abs(q - r))  # warm start from the nearest profile point
            s0 = fits[near][1].copy()
            s0.ep[k] = r * d_hat
            s1 = (fit_spec(s0, chunk, fit_effects=False, max_iter=iters, secant_nfev=cfg.delay_profile_evals, cfg=cfg)
                  if np.isfinite(sse(s0, chunk)) else s0)
            fits[r] = (sse(s1, chunk), s1)
        return fits[r][0] <= (1.0 + tol) * min(v for v, _ in fits.values())

    edges = []
    for far, sign in ((cfg.delay_scan_range[1], 1.0), (cfg.delay_scan_range[0], -1.0)):
        r_in, r_out = 1.0, 1.0 + sign * cfg.delay_scan_step
        if inside(r_out):
            r_in, r_out = r_out, far
            if inside(far):
                r_in = far
            else:
                for _ in range(cfg.delay_bisections):
                    r = round(0.5 * (r_in + r_out), 6)
                    if inside(r):
                        r_in = r
                    else:
                        r_out = r
        edges.append(r_in)
    hi, lo = edges
    c_min = min(v for v, _ in fits.values())
    if fits[1.0][0] > (1.0 + tol) * c_min:  # a better fit was found on the way: edges around it
        ok = [r for r, (v, _) in fits.items() if v <= (1.0 + tol) * c_min]
        lo, hi = min(ok), max(ok)
    r_mid = round(0.5 * (lo + hi), 6)
    inside(r_mid)
    out = fits[r_mid][1].copy()
    out.ranges["delay_s"] = (lo * d_hat, hi * d_hat)
    return out


def scan_motor_fraction(spec: ModelSpec, chunk: Chunk, cfg: DiagnosisConfig) -> ModelSpec:
    """``spec``'s two-mass mode moved along its ridge to the motor share that fits best.

    With the velocity loop holding the motor, a recording shows the table ringing on the
    spring at the locked-motor frequency f·√μ (f the free-free mode, μ the motor's share
    of the inertia); f and μ trade along that curve, a narrow curved valley a local fit
    creeps along and stops in wherever it entered it (independent bench, tuning seed
    s1002.0: a 24 Hz mode fitted at 34 Hz from the start at μ = 0.8; scanned, 25 Hz).  The
    identifiable quantity is f·√μ; the scan finds f where the data say where on the ridge
    the drive lies, and moves nothing where they do not.  The scan: for every
    μ of ``cfg.mode_share_grid`` not within 0.1 of the fitted one, f = f·√μ̂/√μ, the base
    and the mode re-fitted with μ held for ``cfg.mode_scan_iter`` iterations on the race's
    windows; the cheapest point there, polished on ``chunk`` with μ free, replaces
    ``spec`` if it fits ``chunk`` better and is still a lightly damped mode when ``spec``
    was one.
    """
    if "resonance" not in spec.effects or not spec.modes[MODE_SLOTS["resonance"]]:
        return spec
    i_f, i_mu = EP_INDEX["freq_hz"], EP_INDEX["motor_fraction"]
    f_hat, mu_hat = float(spec.ep[i_f]), float(spec.ep[i_mu])
    look = race_part(chunk, 1.0, cfg)
    best, c_best = spec, sse(spec, look)
    # a point where the fit leaves the definition of a mode (Effect.implausible) is not the
    # mode moved along its ridge: the scan keeps the fit a resonance when it was one
    plausible = not EFFECT_MODELS["resonance"].implausible(spec, chunk, cfg)

    def meant(s: ModelSpec) -> bool:
        return not (plausible and EFFECT_MODELS["resonance"].implausible(s, chunk, cfg))

    for mu in cfg.mode_share_grid:
        if abs(mu - mu_hat) < 0.1:
            continue
        s0 = spec.copy()
        s0.ep[i_mu] = mu
        s0.ep[i_f] = f_hat * math.sqrt(mu_hat / mu)
        s0.box = {k: v for k, v in spec.box.items() if k != "freq_hz"}  # the ridge leaves a peak's band
        s1 = fit_spec(s0, look, max_iter=cfg.mode_scan_iter, fd_step=cfg.fd_step_rough, polish=False,
                      bounds={"motor_fraction": (0.999 * mu, 1.001 * mu)}, search=True, cfg=cfg)
        c1 = sse(s1, look)
        if c1 < c_best and meant(s1):
            best, c_best = s1, c1
    if best is spec:
        return spec
    best = polish(best, chunk, cfg)
    return best if sse(best, chunk) < sse(spec, chunk) and meant(best) else spec


def chunk_regression(chunk: Chunk, shift: int = 0) -> Regression | None:
    """The regression of eq. 3.11 on ``chunk`` (standstill rows kept), or None.

    ``shift``: of the command, samples (:func:`ident.preprocessing.shift_command`; −m pairs
    the recorded position with the command m samples earlier: the regression of a drive
    whose position is captured m samples late).  None when it cannot be built (too few
    samples, no motion): no regression start then.
    """
    from core.errors import RapidIdentError
    from ident.regression import build_regression

    seg = np.cumsum(chunk.starts) - 1
    try:
        return build_regression(chunk.x_r, chunk.x, chunk.Ts, seg, shift=shift, standstill="hold")
    except RapidIdentError:
        return None


def delayed_regression_start(chunk: Chunk, m: int, reg: Regression | None = None) -> ModelSpec | None:
    """Base parameters of eq. 3.3 from the regression of eq. 3.11 with an actuation delay of m samples.

    With ``u(t − τ) = ẍ(t) + d(ẋ(t))`` (τ = m·Ts) the rows of eq. 3.11 at sample k pair
    e_i, ẋ, x_r, ẋ_r, ẍ_r at k with ẍ and the friction direction at k + m; solved
    unconstrained (:func:`ident.regression.lstsq_scaled`), θ of eq. 3.10 scaled back by
    a2 = 1/α_2.  ``reg``: :func:`chunk_regression` of ``chunk``, built here when not given
    (build it once for several m).  None when the regression cannot be built or gives α_2 ≤ 0.
    """
    from ident.regression import lstsq_scaled

    if reg is None:
        reg = chunk_regression(chunk)
        if reg is None:
            return None
    Phi, idx = reg.Phi, reg.index
    row_of = np.full(chunk.n + m + 1, -1)
    row_of[idx] = np.arange(idx.size)
    later = row_of[idx + m]
    ok = later >= 0
    if np.count_nonzero(ok) < 50:
        return None
    P = Phi[ok].copy()
    P[:, [2, 6, 7]] = Phi[later[ok]][:, [2, 6, 7]]  # −ẍ, −PV, −NV at k + m
    th, _cost = lstsq_scaled(P, reg.Y[ok])
    alpha_i, alpha_1, alpha_2, beta_0, beta_1, beta_2, d_plus, d_minus = th
    if not alpha_2 > 0:
        return None
    a2 = 1.0 / alpha_2
    return ModelSpec(np.array([alpha_1, 1.0, alpha_i, beta_2, beta_1, beta_0, d_plus, d_minus]) * a2)


def sampled_base(spec: ModelSpec, chunk: Chunk, max_iter: int = 30, causal: bool = False, *,
                 cfg: DiagnosisConfig) -> ModelSpec:
    """``spec`` on the sampled controller (u computed every Ts and held), base re-fitted.

    ``causal``: the feed-forward takes the command's derivatives by backward differences,
    as a drive that sees only the commands received so far (``modes[4] = 2``, see
    :mod:`ident.diagnosis.augmented`); otherwise as an interpolator hands them over.
    Started from :func:`softened_base` when the continuous base is stiff (a pole beyond
    1/Ts would make the sampled loop unstable).
    """
    s = softened_base(spec, chunk.Ts) or spec.copy()
    s.modes[MODE_SLOTS["controller"]] = 2 if causal else 1
    return refit_base(s, chunk, max_iter, cfg=cfg)


def refit_base(spec: ModelSpec, chunk: Chunk, max_iter: int = 30, *, cfg: DiagnosisConfig) -> ModelSpec:
    """The base parameters of ``spec`` re-fitted in free run on ``chunk``, twice: the restart
    re-scales the parameters after the first long move.  Effect parameters are held."""
    return fit_spec(fit_spec(spec, chunk, fit_effects=False, max_iter=max_iter, cfg=cfg), chunk, fit_effects=False,
                    max_iter=max_iter, cfg=cfg)


def base_variants(spec: ModelSpec, chunk: Chunk, pool=None, *, cfg: DiagnosisConfig) -> list[ModelSpec]:
    """The base model on every control law of :data:`~ident.diagnosis.augmented.CONTROLLERS`,
    best training fit first.

    ``spec`` itself (continuous, eq. 3.3 as written) and the sampled law re-fitted with the
    feed-forward's command derivatives handed over ahead (central differences, an
    interpolator's) and taken causally (backward differences, a drive's own): which a drive
    uses is not known from outside, and the wrong one leaves a lag of half a sample to a
    sample on every move that a dead time or a mode would otherwise take up.  ``pool``
    (an executor) fits the two sampled forms side by side.
    """
    fitted = (pool.map if pool is not None else map)(lambda c: sampled_base(spec, chunk, causal=c, cfg=cfg),
                                                     (False, True))
    return sorted([spec, *fitted], key=lambda s: sse(s, chunk))


def softened_base(spec: ModelSpec, Ts: float, pole_ts: float = 0.15, force: bool = False) -> ModelSpec | None:
    """``spec`` with its two faster closed-loop poles moved to a double pole at −pole_ts/Ts (1/s).

    Unless ``force``, only when the fastest pole of s³ + a1·s² + a2·s + a3 (eq. 3.3) lies
    beyond 1/Ts — a degenerate, stiff base model; None otherwise.  The slowest pole is
    kept; b1 scales with a1, b2 and the friction d0, d1 with a2, so feed-forward and static
    ratios are kept.  The free-run cost of eq. 3.3 has several valleys (an integrator
    nearly cancelled, a stiff pole absorbing a lost motion …); this is a second start.
    """
    th = spec.theta
    try:
        r = np.roots([1.0, th[0], th[1], th[2]])
    except (np.linalg.LinAlgError, ValueError):
        return None
    if not np.all(np.isfinite(r)) or th[0] == 0.0 or th[1] == 0.0:
        return None
    if not force and np.max(np.abs(r)) <= 1.0 / Ts:
        return None
    slow = r[np.argmin(np.abs(r))].real
    c = np.real(np.poly([slow, -pole_ts / Ts, -pole_ts / Ts]))
    out = spec.copy()
    t = out.theta
    t[4] = th[4] * c[1] / th[0]
    t[5] = th[5] * c[2] / th[1]
    t[6:8] = th[6:8] * c[2] / th[1]
    t[0:3] = c[1:]
    return out

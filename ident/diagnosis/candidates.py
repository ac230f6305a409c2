"""Candidate explanations: fit the augmented model with one (or more) effects by output error.

For each effect of SPEC §7 (see :mod:`ident.diagnosis.augmented`):

1. starting points on a coarse grid of the effect's main nonlinear parameter and variant,
   led by the localisation (residual spectrum peaks for a resonance, the position
   periodogram for a cyclic error, percentiles of |u| for a saturation), see
   :func:`start_groups`;
2. from each, a short fit of the base parameters with the effect held (a profile of the
   cost over the effect's parameter: the base model identified without the effect has
   adapted to it and must move back before the effect pays);
3. from the best, the joint output-error fit of base and effect parameters (bounded
   Levenberg–Marquardt, objective eq. 3.6 on the free-run simulation, weighted per segment);
4. for some effects a second family of starts, the better training fit kept: backlash from
   a softened base when the given one is stiff (:func:`softened_base`), backlash, resonance
   and dead time on the sampled controller (:func:`sampled_base`; the delay by its profile,
   :func:`fit_delay_profile`); backlash on the sampled controller and Stribeck friction
   also with a coarse difference step (:data:`FD_STEP_ROUGH`), their costs being rough on
   the scale of the fine one.

Every fit works in scaled coordinates ``z = p / s`` (s = |start| or a floor) so one finite-
difference step suits parameters as different as a3 ≈ 1e6 1/s³ and b0 ≈ 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ident.diagnosis.augmented import (
    CONTACT_HZ,
    EFFECTS,
    EP_INDEX,
    N_EP,
    command_derivatives,
    simulate_augmented,
    substeps,
)
from ident.diagnosis.residuals import peak_in_band
from ident.least_squares import bounded_lm

if TYPE_CHECKING:
    from ident.regression import Regression

__all__ = ["Chunk", "ModelSpec", "make_chunk", "simulate_spec", "residual", "sse", "fit_spec", "start_groups",
           "fit_effect", "fit_delay_profile", "sampled_base", "softened_base", "effect_parameters", "PARAM_COUNT",
           "fit_resonance_at_peaks", "resonance_at_peak", "resonance_signature", "chunk_regression",
           "delayed_regression_start", "centre_delay"]

#: Parameters each effect adds (counted for the acceptance penalty).
PARAM_COUNT = {
    "backlash": 2,
    "stribeck": 2,
    "resonance": 3,
    "time_delay": 1,
    "cyclic_error": 3,
    "saturation": 1,
}
_FREE = {
    "backlash": ["gap_mm", "motor_fraction"],
    "stribeck": ["static_to_coulomb_ratio", "stribeck_velocity_mm_s"],
    "resonance": ["freq_hz", "damping", "gain", "motor_fraction"],
    "time_delay": ["delay_s"],
    "cyclic_error": ["period_mm", "amplitude_sin", "amplitude_cos"],
    "saturation": ["limit"],
}
_MODE_SLOT = {"backlash": 0, "time_delay": 1, "cyclic_error": 2, "resonance": 3}
#: Recordings longer than this (s) get the shorter searches, to keep the diagnosis within its
#: time budget: one hold-out fold and one second effect (diagnose), short delay profiles (here).
LONG_S = 10.0
#: Base re-fit iterations at each point of a delay profile (fewer on a long recording).
PROFILE_ITER, PROFILE_ITER_LONG = 25, 8
#: Starting gaps of the backlash fit, mm (one profile start each, in every variant).
BACKLASH_GAPS_MM = (0.003, 0.01, 0.02, 0.04, 0.08)


@dataclass
class Chunk:
    """Samples a model is simulated on, and which of them count in the objective.

    x_r, x : commanded and recorded actual position, mm; starts : first sample of each
    segment (the simulation restarts there); derivs : commanded velocity (mm/s) and
    acceleration (mm/s²); w : weight of each sample (1/√ of its segment's tracking-error
    rms, so the low-speed set is heard next to the high-speed set); score : samples in the
    objective — the free run always covers every sample, so held-out samples are simply
    left out of ``score`` (the first ``skip_s`` after each restart never count).
    """

    x_r: np.ndarray
    x: np.ndarray
    Ts: float
    starts: np.ndarray
    derivs: tuple[np.ndarray, np.ndarray]
    w: np.ndarray
    score: np.ndarray

    @property
    def n(self) -> int:
        return int(self.x_r.size)

    @property
    def long(self) -> bool:
        """Longer than :data:`LONG_S`: the shorter searches (time budget)."""
        return self.n * self.Ts > LONG_S

    def scored(self, mask: np.ndarray) -> "Chunk":
        """The same samples with only ``mask`` (and not the restart transients) scored."""
        return Chunk(self.x_r, self.x, self.Ts, self.starts, self.derivs, self.w, self.score & mask)


def make_chunk(x_r: np.ndarray, x: np.ndarray, Ts: float, starts: np.ndarray, skip_s: float = 0.02) -> Chunk:
    """A :class:`Chunk` from arrays (mm) and a start mask; derivatives taken inside segments."""
    x_r = np.ascontiguousarray(x_r, dtype=float)
    x = np.ascontiguousarray(x, dtype=float)
    starts = np.ascontiguousarray(starts, dtype=np.bool_)
    derivs = command_derivatives(x_r, Ts, starts)
    score = np.ones(x_r.size, dtype=bool)
    k_skip = int(round(skip_s / Ts))
    for s in np.flatnonzero(starts):
        score[s : s + k_skip] = False
    if not np.any(score):
        score[:] = True
    e = x_r - x
    rms_all = float(np.std(e)) or 1.0
    w = np.ones(x_r.size)
    bounds = np.append(np.flatnonzero(starts), x_r.size)
    for a, b in zip(bounds[:-1], bounds[1:]):
        rms = float(np.std(e[a:b]))
        w[a:b] = np.sqrt(rms_all / max(rms, 1e-3 * rms_all))
    return Chunk(x_r, x, float(Ts), starts, derivs, w, score)


@dataclass
class ModelSpec:
    """Base parameters θ (eq. 3.3), effect flags/parameters/variants of the augmented model."""

    theta: np.ndarray
    effects: tuple[str, ...] = ()
    ep: np.ndarray = field(default_factory=lambda: np.zeros(N_EP))
    modes: np.ndarray = field(default_factory=lambda: np.zeros(5, dtype=np.int64))
    #: effect parameters the recording leaves open: name → (low, high) of the values that fit
    #: equally well (:func:`centre_delay`)
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)

    def flags(self) -> np.ndarray:
        return np.array([1 if e in self.effects else 0 for e in EFFECTS], dtype=np.int64)

    def copy(self) -> "ModelSpec":
        return ModelSpec(self.theta.copy(), tuple(self.effects), self.ep.copy(), self.modes.copy(),
                         dict(self.ranges))


def simulate_spec(spec: ModelSpec, chunk: Chunk, nsub: int | None = None) -> np.ndarray:
    """Free-run recorded position (mm) of ``spec`` on ``chunk``."""
    return simulate_augmented(
        chunk.x_r,
        chunk.x,
        chunk.Ts,
        spec.theta,
        flags=spec.flags(),
        ep=spec.ep,
        modes=spec.modes,
        starts=chunk.starts,
        derivs=chunk.derivs,
        nsub=nsub,
    )


def residual(spec: ModelSpec, chunk: Chunk, mask: np.ndarray | None = None) -> np.ndarray:
    """Weighted free-run residual w·(x̂ − x) on ``mask`` (default the scored samples), mm."""
    m = chunk.score if mask is None else mask
    return chunk.w[m] * (simulate_spec(spec, chunk)[m] - chunk.x[m])


def sse(spec: ModelSpec, chunk: Chunk, mask: np.ndarray | None = None) -> float:
    """Weighted sum of squared free-run residuals, mm² (inf when the simulation diverges)."""
    r = residual(spec, chunk, mask)
    with np.errstate(all="ignore"):
        v = float(r @ r)
    return v if np.isfinite(v) else float("inf")


def _nsub(spec: ModelSpec, Ts: float) -> int:
    f = spec.ep[EP_INDEX["freq_hz"]] if "resonance" in spec.effects else 0.0
    if "backlash" in spec.effects and spec.modes[0] == 1 and not ("resonance" in spec.effects and spec.modes[3] == 1):
        f = max(f, CONTACT_HZ)
    return substeps(spec.theta, Ts, 1.5 * f)


#: Forward-difference step of the output-error fit, in scaled units (relative to the start).
FD_STEP = 1e-3
#: A coarser step for the fits of effects that make the free-run cost rough: contact and
#: stick events land on sub-step boundaries, so the cost ripples on the 0.1 % scale and a
#: difference that fine reads the ripple, not the slope (backlash is fitted with both).
FD_STEP_ROUGH = 1e-2
#: Per-parameter steps that hold whatever the base step: over the gap the cost is a parabola
#: with ±20 % ripple at 0.1 % steps; with 0.1 % differences the gap never moves from its start.
_FD_STEPS = {"gap_mm": 0.03}


def _bounds(name: str, p0: float, chunk: Chunk) -> tuple[float, float]:
    Ts = chunk.Ts
    vmax = float(np.max(np.abs(chunk.derivs[0]))) or 1.0
    amax = float(np.max(np.abs(chunk.derivs[1]))) or 1.0
    return {
        "gap_mm": (0.0, 1.0),
        "static_to_coulomb_ratio": (1.0, 20.0),
        "stribeck_velocity_mm_s": (1e-4, vmax),
        "freq_hz": (0.5, 0.45 / Ts),
        "damping": (0.002, 1.5),
        "gain": (-5.0, 5.0),
        "delay_s": (0.0, 0.1),
        "period_mm": (0.7 * p0, 1.4 * p0),
        "amplitude_sin": (-np.inf, np.inf),
        "amplitude_cos": (-np.inf, np.inf),
        "limit": (1e-3 * amax, 100.0 * amax),
        "motor_fraction": (0.2, 0.98),
        "position_motor_share": (0.0, 1.0),
    }[name]


def fit_spec(spec: ModelSpec, chunk: Chunk, *, fit_base: bool = True, fit_effects: bool = True,
             max_iter: int = 25, bounds: dict[str, tuple[float, float]] | None = None,
             fd_step: float = FD_STEP) -> ModelSpec:
    """Output-error fit (eq. 3.6 on the free-run simulation) of base and effect parameters.

    Starts from ``spec``; base parameters move jointly with the effects' parameters when
    ``fit_base``; ``bounds`` narrows the box of named effect parameters; parameters named in
    ``spec.ranges`` (weakly determined, centred by :func:`centre_delay`) are held.  ``fd_step``: the
    forward-difference step (scaled units; the gap always takes its own, coarser one); a
    step coarser than :data:`FD_STEP` is followed by a polish at the fine step (half the
    iterations).  Returns the fitted copy; a fit that fails to improve returns ``spec``.
    """
    # a parameter with a range in ``spec.ranges`` stays at the middle it was put in
    names = [p for e in spec.effects for p in _FREE[e] if p not in spec.ranges] if fit_effects else []
    idx = [EP_INDEX[p] for p in names]
    th0 = spec.theta.astype(float)
    a2 = abs(th0[1]) or 1.0
    a1 = abs(th0[0]) or 1.0
    floors = np.array([1.0, 1.0, 1.0, 0.05, 0.01 * a1, 0.01 * a2, 1e-4 * a2, 1e-4 * a2])
    s_th = np.maximum(np.abs(th0), floors)
    ep0 = spec.ep.astype(float)
    s_ep = []
    lo, hi = [], []
    for p, i in zip(names, idx):
        b = _bounds(p, ep0[i], chunk)
        if bounds and p in bounds:
            b = (max(b[0], bounds[p][0]), min(b[1], bounds[p][1]))
        floor = {"amplitude_sin": 1e-4, "amplitude_cos": 1e-4, "gain": 0.1, "delay_s": 1e-3,
                 "gap_mm": 1e-3, "stribeck_velocity_mm_s": 0.1,
                 "position_motor_share": 0.1}.get(p, 1e-6)
        s = max(abs(ep0[i]), floor)
        if p.startswith("amplitude"):
            s = max(abs(ep0[EP_INDEX["amplitude_sin"]]), abs(ep0[EP_INDEX["amplitude_cos"]]), floor)
        s_ep.append(s)
        lo.append(b[0] / s)
        hi.append(b[1] / s)
        ep0[i] = min(max(ep0[i], b[0]), b[1])
    s_ep = np.array(s_ep)
    nb = 8 if fit_base else 0
    z0 = np.concatenate([th0[:nb] / s_th[:nb], ep0[idx] / s_ep if idx else []])
    lb = np.concatenate([np.full(nb, -np.inf), lo]) if idx else np.full(nb, -np.inf)
    ub = np.concatenate([np.full(nb, np.inf), hi]) if idx else np.full(nb, np.inf)
    if z0.size == 0:
        return spec.copy()
    z0 = np.minimum(np.maximum(z0, lb), ub)

    def steps(h: float) -> np.ndarray:  # difference step per scaled parameter
        return np.concatenate([np.full(nb, h), [_FD_STEPS.get(p, h) for p in names]])

    nsub = _nsub(spec, chunk.Ts)
    m = chunk.score
    w = chunk.w[m]
    flags = spec.flags()

    def unpack(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        th = th0.copy()
        if nb:
            th[:] = z[:8] * s_th
        ep = ep0.copy()
        if idx:
            ep[idx] = z[nb:] * s_ep
        return th, ep

    def resid(z: np.ndarray) -> np.ndarray:
        th, ep = unpack(z)
        y = simulate_augmented(chunk.x_r, chunk.x, chunk.Ts, th, flags=flags, ep=ep, modes=spec.modes,
                               starts=chunk.starts, derivs=chunk.derivs, nsub=nsub)
        r = w * (y[m] - chunk.x[m])
        if not np.all(np.isfinite(r)):
            return np.full(r.size, 1e3)
        return r

    with np.errstate(all="ignore"):  # diverging trial steps are expected and rejected
        fit = bounded_lm(resid, z0, lb, ub, max_iter=max_iter, step=steps(fd_step))
        if fd_step > FD_STEP:  # polish: the coarse step stops short of the valley's floor
            fit = bounded_lm(resid, fit.z, lb, ub, max_iter=max(max_iter // 2, 1), step=steps(FD_STEP))
    z, cost0 = fit.z, fit.cost
    if not np.isfinite(cost0):
        return spec.copy()
    th, ep = unpack(z)
    out = spec.copy()
    out.theta = th
    out.ep = ep
    return out


def _backlash_start(spec: ModelSpec, params: dict, modes: dict) -> ModelSpec:
    """``spec`` plus a backlash gap, its friction given back what the gap explains.

    With the motor leading the table by half the gap in steady motion, a position term that
    reads the motor in part (share ψ) sees an offset ``a2·ψ·g/2`` against the direction of
    motion: a base model fitted without the gap has taken it as Coulomb friction (on a P-PI
    drive often more than the friction itself).  Started without this correction the gap
    pays only after a long walk of d0, d1, and the fit stops at a smaller gap.
    """
    s = _apply(spec, "backlash", params, modes)
    if modes.get("backlash") == 1:
        shift = s.theta[1] * params.get("position_motor_share", 0.0) * 0.5 * params["gap_mm"]
        s.theta[6] -= shift
        s.theta[7] += shift
    return s


def cascade_motor_share(theta: np.ndarray) -> float:
    """ψ, the share of the position feedback that reads the motor, implied by θ of eq. 3.3.

    A P-PI cascade (position gain Kp, velocity loop Kv + Ki/s on the motor) gives
    ``u = Kv·Kp·(x_r − x_table) + Ki·Kp·∫(x_r − x_table) − Kv·ẋ − Ki·x_motor``: the position
    term a2 = Kv·Kp + Ki reads the table with the command's gain b2 = Kv·Kp (θ[5]) and the
    motor with the rest, ψ = 1 − b2/a2 (Table 3.3: 0.82).  A PID on the scale has b2 = a2, ψ = 0.
    Velocity feed-forward Kv in the cascade adds Kp·Kv·Ki to b2: ψ then comes out low.
    """
    a2, b2 = float(theta[1]), float(theta[5])
    return float(np.clip(1.0 - b2 / a2, 0.0, 1.0)) if a2 > 0.0 else 0.0


def _apply(spec: ModelSpec, effect: str, params: dict, modes: dict) -> ModelSpec:
    s = spec.copy()
    s.effects = tuple(dict.fromkeys(spec.effects + (effect,)))
    for k, v in params.items():
        s.ep[EP_INDEX[k]] = v
    for k, v in modes.items():
        s.modes[_MODE_SLOT[k]] = v
    return s


def start_groups(spec: ModelSpec, effect: str, chunk: Chunk, evidence: dict) -> list[list[ModelSpec]]:
    """Starting points for ``effect`` on top of ``spec``, grouped by its main parameter.

    Each group holds the variants for one value of the effect's main nonlinear parameter
    (gap, static ratio, frequency, delay, period, limit); the best of a group (base held)
    is refined jointly with the base parameters for a few iterations before the groups are
    compared — the base model identified without the effect has adapted to it, so the
    effect only pays once the base parameters move back.  ``evidence`` is the localisation
    of :func:`ident.diagnosis.residuals.localise` (spectrum peaks, position period).
    """
    Ts = chunk.Ts
    vmax = float(np.max(np.abs(chunk.derivs[0]))) or 1.0
    groups: list[list[tuple[dict, dict]]] = []
    if effect == "backlash":
        # mode 1 with the position term's motor share ψ that θ implies (0 for a PID on the
        # scale, ≈ 0.8 for a P-PI cascade, whose velocity integral is the motor position; a
        # second family at the other value ended within 1 % of the training cost with the
        # P-PI gap 30 % small).  Mode 0 (loop closed on the motor, the table recorded) is not
        # started: a controller records the position it controls, and a dead band on the
        # output alone mimics stick-slip at reversals
        for g in BACKLASH_GAPS_MM:
            groups.append([({"gap_mm": g, "motor_fraction": 0.8, "position_motor_share": psi}, {"backlash": 1})
                           for psi in (cascade_motor_share(spec.theta),)])
        return [[_backlash_start(spec, p, m) for p, m in g] for g in groups]
    elif effect == "stribeck":
        for r in (1.5, 3.0):
            groups.append([({"static_to_coulomb_ratio": r, "stribeck_velocity_mm_s": v}, {})
                           for v in (0.2, 1.0, 0.02 * vmax)])
    elif effect == "resonance":
        # the residual's spectrum peaks first, then a log grid over the band machine-tool modes
        # occupy (10 Hz up to 0.3/Ts): a mode near the loop bandwidth shows lower in closed loop
        fs = [p["freq_hz"] for p in evidence.get("spectrum_peaks", [])[:2] if p["freq_hz"] > MIN_MODE_HZ]
        for f in list(np.geomspace(10.0, 0.3 / Ts, 4)):
            if all(abs(np.log(f / c)) > 0.2 for c in fs):
                fs.append(float(f))
        for f in fs:
            groups.append([({"freq_hz": f, "damping": 0.05, "gain": 1.0, "motor_fraction": 0.8}, {"resonance": 0})]
                          + [({"freq_hz": f, "damping": 0.3, "gain": 1.0, "motor_fraction": 0.8,
                               "position_motor_share": psi}, {"resonance": 1}) for psi in (0.0, 0.8)])
    elif effect == "time_delay":
        for d in (0.7, 1.5, 3.0, 6.0):
            groups.append([({"delay_s": d * Ts}, {"time_delay": mode}) for mode in (0, 1)])
    elif effect == "cyclic_error":
        per = evidence.get("position_periodic", {})
        pg = evidence.get("position_periodogram_")
        cands: list[float] = []
        if pg is not None:
            periods, share = pg
            for i in np.argsort(share)[::-1]:
                if all(abs(np.log(periods[i] / c)) > 0.1 for c in cands):
                    cands.append(float(periods[i]))
                if len(cands) >= 3:
                    break
        if not cands:
            cands = [per.get("period_mm") or 1.0]
        amp = max(per.get("amplitude_mm", 0.0), 1e-4)
        a2 = abs(spec.theta[1]) or 1.0
        for P in cands:
            phases = (0.0, 0.5 * np.pi, np.pi, 1.5 * np.pi)
            groups.append([({"period_mm": P, "amplitude_sin": amp * np.cos(ph), "amplitude_cos": amp * np.sin(ph)},
                            {"cyclic_error": 0}) for ph in phases])
            groups.append([({"period_mm": P, "amplitude_sin": a2 * amp * np.cos(ph),
                             "amplitude_cos": a2 * amp * np.sin(ph)}, {"cyclic_error": 1}) for ph in phases])
    elif effect == "saturation":
        u = np.empty(chunk.n)
        simulate_augmented(chunk.x_r, chunk.x, chunk.Ts, spec.theta, flags=spec.flags(), ep=spec.ep,
                           modes=spec.modes, starts=chunk.starts, derivs=chunk.derivs, u_out=u)
        au = np.abs(u[np.isfinite(u)])
        for q in (99.9, 99.0, 96.0):
            # ψ: the share of the position term that is the (frozen-when-saturated) integral of
            # the motor velocity — 0 for a PID, ≈ 0.8 for a P-PI cascade
            groups.append([({"limit": float(np.percentile(au, q)), "position_motor_share": psi}, {})
                           for psi in (0.0, 0.8)])
    else:
        raise ValueError(f"unknown effect {effect!r}")
    return [[_apply(spec, effect, p, m) for p, m in g] for g in groups]


#: Backlash: restarts of the best fit with its velocity gain a1 (and b1) raised by these factors.
VELOCITY_GAIN_RESTARTS = (1.25, 1.5)


def fit_effect(spec: ModelSpec, effect: str, chunk: Chunk, evidence: dict, *, short_iter: int = 3,
               max_iter: int = 20, sampled: ModelSpec | None = None) -> ModelSpec:
    """``spec`` plus ``effect``, fitted by output error on ``chunk`` (base parameters too).

    Every variant that only differs in the effect's main parameter or variant gets a short
    fit of the base parameters with the effect held there (a profile of the cost over the
    effect's main parameter; phases of a cyclic error are chosen with the base held); the
    full joint fit continues from the best of those.  Backlash, resonance and dead time are
    also fitted on the sampled controller, from ``sampled`` (:func:`sampled_base` of ``spec``, computed
    here when not given), and the better fit on ``chunk`` is returned.  Backlash on the
    sampled controller and Stribeck friction are fitted with the fine and the coarse
    difference step (:data:`FD_STEP`, :data:`FD_STEP_ROUGH`), the better training fit kept;
    on a PID loop (ψ of :func:`cascade_motor_share` below 0.5) the coarse-step backlash fit
    continues from every gap start, not only from the best after the short step.  A dead
    time is returned at the middle of the delays that fit equally well (:func:`centre_delay`).
    """
    if effect in ("resonance", "time_delay", "backlash") and not spec.modes[4] and sampled is None:
        sampled = sampled_base(spec, chunk)
    if effect == "backlash":
        fits = [_fit_effect_from(spec, effect, chunk, evidence, short_iter=short_iter, max_iter=max_iter)]
        soft = softened_base(spec, chunk.Ts)
        if soft is not None:
            # a stiff base model (one pole faster than the sample rate) has absorbed the lost
            # motion; the two-mass model's own valley is reached from a moderate bandwidth
            fits.append(_fit_effect_from(soft, effect, chunk, evidence, short_iter=8, max_iter=max_iter,
                                         groups=[[_backlash_start(soft, {"gap_mm": g, "motor_fraction": 0.8,
                                                                         "position_motor_share": psi}, {"backlash": 1})
                                                  for psi in (cascade_motor_share(soft.theta),)] for g in (0.01, 0.03)]))
        # the gap inside a digital loop: the lost motion meets the sample-and-hold lag.  Fitted
        # with the coarse difference step as well: a loose PID loop rattles at every contact
        # and only the coarse step reaches its valley (a 99.8 % P-PI fit needs the fine one;
        # a base already on the sampled controller had its fine-step fit above).
        # With the coarse step on a loop that reads the position on the scale (ψ = 0, PID)
        # every gap start is fitted jointly (not on a long recording): the rattle at each
        # contact makes the short profile step rank the starts badly — seed 30 000's deepest
        # valley (training cost 0.074 × the base's against 0.168 ×, held-out 0.110 × against
        # 0.207 ×, gap 0.88 × the truth against 0.74 ×) is reached from the start it ranked
        # third.  On a P-PI cascade (ψ ≈ 0.8) the extra fits found no better gap and once a
        # valley that predicted the held-out data 46 % worse (seed 30 003, motor share 0.3)
        every = not chunk.long and cascade_motor_share((spec if sampled is None else sampled).theta) < 0.5
        on_sampled = [(spec, FD_STEP_ROUGH)] if spec.modes[4] else [(sampled, FD_STEP), (sampled, FD_STEP_ROUGH)]
        for s0, h in on_sampled:
            fits.append(_fit_effect_from(s0, effect, chunk, evidence, short_iter=short_iter, max_iter=max_iter,
                                         fd_step=h, every_start=every and h == FD_STEP_ROUGH))
        best = min(fits, key=lambda f: sse(f, chunk))
        if not chunk.long:
            # the base identified without the gap took part of the lost motion as a soft
            # velocity loop (seed 30 006: a1 76 against the drive's 193); the joint fit raises
            # a1 only part of the way (149) before the contacts start to rattle.  Restarted
            # above that ridge it reaches the valley from the other side (training cost 0.185
            # → 0.048 × the base's, gap 0.72 → 0.93 × the truth).  b1 moves with a1, keeping
            # the velocity feed-forward's share.
            for k in VELOCITY_GAIN_RESTARTS:
                s0 = best.copy()
                s0.theta[[0, 4]] *= k
                if np.isfinite(sse(s0, chunk)):
                    fits.append(fit_spec(fit_spec(s0, chunk, max_iter=max_iter, fd_step=FD_STEP_ROUGH), chunk,
                                         max_iter=max_iter, fd_step=FD_STEP_ROUGH))
        return min(fits, key=lambda f: sse(f, chunk))
    if effect == "resonance" and not spec.modes[4]:
        # a mode near the loop bandwidth interacts with the sample-and-hold phase lag: fit it on
        # the sampled controller as well, keep whichever fits the training data better
        fits = [_fit_effect_from(sampled, effect, chunk, evidence, short_iter=short_iter, max_iter=max_iter),
                _fit_effect_from(spec, effect, chunk, evidence, short_iter=short_iter, max_iter=max_iter)]
        at_peaks = fit_resonance_at_peaks(sampled, chunk, evidence, max_iter=max_iter)
        if at_peaks is not None:
            # free, the fit tends to buy training cost with a stiff, well-damped "mode" the
            # residual spectrum does not show; a mode where the spectrum peaks is preferred
            peaks = evidence.get("spectrum_peaks", [])
            fits = [at_peaks] + [f for f in fits if resonance_at_peak(f, peaks, chunk.Ts)]
        return min(fits, key=lambda f: sse(f, chunk))
    if effect == "time_delay":
        # the continuous controller of eq. 3.3 hides the half sample of the zero-order hold and
        # of the backward-difference velocity in any delay it is given: fit the dead time on
        # the sampled controller (as well) and keep whichever fits the training data better
        if spec.modes[4]:
            return centre_delay(fit_delay_profile(spec, chunk, max_iter=max_iter), chunk)
        alt = fit_delay_profile(sampled, chunk, max_iter=max_iter)
        own = _fit_effect_from(spec, effect, chunk, evidence, short_iter=short_iter, max_iter=max_iter)
        return centre_delay(alt if sse(alt, chunk) < sse(own, chunk) else own, chunk)
    if effect == "stribeck":
        # stick and breakaway land on sub-step boundaries as contacts do: fine and coarse step
        return min((_fit_effect_from(spec, effect, chunk, evidence, short_iter=short_iter, max_iter=max_iter,
                                     fd_step=h) for h in (FD_STEP, FD_STEP_ROUGH)), key=lambda f: sse(f, chunk))
    return _fit_effect_from(spec, effect, chunk, evidence, short_iter=short_iter, max_iter=max_iter)


#: Lowest frequency a resonance is started at, Hz (below, the loop itself and the moves dominate).
MIN_MODE_HZ = 5.0
#: Resonance starts at the residual spectrum peaks above MIN_MODE_HZ that hold at least this
#: share of the residual power (above 20 Hz, or in all for a lower peak; a mode concentrates
#: it: ≥ 20 % in the benchmark; a dead time spreads it over small peaks: ≤ 11 %) …
PEAK_MIN_SHARE = 0.15
#: … the first this many of them, each held inside this band (× the peak frequency): a
#: two-mass mode shows between f·√μ and f, so its free-free frequency lies above the peak
PEAK_STARTS = 2
PEAK_BAND = (0.9, 1.4)
#: Damping of a mode the signature test accepts (ζ above it is a filter, not a resonance).
MAX_MODE_DAMPING = 0.15
#: A spectrum peak corroborates a mode within this log-distance (≈ ±20 %) of its band — for
#: the fit's choice among resonance fits and for the acceptance test alike.
PEAK_LOG_TOL = 0.2
#: A start whose free-run cost exceeds the base model's by this factor has diverged (costs
#: of 1e10 and beyond); a lightly damped mode started at the peak with the base gains rings
#: at up to ~1e3 × and still fits (two P-PI modes near 90 Hz: 1007 × and 1372 ×).
DIVERGED = 1e6


def resonance_signature(spec: ModelSpec, peaks: list[dict], Ts: float, tol: float = PEAK_LOG_TOL) -> str:
    """Why the fitted resonance of ``spec`` does not look like a mode the residual spectrum shows ("" if it does).

    A mode is lightly damped (ζ ≤ ``MAX_MODE_DAMPING``), below 0.45/Ts, and one of ``peaks``
    lies in its band f·√μ … f widened by ``tol`` in log-frequency: a two-mass mode inside the
    loop shows between its locked-motor frequency f·√μ (motor held by a stiff velocity loop)
    and its free-free frequency f; the filter on the recorded position at f alone.
    """
    p = effect_parameters(spec, "resonance")
    f = p["freq_hz"]
    if p["damping"] > MAX_MODE_DAMPING or f > 0.45 / Ts:
        return f"not a lightly damped mode (ζ = {p['damping']:.2f}, {f:.0f} Hz)"
    lo = f * math.sqrt(p["motor_fraction"]) if p["kind"] == "two_mass" else f
    if not peak_in_band(peaks, lo, f, tol):
        band = f"{lo:.0f}–{f:.0f} Hz" if lo < f else f"{f:.0f} Hz"
        return f"no residual spectrum peak near {band}"
    return ""


def resonance_at_peak(spec: ModelSpec, peaks: list[dict], Ts: float, tol: float = PEAK_LOG_TOL) -> bool:
    """Does the fitted resonance of ``spec`` look like a mode the residual spectrum shows?
    (:func:`resonance_signature` finds nothing to object)."""
    return not resonance_signature(spec, peaks, Ts, tol)


def fit_resonance_at_peaks(sampled: ModelSpec, chunk: Chunk, evidence: dict, *, max_iter: int = 20,
                           profile_iter: int = 5) -> ModelSpec | None:
    """A two-mass mode (sampled controller) started at each residual spectrum peak and kept near it.

    Started lightly damped (ζ = 0.02) at the peak, the position term on the table (PID) or
    mostly on the motor (P-PI); a short base re-fit with the mode held, then the joint
    output-error fit with the frequency held inside ``PEAK_BAND`` × the peak and ζ ≤
    ``MAX_MODE_DAMPING``.  Every start is fitted jointly: the profile cost alone ranks them
    badly (a mode near the loop bandwidth only pays once the gains have moved back).
    None when the spectrum has no such peak (``PEAK_MIN_SHARE``).
    """
    peaks = [p["freq_hz"] for p in evidence.get("spectrum_peaks", [])
             if p["freq_hz"] > MIN_MODE_HZ and max(p.get("share_above_20_hz", 0.0), p.get("power_share", 0.0)) >= PEAK_MIN_SHARE]
    base_v = sse(sampled, chunk)
    best, best_v = None, np.inf
    for fp in peaks[:PEAK_STARTS]:
        bounds = {"freq_hz": (PEAK_BAND[0] * fp, PEAK_BAND[1] * fp), "damping": (0.002, MAX_MODE_DAMPING)}
        for psi in (0.0, 0.8):
            s0 = _apply(sampled, "resonance", {"freq_hz": fp, "damping": 0.02, "gain": 1.0, "motor_fraction": 0.8,
                                               "position_motor_share": psi}, {"resonance": 1})
            if not sse(s0, chunk) < DIVERGED * base_v:  # a start the loop cannot hold
                continue
            s1 = fit_spec(s0, chunk, fit_effects=False, max_iter=profile_iter)
            s2 = fit_spec(s1, chunk, max_iter=max_iter, bounds=bounds)
            v = sse(s2, chunk)
            if v < best_v:
                best, best_v = s2, v
    return best


def fit_delay_profile(spec: ModelSpec, chunk: Chunk, *,
                      grid_ts: tuple[float, ...] = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0),
                      profile_iter: int | None = None, golden_steps: int = 5, max_iter: int = 20) -> ModelSpec:
    """A dead time fitted by its profile: base parameters re-fitted at every trial delay.

    The delay enters the free-run cost through a cliff (a loop given a longer dead time
    than its gains allow goes unstable), so it is searched, not differentiated: a grid of
    ``grid_ts`` samples in both variants (capture, actuation) with a short base re-fit at
    each, then a golden-section search between the best point's neighbours, then the joint
    fit (eq. 3.6) of base and delay.  The base re-fit gets ``profile_iter`` iterations
    (default 25, 8 on recordings longer than ``LONG_S``): a delay trades against the gains,
    and a short re-fit leaves the profile's minimum up to a sample off.
    """
    Ts = chunk.Ts
    if profile_iter is None:
        profile_iter = PROFILE_ITER_LONG if chunk.long else PROFILE_ITER
    k = EP_INDEX["delay_s"]

    def profile(start: ModelSpec, d: float) -> tuple[float, ModelSpec | None]:
        s0 = start.copy()
        s0.ep[k] = d
        if not np.isfinite(sse(s0, chunk)):
            return np.inf, None
        s1 = fit_spec(s0, chunk, fit_effects=False, max_iter=profile_iter)
        return sse(s1, chunk), s1

    best_v, best, best_i = np.inf, None, 0
    grid = [g * Ts for g in grid_ts]
    for mode in (0, 1):
        start = _apply(spec, "time_delay", {"delay_s": grid[0]}, {"time_delay": mode})
        for i, d in enumerate(grid):
            v, s1 = profile(start, d)
            if v < best_v:
                best_v, best, best_i = v, s1, i
    if best is None:
        return _apply(spec, "time_delay", {}, {})
    lo = grid[best_i - 1] if best_i > 0 else 0.0
    hi = grid[best_i + 1] if best_i + 1 < len(grid) else 2.0 * grid[-1]
    g = 0.5 * (math.sqrt(5.0) - 1.0)
    start = best
    a, b = lo, hi
    c, d = b - g * (b - a), a + g * (b - a)
    fc, sc = profile(start, c)
    fd, sd = profile(start, d)
    for _ in range(golden_steps):
        if fc < fd:
            b, d, fd, sd = d, c, fc, sc
            c = b - g * (b - a)
            fc, sc = profile(start, c)
        else:
            a, c, fc, sc = c, d, fd, sd
            d = a + g * (b - a)
            fd, sd = profile(start, d)
    for v, s1 in ((fc, sc), (fd, sd)):
        if s1 is not None and v < best_v:
            best_v, best = v, s1
    fits = [fit_spec(best, chunk, max_iter=max_iter)]
    if spec.modes[4] and not chunk.long:
        # the valley of a dead time inside the loop can lie far from the base identified
        # without it (gains 2-3x lower): start there from the regression that knows the delay
        # (the hold and the sampled velocity add about a sample: m samples in the regression
        # is a dead time of about m − 1 samples on the sampled controller)
        reg = chunk_regression(chunk)
        for m in (1, 2, 3) if reg is not None else ():
            s0 = delayed_regression_start(chunk, m, reg)
            if s0 is None:
                continue
            s0 = _apply(s0, "time_delay", {"delay_s": max(m - 1, 0.5) * Ts}, {"time_delay": 1})
            s0.modes[4] = 1
            if np.isfinite(sse(s0, chunk)):
                s1 = fit_spec(s0, chunk, fit_effects=False, max_iter=25)
                fits.append(fit_spec(fit_spec(s1, chunk, max_iter=max_iter), chunk, max_iter=max_iter))
    return min(fits, key=lambda f: sse(f, chunk))


#: Delays whose training cost lies within this share of the best fit equally well: 2 % of
#: the cost is 1 % of the residual norm, a quarter of the smallest held-out gain the
#: diagnosis acts on (``diagnose.MIN_GAIN``) …
DELAY_PROFILE_TOL = 0.02
#: … searched for between DELAY_SCAN_RANGE × the fitted delay: a step of DELAY_SCAN_STEP ×
#: either way, then DELAY_BISECTIONS halvings towards the far end when the step is inside.
DELAY_SCAN_RANGE = (0.1, 3.0)
DELAY_SCAN_STEP = 0.1
DELAY_BISECTIONS = 4


def centre_delay(spec: ModelSpec, chunk: Chunk, tol: float = DELAY_PROFILE_TOL) -> ModelSpec:
    """``spec``'s dead time moved to the middle of the delays that fit equally well.

    A capture delay on a stiff loop (P-PI) is weakly determined: a shorter trial delay is
    made up by a slower loop, so the profile of the training cost over the delay (base
    re-fitted at each) is flat below the truth up to a cliff a little above it, where no
    causal loop can take the surplus back.  Its minimum then lies anywhere in the flat
    part (seed 10 004: 0.59 × the truth, 0.3 % below the cost at the truth).  The edges of
    the interval where the cost stays within ``tol`` of the lowest seen are searched on
    both sides of the fitted delay (:data:`DELAY_SCAN_RANGE`); the returned model has the
    delay at the middle of that interval (base re-fitted there, the delay then held by
    :func:`fit_spec`) and the interval in ``ranges["delay_s"]``.  On a sharp profile (a
    PID loop, an actuation delay) the first step either way is outside: the interval is
    that step wide and the delay stays where the fit put it.
    """
    k = EP_INDEX["delay_s"]
    d_hat = float(spec.ep[k])
    if "time_delay" not in spec.effects or not d_hat > 0.0:
        return spec
    iters = PROFILE_ITER_LONG if chunk.long else PROFILE_ITER
    fits: dict[float, tuple[float, ModelSpec]] = {1.0: (sse(spec, chunk), spec)}

    def inside(r: float) -> bool:
        if r not in fits:
            near = min(fits, key=lambda q: abs(q - r))  # warm start from the nearest profile point
            s0 = fits[near][1].copy()
            s0.ep[k] = r * d_hat
            s1 = fit_spec(s0, chunk, fit_effects=False, max_iter=iters) if np.isfinite(sse(s0, chunk)) else s0
            fits[r] = (sse(s1, chunk), s1)
        return fits[r][0] <= (1.0 + tol) * min(v for v, _ in fits.values())

    edges = []
    for far, sign in ((DELAY_SCAN_RANGE[1], 1.0), (DELAY_SCAN_RANGE[0], -1.0)):
        r_in, r_out = 1.0, 1.0 + sign * DELAY_SCAN_STEP
        if inside(r_out):
            r_in, r_out = r_out, far
            if inside(far):
                r_in = far
            else:
                for _ in range(DELAY_BISECTIONS):
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


def chunk_regression(chunk: Chunk) -> Regression | None:
    """The regression of eq. 3.11 on ``chunk`` (no command shift, standstill rows kept), or None.

    None when it cannot be built (too few samples, no motion): no regression start then.
    """
    from core.errors import RapidIdentError
    from ident.regression import build_regression

    seg = np.cumsum(chunk.starts) - 1
    try:
        return build_regression(chunk.x_r, chunk.x, chunk.Ts, seg, shift=0, standstill="hold")
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


def sampled_base(spec: ModelSpec, chunk: Chunk, max_iter: int = 30) -> ModelSpec:
    """``spec`` on the sampled controller (u computed every Ts and held), base re-fitted.

    Started from :func:`softened_base` when the continuous base is stiff (a pole beyond
    1/Ts would make the sampled loop unstable).
    """
    s = softened_base(spec, chunk.Ts) or spec.copy()
    s.modes[4] = 1
    # twice, as the base itself: the restart re-scales the parameters after the first long move
    return fit_spec(fit_spec(s, chunk, fit_effects=False, max_iter=max_iter), chunk, fit_effects=False,
                    max_iter=max_iter)


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


def _fit_effect_from(spec: ModelSpec, effect: str, chunk: Chunk, evidence: dict, *, short_iter: int,
                     max_iter: int, groups: list[list[ModelSpec]] | None = None,
                     fd_step: float = FD_STEP, every_start: bool = False) -> ModelSpec:
    """:func:`fit_effect` from the start ``groups`` (default :func:`start_groups`).

    The joint fit continues from the start that is best after the short profile step, or,
    with ``every_start``, from every start (the best training fit kept).
    """
    starts: list[tuple[float, ModelSpec]] = []
    for group in (start_groups(spec, effect, chunk, evidence) if groups is None else groups):
        if effect == "cyclic_error":
            vals = [sse(s, chunk) for s in group]
            group = [group[int(np.argmin(vals))]]
        for s0 in group:
            if not np.isfinite(sse(s0, chunk)):
                continue
            # profile step: the base re-adapts to the effect held at its start value
            s1 = fit_spec(s0, chunk, fit_effects=False, max_iter=short_iter, fd_step=fd_step)
            starts.append((sse(s1, chunk), s1))
    starts = [(v, s1) for v, s1 in starts if np.isfinite(v)]
    if not starts:
        return _apply(spec, effect, {}, {})
    if not every_start:
        starts = [min(starts, key=lambda vs: vs[0])]
    fits = [fit_spec(fit_spec(s1, chunk, max_iter=max_iter, fd_step=fd_step), chunk, max_iter=max_iter,
                     fd_step=fd_step) for _v, s1 in starts]
    return min(fits, key=lambda f: sse(f, chunk))


def effect_parameters(spec: ModelSpec, effect: str) -> dict:
    """The effect's parameters in the words of SPEC §7, with units in the key names."""
    ep = spec.ep
    if effect == "backlash":
        out = {"gap_mm": float(ep[0]), "loop": "table_fed_back" if spec.modes[0] else "table_recorded"}
        if spec.modes[0]:
            out["motor_fraction"] = float(ep[11])
            out["position_motor_share"] = float(ep[12])
        return out
    if effect == "stribeck":
        return {"static_to_coulomb_ratio": float(ep[1]), "stribeck_velocity_mm_s": float(ep[2])}
    if effect == "resonance":
        if spec.modes[3]:
            return {"freq_hz": float(ep[3]), "damping": float(ep[4]), "motor_fraction": float(ep[11]),
                    "kind": "two_mass"}
        return {"freq_hz": float(ep[3]), "damping": float(ep[4]), "gain": float(ep[5]), "kind": "output_filter"}
    if effect == "time_delay":
        out = {"delay_s": float(ep[6]), "where": "actuation" if spec.modes[1] else "capture"}
        if "delay_s" in spec.ranges:
            out["delay_range_s"] = [float(v) for v in spec.ranges["delay_s"]]
        return out
    if effect == "cyclic_error":
        amp = float(np.hypot(ep[8], ep[9]))
        kind = "disturbance" if spec.modes[2] else "position_error"
        return {
            "period_mm": float(ep[7]),
            "amplitude": amp,
            "amplitude_unit": "mm/s^2" if spec.modes[2] else "mm",
            "phase_rad": float(np.arctan2(ep[9], ep[8])),
            "kind": kind,
        }
    if effect == "saturation":
        return {"limit": float(ep[10]), "limit_unit": "mm/s^2", "position_motor_share": float(ep[12])}
    raise ValueError(f"unknown effect {effect!r}")

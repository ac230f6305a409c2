"""What a candidate model is and how it is scored: the samples (:class:`Chunk`), the model
(:class:`ModelSpec`: base parameters θ of eq. 3.3 plus effects), its free-run simulation
(:func:`simulate_spec`, the one simulator of :mod:`ident.diagnosis.augmented`) and the
weighted output-error cost of eq. 3.6 (:func:`residual`, :func:`sse`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ident.diagnosis.augmented import (
    EFFECTS,
    EP_INDEX,
    MODE_SLOTS,
    N_EP,
    N_MODES,
    command_derivatives,
    model_substeps,
    restart_sensitivities,
    sensitivities,
    simulate_augmented,
)
from ident.fixed_order import sum_squares
from ident.portable_math import exp

__all__ = ["Chunk", "ModelSpec", "make_chunk", "simulate_spec", "residual", "residual_jacobian", "sse", "sim_substeps"]


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
    #: segment starts that restart mid-move and the recorded velocity and acceleration
    #: there, (mask, v, a) (:meth:`windows`; ``simulate_augmented(warm=)``)
    warm: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    #: multiple-shooting windows (:meth:`shots`): the state each warm restart misreads is
    #: estimated per window (:func:`estimated_states`)
    estimate_states: bool = False

    @property
    def n(self) -> int:
        return int(self.x_r.size)

    def scored(self, mask: np.ndarray) -> "Chunk":
        """The same samples with only ``mask`` (and not the restart transients) scored."""
        return replace(self, score=self.score & mask)

    def reweighted(self, r: np.ndarray) -> "Chunk":
        """The same samples weighted by a variance of each segment's own: ``w = σ/σ_seg``,
        σ_seg the rms of the residual ``r`` (mm, every sample) over the segment's scored
        samples, σ over all of them (floored at 1e-3·σ, as :func:`make_chunk` floors).

        Under ``r``'s per-segment variances the weighted cost is the Gaussian likelihood
        (up to constants): a segment whose model residual is large counts for little.
        """
        sc = self.score & np.isfinite(r)
        if not np.any(sc):
            return self
        sigma = math.sqrt(float(np.mean(r[sc] ** 2))) or 1.0
        w = np.ones(self.n)
        bounds = np.append(np.flatnonzero(self.starts), self.n)
        for a, b in zip(bounds[:-1], bounds[1:]):
            m = sc[a:b]
            s_seg = math.sqrt(float(np.mean(r[a:b][m] ** 2))) if np.any(m) else sigma
            w[a:b] = sigma / max(s_seg, 1e-3 * sigma)
        return replace(self, w=w)

    def part(self, frac: float) -> "Chunk":
        """The first part of every segment holding ``frac`` of its scored samples (a cheaper
        look at the same physics for the early rounds of a search).

        Each part starts where its segment starts, so the simulation restarts where it
        does on the whole chunk (from rest, not mid-move); weights and scored samples are
        the chunk's own.  ``frac >= 1`` returns the chunk itself.
        """
        if frac >= 1.0:
            return self
        bounds = np.append(np.flatnonzero(self.starts), self.n)
        keep = np.zeros(self.n, dtype=bool)
        for a, b in zip(bounds[:-1], bounds[1:]):
            counted = np.cumsum(self.score[a:b])
            if counted.size == 0 or counted[-1] == 0:
                continue
            end = a + int(np.searchsorted(counted, frac * counted[-1])) + 1
            keep[a:end] = True
        return self._take(keep, self.starts, self.score, self.warm)

    def windows(self, seconds: float, window_s: float = 1.0, lead_s: float = 0.1) -> "Chunk":
        """About ``seconds`` of the chunk in windows spread evenly over all of it (a cheaper
        look at the same physics for the early rounds of a search that, unlike :meth:`part`,
        sees every stretch of the travel, of the program and of both speed sets).

        ``round(seconds / window_s)`` windows (at least one) of equal length, the i-th
        beginning where i/m of the scored samples lie before it, each inside its segment.
        A window restarts the simulation mid-move (``warm``: on the recorded state, see
        :func:`~ident.diagnosis.augmented.simulate_augmented`) between ``lead_s`` and twice
        that before its first scored sample, where :func:`_restart_state` reads the state
        best, and that lead-in is not scored: what the restart cannot know (a mode's phase,
        an integral wound up in saturation) settles there.  A window reaching back to its
        segment's start restarts there at rest, as the whole chunk does.  Returns the chunk
        itself when it is no longer than ``seconds``.
        """
        plan = self._window_plan(seconds, window_s)
        if plan is None:
            return self
        firsts, length = plan
        lead = int(round(lead_s / self.Ts))
        keep, starts, (warm, vw, aw) = self._no_windows()
        score = np.zeros(self.n, dtype=bool)
        for a, lo, hi in firsts:
            b = min(a + length, hi)
            r = lo  # reaches back to the segment's start: restart there, at rest
            if a - lead - _HALF > lo:  # restart mid-move where the recorded state is read best
                r, vw_r, aw_r = _restart_state(self.x, self.derivs[0], max(a - 2 * lead, lo + _HALF), a - lead,
                                               self.Ts)
                warm[r], vw[r], aw[r] = True, vw_r, aw_r
            score[r:b] = self.score[r:b]
            if r > lo:
                score[r:a] = False  # the lead-in
            keep[r:b] = True
            starts[r] = True
        return self._take(keep, starts, score, (warm, vw, aw))

    def rest_windows(self, seconds: float, window_s: float = 1.0, rest_s: float = 0.05,
                     held: np.ndarray | None = None) -> "Chunk | None":
        """About ``seconds`` of the chunk in windows spread over all of it, as :meth:`windows`,
        but each restarting where the axis rests: at its segment's start or at the end of a
        dwell of the command at least ``rest_s`` long where the recording shows the axis at
        rest (the restarts of :meth:`rests`, velocity 0), the integral holding ``held``
        there (mm/s², an array over the chunk's samples: the force a model's own free run
        holds at each rest, :func:`~ident.diagnosis.candidates.held_force`; 0 when None).

        For a model with a state no recording shows mid-move — an integral wound up while
        the output is clipped — a window restarted mid-move misreads it, but at a rest it is
        known: an integral wound up beyond the force friction holds would move the axis.
        Window i runs from the last rest at or before the first sample :meth:`windows`
        would score (the i/m point of the scored samples) to ``window_s`` past that sample,
        within its segment; windows that overlap join.  Every sample of a window is scored
        (a rest has no lead-in to settle).  None when the chunk holds no such dwell (the
        caller races on :meth:`part` then); the chunk itself when it is no longer than
        ``seconds``.
        """
        plan = self._window_plan(seconds, window_s)
        if plan is None:
            return self
        rested = self.rests(rest_s)
        if rested is None:
            return None
        firsts, length = plan
        points = np.flatnonzero(rested.starts)  # segment starts and rests, sorted
        keep, starts, (warm, vw, aw) = self._no_windows()
        rest_warm = rested.warm[0]
        end = -1
        for a, _lo, hi in firsts:
            r = int(points[int(np.searchsorted(points, a, side="right")) - 1])  # ≥ the segment's start
            b = min(a + length, hi)
            if r > end or self.starts[r]:  # a new window: the simulation restarts at the rest
                starts[r] = True
                if rest_warm[r]:
                    warm[r], vw[r], aw[r] = True, 0.0, 0.0 if held is None else float(held[r])
            keep[r:b] = True
            end = max(end, b)
        return self._take(keep, starts, self.score, (warm, vw, aw))

    def shots(self, window_s: float, lead_s: float = 0.1) -> "Chunk":
        """Every scored sample of the chunk in short windows, each simulated from the recorded
        state: the chunk of a multiple-shooting fit (Ribeiro et al., Automatica 2020).

        Every segment is cut into consecutive windows of about ``window_s`` (a tail shorter
        than half a window joins the one before).  The first window of a segment starts
        where the segment does (at rest, or warm where the chunk itself restarts warm); every
        other one restarts the simulation mid-move on the recorded position, velocity and
        acceleration between ``lead_s`` and twice that before its first sample, where
        :func:`_restart_state` reads them best, and that lead-in is not scored: what the
        restart cannot know (a mode's phase and deflection, a delay's history, an integral
        wound up in saturation) settles there.  Lead-ins repeat samples the window before
        scores, so every scored sample of the chunk is scored once.  A model's error then
        grows over one window only, never over a whole segment.
        """
        L = max(int(round(window_s / self.Ts)), 1)
        lead = int(round(lead_s / self.Ts))
        seg_starts = np.flatnonzero(self.starts)
        seg_ends = np.append(seg_starts[1:], self.n)
        idx, starts, score, warm, vw, aw = [], [], [], [], [], []
        # mid-move: the command moves at every sample the restart's parabola is read from
        # (at the end of a move the table may already rest in its gap or stick)
        still = np.convolve(self.derivs[0] == 0.0, np.ones(2 * _HALF + 1), mode="same")
        moving = still == 0.0
        for lo, hi in zip(seg_starts.tolist(), seg_ends.tolist()):
            a = lo
            while a < hi:
                b = hi if hi - (a + L) < L // 2 else a + L
                r, w0, v0, a0 = lo, False, 0.0, 0.0
                if self.warm is not None:
                    w0, v0, a0 = bool(self.warm[0][lo]), float(self.warm[1][lo]), float(self.warm[2][lo])
                at = _moving_restart(moving, lo + _HALF, a - lead, lead) if a > lo else None
                if at is not None:
                    r, v0, a0 = _restart_state(self.x, self.derivs[0], *at, self.Ts, moving)
                    w0 = True
                elif a > lo:  # nothing moves between the segment's start and the window: restart there
                    r = lo
                k = np.arange(r, b)
                idx.append(k)
                st = np.zeros(k.size, dtype=bool)
                st[0] = True
                starts.append(st)
                sc = self.score[k].copy()
                sc[: a - r] = False  # the lead-in is not scored
                score.append(sc)
                wm = np.zeros(k.size, dtype=bool)
                wm[0] = w0
                warm.append(wm)
                vv, aa = np.zeros(k.size), np.zeros(k.size)
                vv[0], aa[0] = v0, a0
                vw.append(vv)
                aw.append(aa)
                a = b
        i = np.concatenate(idx)
        return Chunk(self.x_r[i], self.x[i], self.Ts, np.concatenate(starts),
                     (self.derivs[0][i], self.derivs[1][i]), self.w[i], np.concatenate(score),
                     (np.concatenate(warm), np.concatenate(vw), np.concatenate(aw)), estimate_states=True)

    def rests(self, rest_s: float) -> "Chunk | None":
        """The same samples, the simulation restarted at rest at the end of every dwell of
        the command at least ``rest_s`` long (its last sample before the command moves
        again): the held-out reading of :func:`rest_residual`.

        At such a restart the model's axis is put at the recorded position at rest
        (``warm`` with velocity 0; the force friction holds there is what
        :func:`rest_residual` profiles) — only where the recording shows the axis at rest:
        the slope of a straight line fitted to its last ``rest_s`` of positions within three
        standard errors of 0 (an axis still creeping towards the command is moving, and a
        restart at rest would misread it).  A restart after the segment's first ``rest_s``
        only; None when the chunk holds no such dwell.  Every sample scored in the chunk
        stays scored: a restart at rest misreads nothing the model can know (a stuck axis
        shows no force), so there is no lead-in.
        """
        k_rest = max(int(round(rest_s / self.Ts)), 1)
        still = self.derivs[0] == 0.0
        starts = self.starts.copy()
        seg_start = np.maximum.accumulate(np.where(self.starts, np.arange(self.n), 0))
        run = 0
        for k in range(self.n - 1):
            run = 0 if self.starts[k] else run
            run = run + 1 if still[k] else 0
            if (run >= k_rest and not still[k + 1] and not self.starts[k + 1] and k - seg_start[k] >= k_rest
                    and _at_rest(self.x[k + 1 - k_rest : k + 1])):
                starts[k] = True
        added = starts & ~self.starts
        if not added.any():
            return None
        return replace(self, starts=starts, warm=(added, np.zeros(self.n), np.zeros(self.n)),
                       estimate_states=False)

    def _window_plan(self, seconds: float, window_s: float) -> tuple[list[tuple[int, int, int]], int] | None:
        """Where the ``round(seconds / window_s)`` windows (at least one) of :meth:`windows`
        and :meth:`rest_windows` begin: for the i-th of m, the first sample after i/m of the
        scored samples, with the bounds of its segment (first, last + 1); and their length
        in samples.  None when the chunk is no longer than ``seconds`` or scores nothing."""
        n_need = int(round(seconds / self.Ts))
        cum = np.cumsum(self.score)
        if self.n <= n_need or cum[-1] == 0:
            return None
        m = max(1, int(round(seconds / window_s)))
        seg_starts = np.flatnonzero(self.starts)
        seg_ends = np.append(seg_starts[1:], self.n)
        firsts = []
        for i in range(m):
            a = int(np.searchsorted(cum, i * cum[-1] / m + 1))  # first scored sample of window i
            j = int(np.searchsorted(seg_starts, a, side="right")) - 1
            firsts.append((a, int(seg_starts[j]), int(seg_ends[j])))
        return firsts, max(n_need // m, 1)

    def _no_windows(self) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Empty masks of kept samples and restarts, and the chunk's own warm restarts
        (mask, v, a) as new arrays: what :meth:`windows` and :meth:`rest_windows` fill."""
        warm = np.zeros(self.n, dtype=bool)
        vw, aw = np.zeros(self.n), np.zeros(self.n)
        if self.warm is not None:
            warm[:], vw[:], aw[:] = self.warm
        return np.zeros(self.n, dtype=bool), np.zeros(self.n, dtype=bool), (warm, vw, aw)

    def _take(self, keep: np.ndarray, starts: np.ndarray, score: np.ndarray,
              warm: tuple[np.ndarray, np.ndarray, np.ndarray] | None) -> "Chunk":
        """The samples of ``keep`` with the given starts, scored samples and warm restarts."""
        i = np.flatnonzero(keep)
        return Chunk(self.x_r[i], self.x[i], self.Ts, starts[i], (self.derivs[0][i], self.derivs[1][i]),
                     self.w[i], score[i], None if warm is None else tuple(a[i] for a in warm))


def _at_rest(x: np.ndarray) -> bool:
    """Does the recorded position ``x`` (a stretch of samples) show no motion: the slope of
    the straight line fitted to it within three standard errors of 0?"""
    t = np.arange(x.size) - 0.5 * (x.size - 1)
    # np.sum's pairwise order, not BLAS's machine-dependent dot
    stt = float(np.sum(t * t))
    slope = float(np.sum(t * (x - x.mean()))) / stt
    res = x - x.mean() - slope * t
    se = math.sqrt(float(np.sum(res * res)) / max(x.size - 2, 1) / stt)
    return abs(slope) <= 3.0 * se


#: Samples either side of a warm restart its velocity and acceleration are read from.
_HALF = 5


def _moving_restart(moving: np.ndarray, lo: int, hi: int, lead: int) -> tuple[int, int] | None:
    """The span [hi − lead, hi] to restart in (:func:`_restart_state`) when the command moves
    there (``moving``, a mask of samples); else the ``lead`` samples up to the last sample in [lo, hi] where it moves, so
    a window after a dwell restarts on the move before it (at rest the side of a gap the
    table rests on and the force friction holds are not known).  None when the command
    does not move in [lo, hi].
    """
    if hi < lo:
        return None
    where = np.flatnonzero(moving[lo : hi + 1])
    if where.size == 0:
        return None
    last = lo + int(where[-1])
    return max(last - lead, lo), last


def _restart_state(x: np.ndarray, v_r: np.ndarray, lo: int, hi: int, Ts: float,
                   moving: np.ndarray | None = None) -> tuple[int, float, float]:
    """The sample in [lo, hi] where the recorded position ``x`` is closest to a parabola over
    the ``_HALF`` samples either side (the acceleration steady: no switch of the command's
    jerk, no reversal inside), while the command moves (``v_r`` ≠ 0: at rest the side of a
    gap the table rests on is not known) where it does, with the parabola's slope and
    curvature there (mm/s, mm/s²): a least-squares fit averages the encoder's quantization
    and noise that plain differences would amplify.  ``x`` must hold ``_HALF`` samples
    either side of [lo, hi].  ``moving``: the samples that count as moving (default
    ``v_r`` ≠ 0).
    """
    # x ≈ c0·j² + c1·j + c2 over j = −_HALF … _HALF: on the symmetric stencil the normal
    # equations split (odd moments vanish) and the least-squares weights have a closed form,
    # summed column by column in a fixed order — no BLAS or LAPACK, whose order of
    # operations (and so the restart's last bits) depends on the machine
    js = range(-_HALF, _HALF + 1)
    s0 = float(2 * _HALF + 1)
    s2 = float(sum(j * j for j in js))
    s4 = float(sum(j ** 4 for j in js))
    det = s4 * s0 - s2 * s2
    seg = np.arange(lo, hi + 1)
    X = {j: x[seg + j] for j in js}  # the stencil's samples, per offset
    c0 = np.zeros(seg.size)
    c1 = np.zeros(seg.size)
    c2 = np.zeros(seg.size)
    for j in js:
        c0 += X[j] * ((s0 * j * j - s2) / det)
        c1 += X[j] * (j / s2)
        c2 += X[j] * ((s4 - s2 * j * j) / det)
    misfit = np.zeros(seg.size)
    for j in js:
        e = X[j] - (c0 * float(j * j) + c1 * float(j) + c2)
        misfit += e * e
    moving = v_r[lo : hi + 1] != 0.0 if moving is None else moving[lo : hi + 1]
    if moving.any():
        misfit[~moving] = np.inf
    k = int(np.argmin(misfit))
    return lo + k, float(c1[k]) / Ts, float(2.0 * c0[k]) / (Ts * Ts)


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
    modes: np.ndarray = field(default_factory=lambda: np.zeros(N_MODES, dtype=np.int64))
    #: effect parameters the recording leaves open: name → (low, high) of the values that fit
    #: equally well (:func:`centre_delay`)
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    #: narrower boxes for effect parameters a start was led to by evidence (a mode started
    #: at a residual spectrum peak stays near it): name → (low, high)
    box: dict[str, tuple[float, float]] = field(default_factory=dict)
    #: what led a start away from the base, when not a grid ("" for the grid): a base from
    #: other evidence (the regression that knows a delay) lies in a valley of its own
    origin: str = ""

    def flags(self) -> np.ndarray:
        return np.array([1 if e in self.effects else 0 for e in EFFECTS], dtype=np.int64)

    def copy(self) -> "ModelSpec":
        return ModelSpec(self.theta.copy(), tuple(self.effects), self.ep.copy(), self.modes.copy(),
                         dict(self.ranges), dict(self.box), self.origin)

    def released(self) -> "ModelSpec":
        """A copy with no parameter held (``ranges`` cleared): for a joint fit with another effect."""
        s = self.copy()
        s.ranges = {}
        return s

    def with_effect(self, effect: str, params: dict | None = None, variant: int | None = None) -> "ModelSpec":
        """A copy with ``effect`` switched on, its parameters (names of ``EP_INDEX``) and variant set."""
        s = self.copy()
        s.effects = tuple(dict.fromkeys(self.effects + (effect,)))
        for k, v in (params or {}).items():
            s.ep[EP_INDEX[k]] = v
        if variant is not None:
            s.modes[MODE_SLOTS[effect]] = variant
        return s

    @property
    def sampled(self) -> bool:
        """True on a sampled controller (u computed every Ts and held; either feed-forward)."""
        return bool(self.modes[MODE_SLOTS["controller"]])


def simulate_spec(spec: ModelSpec, chunk: Chunk, nsub: int | None = None,
                  u_out: np.ndarray | None = None) -> np.ndarray:
    """Free-run recorded position (mm) of ``spec`` on ``chunk``; ``u_out`` (chunk.n,), when
    given, is filled with the control-equivalent acceleration u (mm/s²) applied at each
    sample (:func:`~ident.diagnosis.augmented.simulate_augmented`)."""
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
        u_out=u_out,
        warm=chunk.warm,
    )


def residual(spec: ModelSpec, chunk: Chunk, mask: np.ndarray | None = None, *,
             shared_states: bool = False) -> np.ndarray:
    """Weighted free-run residual w·(x̂ − x) on ``mask`` (default the scored samples), mm;
    on multiple-shooting windows with the restart states estimated (:func:`estimated_states`).

    ``shared_states``: estimate only the states every model's restart misreads (position,
    velocity, the integral holding the acceleration), not a mode's free response — the same
    nuisance parameters per window for a model with and without an effect, as the held-out
    windows of the acceptance compare them (``DiagnosisConfig.accept_on_windows``).
    """
    m = chunk.score if mask is None else mask
    r = chunk.w[m] * (simulate_spec(spec, chunk)[m] - chunk.x[m])
    effects = () if shared_states else spec.effects
    return estimated_states(r, effects, spec.ep, spec.modes, chunk, restart_responses(spec, chunk, m), m)


def residual_jacobian(spec: ModelSpec, chunk: Chunk, d_theta: np.ndarray, d_ep: np.ndarray, *,
                      restarts: list[np.ndarray] | None = None, nsub: int | None = None) -> np.ndarray:
    """Exact derivatives of :func:`residual` (without ``shared_states``), (P, scored samples):
    row p along the direction ``(d_theta[p], d_ep[p])`` of the parameters.

    The complex-step sensitivities of the free run (:func:`~ident.diagnosis.augmented.sensitivities`),
    weighted; on multiple-shooting windows projected as :func:`estimated_states` projects the
    residual, with ``restarts`` (:func:`restart_responses`, of the model the fit started
    from) held: the window states are eliminated by a projection linear in the residual,
    its basis held over the step (Kaufman's variable projection).  A row whose simulation
    diverges is zero: the residual is a constant there.
    """
    m = chunk.score
    D = sensitivities(chunk.x_r, chunk.x, chunk.Ts, spec.theta, spec.ep, d_theta, d_ep, flags=spec.flags(),
                      modes=spec.modes, starts=chunk.starts, derivs=chunk.derivs,
                      nsub=sim_substeps(spec, chunk.Ts) if nsub is None else nsub, warm=chunk.warm)
    with np.errstate(all="ignore"):
        G = chunk.w[m] * D[:, m]
    G[~np.isfinite(G).all(axis=1)] = 0.0
    if restarts is not None:
        for g in G:
            g[:] = estimated_states(g, spec.effects, spec.ep, spec.modes, chunk, restarts)
    return G


def rest_residual(spec: ModelSpec, chunk: Chunk, grid: int, span: float = 1.0) -> np.ndarray:
    """Raw residual x̂ − x (mm) on ``chunk``'s scored samples, ``chunk`` restarted at rest
    (:meth:`Chunk.rests`), the force friction holds at each restart profiled out.

    At rest the recorded position shows where a stuck axis stands, not the force its
    friction holds: the integral may have wound up to anywhere in the stick band
    [r·d1, r·d0] (eq. 3.2 with its breakaway ratio r, 1 without Stribeck friction), and
    when the axis breaks away again follows from it.  Each window between restarts is
    simulated from ``grid`` forces spread evenly over ``span`` × the model's own stick band
    (a sampled loop's held output may exceed it while its axis slips by less than the
    encoder resolves) and keeps
    the one that predicts the window best: the profile likelihood of the held-out data
    with that force a nuisance parameter of every window, one per window for any model.
    Over a free run a stick-slip model's breakaways drift in phase (one missed breakaway
    leaves the axis stuck at another place until the next move); restarted at every rest
    the model is judged on what it predicts from there: when it breaks away, how far it
    slides, where it sticks.
    """
    d0, d1 = float(spec.theta[6]), float(spec.theta[7])
    r = float(spec.ep[EP_INDEX["static_to_coulomb_ratio"]]) if "stribeck" in spec.effects else 1.0
    lo, hi = span * r * min(d0, d1, 0.0), span * r * max(d0, d1, 0.0)
    on = chunk.warm[0]
    win = (np.cumsum(chunk.starts) - 1)[chunk.score]
    nw = int(np.count_nonzero(chunk.starts))
    best = np.full(nw, np.inf)
    out = np.full(win.size, np.inf)
    for force in np.linspace(lo, hi, max(grid, 1)):
        c = replace(chunk, warm=(on, chunk.warm[1], np.where(on, force, 0.0)))
        res = simulate_spec(spec, c)[chunk.score] - chunk.x[chunk.score]
        with np.errstate(all="ignore"):
            e = np.bincount(win, weights=res * res, minlength=nw)
        better = e < best
        best = np.where(better, e, best)
        take = better[win]
        out[take] = res[take]
    return out


def restart_responses(spec: ModelSpec, chunk: Chunk, m: np.ndarray | None = None) -> list[np.ndarray] | None:
    """The weighted responses of ``spec``'s simulation on ``chunk``'s samples ``m`` (default
    the scored ones) to an offset of every warm restart's position, velocity and
    acceleration (per mm, mm/s and mm/s², exact: :func:`~ident.diagnosis.augmented.restart_sensitivities`):
    the directions a window's error takes when the restart misreads the state — the
    position, the velocity, the integral holding the acceleration.  None unless ``chunk``
    estimates its restart states (:meth:`Chunk.shots`).
    """
    if not chunk.estimate_states or chunk.warm is None:
        return None
    m = chunk.score if m is None else m
    D = restart_sensitivities(chunk.x_r, chunk.x, chunk.Ts, spec.theta, spec.ep, flags=spec.flags(),
                              modes=spec.modes, starts=chunk.starts, derivs=chunk.derivs,
                              nsub=sim_substeps(spec, chunk.Ts), warm=chunk.warm)
    return [chunk.w[m] * d[m] for d in D]


def estimated_states(r: np.ndarray, effects: tuple[str, ...], ep: np.ndarray, modes: np.ndarray, chunk: Chunk,
                     cols: list[np.ndarray] | None, m: np.ndarray | None = None) -> np.ndarray:
    """``r`` (weighted residuals of ``chunk``'s samples ``m``, default the scored ones) with
    every warm window's initial state estimated: the initial states of multiple shooting.

    A restart mid-move reads position, velocity and acceleration from the recording and
    settles the rest; what it misreads adds to the window's output, to first order, as a
    combination of ``cols`` (:func:`restart_responses`) and — for a mode on the recorded
    position (``resonance``, output filter, restarted undeflected) — of its free response
    e^(−ζωt)·(A cos ω_d t + B sin ω_d t), t from the restart.  The combination of every
    window is estimated by least squares and removed (variable projection: the states are
    eliminated, not fitted as parameters).  Windows restarted at rest keep their state.
    Returns ``r`` itself on other chunks.
    """
    if cols is None or not chunk.estimate_states or chunk.warm is None:
        return r
    m = chunk.score if m is None else m
    win = np.cumsum(chunk.starts) - 1  # window of each sample
    first = np.flatnonzero(chunk.starts)
    warm_win = chunk.warm[0][first]
    basis = list(cols)
    if "resonance" in effects and int(modes[MODE_SLOTS["resonance"]]) == 0:
        f, zeta = float(ep[EP_INDEX["freq_hz"]]), float(ep[EP_INDEX["damping"]])
        if f > 0.0 and 0.0 <= zeta < 1.0:
            t = (np.arange(chunk.n) - first[win]) * chunk.Ts
            om = 2.0 * math.pi * f
            env = chunk.w * exp(-zeta * om * t)
            wd = om * math.sqrt(1.0 - zeta * zeta)
            basis += [(env * np.cos(wd * t))[m], (env * np.sin(wd * t))[m]]
    k = win[m]
    live = warm_win[k]
    B = np.stack([np.where(live, b, 0.0) for b in basis], axis=1)  # (samples, columns)
    if not (np.all(np.isfinite(B)) and np.all(np.isfinite(r))):
        return r
    nw, nc = first.size, B.shape[1]
    G = np.zeros((nw, nc, nc))
    h = np.zeros((nw, nc))
    for i in range(nc):
        h[:, i] = np.bincount(k, weights=B[:, i] * r, minlength=nw)
        for j in range(i, nc):
            G[:, i, j] = G[:, j, i] = np.bincount(k, weights=B[:, i] * B[:, j], minlength=nw)
    # columns equilibrated per window: a restart's responses (~1e-3) beside a mode's free
    # response (~1e2) would otherwise fall below pinv's cut-off and be dropped
    d = np.sqrt(np.einsum("wii->wi", G))
    d = np.where(d > 0.0, d, 1.0)
    Gs = G / (d[:, :, None] * d[:, None, :])
    coef = np.einsum("wij,wj->wi", np.linalg.pinv(Gs, rcond=1e-10, hermitian=True), h / d) / d
    return r - np.einsum("si,si->s", B, coef[k])


def sse(spec: ModelSpec, chunk: Chunk, mask: np.ndarray | None = None) -> float:
    """Weighted sum of squared free-run residuals, mm² (inf when the simulation diverges)."""
    r = residual(spec, chunk, mask)
    with np.errstate(all="ignore"):
        v = sum_squares(r)
    return v if np.isfinite(v) else float("inf")


def sim_substeps(spec: ModelSpec, Ts: float) -> int:
    """Sub-steps per sample of ``spec``'s simulation (:func:`~ident.diagnosis.augmented.model_substeps`)."""
    return model_substeps(spec.theta, Ts, spec.flags(), spec.ep, spec.modes)

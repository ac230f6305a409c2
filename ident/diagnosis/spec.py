"""What a candidate model is and how it is scored: the samples (:class:`Chunk`), the model
(:class:`ModelSpec`: base parameters θ of eq. 3.3 plus effects), its free-run simulation
(:func:`simulate_spec`, the one simulator of :mod:`ident.diagnosis.augmented`) and the
weighted output-error cost of eq. 3.6 (:func:`residual`, :func:`sse`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ident.diagnosis.augmented import (
    EFFECTS,
    EP_INDEX,
    MODE_SLOTS,
    N_EP,
    N_MODES,
    command_derivatives,
    model_substeps,
    simulate_augmented,
)

__all__ = ["Chunk", "ModelSpec", "make_chunk", "simulate_spec", "residual", "sse", "sim_substeps"]


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

    def scored(self, mask: np.ndarray) -> "Chunk":
        """The same samples with only ``mask`` (and not the restart transients) scored."""
        return Chunk(self.x_r, self.x, self.Ts, self.starts, self.derivs, self.w, self.score & mask)

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
        i = np.flatnonzero(keep)
        return Chunk(self.x_r[i], self.x[i], self.Ts, self.starts[i], (self.derivs[0][i], self.derivs[1][i]),
                     self.w[i], self.score[i])


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


def sim_substeps(spec: ModelSpec, Ts: float) -> int:
    """Sub-steps per sample of ``spec``'s simulation (:func:`~ident.diagnosis.augmented.model_substeps`)."""
    return model_substeps(spec.theta, Ts, spec.flags(), spec.ep, spec.modes)

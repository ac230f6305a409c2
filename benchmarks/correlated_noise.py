"""Measurement noise correlated like a closed loop's residual, for the benchmarks and tests
whose truth is in the model class and only the noise is random."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ar1_noise"]


def ar1_noise(n: int, rho: float, sigma_mm: float, seed: int | np.random.Generator) -> np.ndarray:
    """Stationary AR(1) noise n_k = ρ·n_{k−1} + e_k of standard deviation ``sigma_mm``, mm, (n,).

    Its integrated autocorrelation time is (1 + ρ)/(1 − ρ) samples (19 at ρ = 0.9).  The
    first sample is drawn from the stationary distribution, so the whole record is
    stationary.  ``seed``: an int or a :class:`numpy.random.Generator` (drawn from).
    """
    rng = np.random.default_rng(seed)
    e = rng.standard_normal(n) * sigma_mm * math.sqrt(1.0 - rho * rho)
    out = np.empty(n)
    out[0] = rng.standard_normal() * sigma_mm
    for k in range(1, n):
        out[k] = rho * out[k - 1] + e[k]
    return out

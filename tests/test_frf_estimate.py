"""The H1 estimate recovers a known system's frequency response, and its coherence says where the data carry none."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import butter, freqz, lfilter

from ident.frf_estimate import h1_estimate

FS = 1000.0


def _system():
    """A second-order low-pass at 40 Hz, as a sampled filter with an exactly known response."""
    return butter(2, 40.0, fs=FS)


def test_h1_matches_a_known_system_driven_by_broadband_input():
    rng = np.random.default_rng(0)
    u = np.cumsum(rng.standard_normal(40_000))  # a wandering position, like a command
    b, a = _system()
    y = lfilter(b, a, u)
    est = h1_estimate(u, y, FS)
    _, h = freqz(b, a, worN=est.f, fs=FS)
    band = est.f < 100
    assert np.max(np.abs(est.H[band] - h[band])) < 0.02
    assert np.min(est.coherence[band]) > 0.99


def test_coherence_falls_where_the_input_has_no_power_and_noise_dominates():
    rng = np.random.default_rng(1)
    b, a = _system()
    u = np.cumsum(lfilter(*butter(4, 20.0, fs=FS), rng.standard_normal(40_000)))  # nothing above ~20 Hz
    y = lfilter(b, a, u) + 1e-3 * rng.standard_normal(u.size)
    est = h1_estimate(u, y, FS)
    _, h = freqz(b, a, worN=est.f, fs=FS)
    low, high = est.f < 10, est.f > 200
    assert np.median(est.coherence[low]) > 0.95
    assert np.median(est.coherence[high]) < 0.3
    assert np.max(np.abs(est.H[low] - h[low])) < 0.05


def test_segments_are_estimated_apart_and_a_too_short_recording_gives_none():
    rng = np.random.default_rng(2)
    b, a = _system()
    u1, u2 = np.cumsum(rng.standard_normal(20_000)), 50 + np.cumsum(rng.standard_normal(20_000))
    u = np.r_[u1, u2]
    y = np.r_[lfilter(b, a, u1), lfilter(b, a, u2)]  # the filter restarts at the seam
    seg = np.r_[np.zeros(u1.size, int), np.ones(u2.size, int)]
    est = h1_estimate(u, y, FS, segment=seg, nperseg=1024)
    _, h = freqz(b, a, worN=est.f, fs=FS)
    assert est.nperseg == 1024 and est.averages == 2 * (1 + (u1.size - 1 - 1024) // 512)
    assert np.max(np.abs(est.H[est.f < 100] - h[est.f < 100])) < 0.02
    assert h1_estimate(u[:100], y[:100], FS, nperseg=256) is None
    with pytest.raises(ValueError):
        h1_estimate(u, y[:-1], FS)

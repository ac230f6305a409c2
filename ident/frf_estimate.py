"""Non-parametric frequency response from the data themselves: the H1 (Welch) estimate.

The identified model's tracking transfer function G_track = x / x_r (thesis eq. 3.3, Figs
3.5, 3.8, 3.10) is a parametric claim; this module gives what the recording alone says about
the same response, so a reader sees where the data support the model and where the
excitation carried no information::

    H1(f) = S_uy(f) / S_uu(f),        γ²(f) = |S_uy(f)|² / (S_uu(f) · S_yy(f))

with S the Welch-averaged (cross) power spectral densities of the input u (commanded
position) and the output y (actual position) — MATLAB's ``tfestimate`` / ``mscohere``.
γ² (the magnitude-squared coherence, 0 … 1) is near 1 where the output is a linear response
to the input, and falls where the input had no power, noise dominates or the response is
not linear (friction, backlash).

Both signals are first-differenced before the spectra are taken: a position recording
wanders over millimetres at the lowest frequencies and its leakage would swamp the rest;
the same filter on input and output leaves H1 and γ² unchanged in theory.  A recording
made of segments (the low- and high-speed sets, a gap) is estimated per segment and the
spectra summed weighted by each segment's averages: no window spans a seam.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FrfEstimate", "h1_estimate"]


@dataclass(frozen=True)
class FrfEstimate:
    """An H1 estimate: ``f`` Hz (> 0), complex ``H`` (output/input), ``coherence`` γ² in [0, 1].

    ``averages`` is the number of Welch windows summed (over all segments), ``nperseg`` the
    window length in samples (frequency resolution fs / nperseg).
    """

    f: np.ndarray
    H: np.ndarray
    coherence: np.ndarray
    averages: int
    nperseg: int


def _default_nperseg(lengths: list[int]) -> int:
    """A window that gives about eight averages on the longest segment, 256 … 4096 samples."""
    n = max(lengths)
    return int(min(4096, max(256, 2 ** int(np.floor(np.log2(max(n // 8, 1)))))))


def h1_estimate(u: np.ndarray, y: np.ndarray, fs: float, *, segment: np.ndarray | None = None,
                nperseg: int | None = None) -> FrfEstimate | None:
    """H1 estimate of the response from ``u`` to ``y`` sampled at ``fs`` Hz, with its coherence.

    Parameters
    ----------
    u, y : ndarray (N,)
        Input and output (here commanded and actual position, mm; any units).
    fs : float
        Sample rate, Hz.
    segment : ndarray of int (N,), optional
        Segment ids; windows never span a change of id.
    nperseg : int, optional
        Welch window length, samples (Hann window, half overlap); by default about an
        eighth of the longest segment, 256 … 4096.

    Returns ``None`` when no segment is as long as one window or the input has no power.
    """
    from scipy.signal import csd, welch

    u = np.asarray(u, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    if u.shape != y.shape:
        raise ValueError(f"u has {u.size} samples but y has {y.size}")
    seg = np.zeros(u.size, dtype=int) if segment is None else np.asarray(segment).ravel()
    edges = np.flatnonzero(np.diff(seg) != 0) + 1
    pieces = [(a, b) for a, b in zip(np.r_[0, edges], np.r_[edges, u.size])]
    if nperseg is None:
        nperseg = _default_nperseg([b - a for a, b in pieces])
    Suu = Syy = Suy = None
    total = 0
    for a, b in pieces:
        du, dy = np.diff(u[a:b]), np.diff(y[a:b])
        if du.size < nperseg:
            continue
        k = 1 + (du.size - nperseg) // (nperseg // 2)  # Welch windows in this segment
        kw = dict(fs=fs, nperseg=nperseg, detrend="constant")
        f, puu = welch(du, **kw)
        _, pyy = welch(dy, **kw)
        _, puy = csd(du, dy, **kw)
        Suu = k * puu if Suu is None else Suu + k * puu
        Syy = k * pyy if Syy is None else Syy + k * pyy
        Suy = k * puy if Suy is None else Suy + k * puy
        total += k
    if total == 0 or not np.any(Suu[1:] > 0):
        return None
    f, Suu, Syy, Suy = f[1:], Suu[1:], Syy[1:], Suy[1:]  # drop DC: the differences carry none
    with np.errstate(divide="ignore", invalid="ignore"):
        H = np.where(Suu > 0, Suy / Suu, np.nan + 0j)
        coh = np.where((Suu > 0) & (Syy > 0), np.abs(Suy) ** 2 / (Suu * Syy), 0.0)
    return FrfEstimate(f, H, np.clip(coh, 0.0, 1.0), total, int(nperseg))

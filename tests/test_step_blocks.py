"""The piecewise-constant load windows (disturbance._step_blocks) are binary segmentation:
split the piece whose split lowers the squared error most (ties to the earliest piece),
keep the number of pieces the BIC prefers.  The heap that picks the next piece is a
faster way to the same pieces as scanning every piece at every split."""

import math

import numpy as np
import pytest

from ident.diagnosis import disturbance as d


def _scanned_path(y: np.ndarray, Ts: float, starts: np.ndarray) -> list[list[tuple[int, int]]]:
    """The segmentation path by the definition: a scan of every piece for the best split."""
    n = y.size
    c1 = np.concatenate([[0.0], np.cumsum(y)])
    bounds = list(np.append(np.flatnonzero(starts), n))
    m = max(int(round(d.BLOCK_MIN_S / Ts)), 2)
    pieces = [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]
    gains = {p: d._split_gain(c1, *p, m) for p in pieces}
    path = [sorted(pieces)]
    for _ in range(int(n * Ts / (2.0 * d.BLOCK_MIN_S))):
        p = max(pieces, key=lambda q: (gains[q][0], -q[0]))
        g, k = gains[p]
        if k < 0 or g <= 0.0:
            break
        pieces.remove(p)
        for q in ((p[0], k), (k, p[1])):
            pieces.append(q)
            gains[q] = d._split_gain(c1, *q, m)
        path.append(sorted(pieces))
    return path


def _windows_of(path, y, Ts, starts):
    """_step_blocks's choice on a given path (BIC, two levels, edges), written out again."""
    n = y.size
    c1 = np.concatenate([[0.0], np.cumsum(y)])
    c2 = np.concatenate([[0.0], np.cumsum(y * y)])
    n_eff = max(2.0 * d.DISTURBANCE_BAND_HZ * n * Ts, 2.0)

    def rss(ps):
        return float(sum((c2[b] - c2[a]) - (c1[b] - c1[a]) ** 2 / (b - a) for a, b in ps))

    bic = [n_eff * math.log(max(rss(ps), 1e-300) / n) + 2.0 * j * math.log(n_eff) for j, ps in enumerate(path)]
    best = path[int(np.argmin(bic))]
    if len(best) == len(path[0]):
        return []
    levels = np.array([(c1[b] - c1[a]) / (b - a) for a, b in best])
    on = d._two_levels(levels, np.array([b - a for a, b in best], dtype=float))
    bounds = list(np.append(np.flatnonzero(starts), n))
    edge = int(round(d.SEGMENT_EDGE_S / Ts))
    seg_of = np.searchsorted(bounds, np.arange(n), side="right") - 1
    out = []
    for (a, b), hit in zip(best, on):
        if hit and out and out[-1][1] == a:
            out[-1] = (out[-1][0], b)
        elif hit:
            out.append((a, b))
    return [(a, b) for a, b in out if a - bounds[seg_of[a]] >= edge and bounds[seg_of[a] + 1] - b >= edge]


@pytest.mark.parametrize("seed", range(6))
def test_the_windows_are_those_of_scanning_every_piece(seed):
    rng = np.random.default_rng(seed)
    Ts, n = 1e-3, 12_000
    t = np.arange(n) * Ts
    y = np.cumsum(rng.normal(size=n)) * 0.05 + (np.sin(2 * np.pi * 0.7 * t) > 0.3) * 2.0
    if seed % 2:
        y = np.round(y, 1)  # equal gains: the earliest piece is split first
    starts = np.zeros(n, dtype=bool)
    starts[[0, 4_000 + 100 * seed]] = True
    assert d._step_blocks(y, Ts, starts) == _windows_of(_scanned_path(y, Ts, starts), y, Ts, starts)


def test_pulses_on_half_of_the_time_are_found_where_they_are():
    rng = np.random.default_rng(7)
    Ts, n = 1e-3, 10_000
    y = rng.normal(size=n) * 0.1
    on = [(2_000, 2_500), (5_000, 5_500), (8_000, 8_500)]
    for a, b in on:
        y[a:b] += 3.0
    starts = np.zeros(n, dtype=bool)
    starts[0] = True
    found = d._step_blocks(y, Ts, starts)
    assert len(found) == len(on)
    for (a, b), (fa, fb) in zip(on, found):
        assert abs(fa - a) <= 5 and abs(fb - b) <= 5


@pytest.mark.parametrize("wn", [0.02, 0.2, 0.99])
def test_the_low_pass_is_scipys_butterworth_and_zero_phase_filter_to_rounding(wn):
    from scipy import signal

    b, a = d._butter2(wn)
    b0, a0 = signal.butter(2, wn)
    assert np.allclose(b, b0, rtol=1e-13, atol=1e-16) and np.allclose(a, a0, rtol=1e-13, atol=1e-16)
    x = np.cumsum(np.random.default_rng(5).standard_normal(600))
    for n in (600, 16):
        y = d._filtfilt(b, a, x[:n], min(9, n - 1))
        assert np.allclose(y, signal.filtfilt(b, a, x[:n], padlen=min(9, n - 1)), rtol=0, atol=1e-12 * np.abs(x).max())

"""The equivalent input disturbance: what the drive model would need as an extra acceleration.

Eq. 3.3 in the time domain, with ``z = ∫(x_r − x) dt`` and the Coulomb friction ``f`` of
eq. 3.2, plus an unknown input ``w`` (mm/s²) where a force enters the loop::

    ẍ = b0·ẍ_r + b1·ẋ_r + b2·x_r − a1·ẋ − a2·x + a3·z − f(ẋ) + w

Evaluated on the *recorded* position (ẋ, ẍ by zero-phase low-pass differentiation), this
gives ``w(t)`` — the model inverted along the recording.  Whatever the model leaves out
shows up in ``w`` as a function of what causes it, whatever its structure:

* of velocity — a friction curve other than Coulomb (Stribeck, viscous asymmetry);
* of position — a periodic disturbance (cogging, pitch error), or a position map;
* of the time since a reversal — lost motion (backlash), breakaway;
* of the commanded acceleration — a limit reached, an unmodelled inertia;
* of time alone — a load the drive's own motion does not cause (an external force);
* of frequency — a structural mode.

:func:`analyse_disturbance` measures how much of ``w`` (low-passed to the band a load
acts in) each family explains by least squares, finds time blocks that the state
families leave unexplained, and says it in words and numbers.  At rest the friction can
take any value in ``[d1, d0]`` (stick), so only what exceeds that band counts there.
Since ``w`` is an acceleration, a force is ``w`` times the moving mass, which the
closed-loop model does not know: sizes are given in mm/s².
"""

from __future__ import annotations

import bisect
import heapq
import math

import numpy as np

from ident.diagnosis.residuals import (BLOCK_MIN_S, SEGMENT_EDGE_S, excursion_blocks, position_periodogram,
                                       reversal_times, time_since)
from ident.fixed_order import dot, lstsq, matvec, sum_squares, unit_columns
from ident.portable_math import exp, geomspace

__all__ = ["equivalent_disturbance", "analyse_disturbance", "block_input", "DISTURBANCE_BAND_HZ"]

#: Low-pass of the recorded position before differentiation, Hz (keeps ẍ's noise bounded).
DIFFERENTIATION_HZ = 40.0
#: Band a load or a slow drive effect acts in: w is analysed low-passed to this, Hz.
DISTURBANCE_BAND_HZ = 10.0
#: The disturbance is called time-localised (an external load) when the blocks explain at
#: least this share of its energy while covering at most ``BLOCK_MAX_TIME_SHARE`` of the time,
#: more than any state family (velocity, position, reversal, acceleration) alone …
BLOCK_MIN_SHARE = 0.5
BLOCK_MAX_TIME_SHARE = 0.5
#: … and the state families together explain less than this share of what the blocks
#: explain (``blocks_unique_share`` ≥ 1 − this): a load the motion causes recurs wherever
#: the motion's state recurs, so velocity, position, reversal or acceleration terms
#: reproduce its blocks; an external load does not …
BLOCK_MAX_STATE_SHARE = 0.5
#: … and the blocks add significantly to the state families: partial F-test on the
#: effective number of independent samples (N / correlation time of the joint fit's
#: residual), at this level.
BLOCK_ALPHA = 0.01
#: Rounds of (state families fitted outside the blocks → blocks found again on what they leave).
BLOCK_ROUNDS = 4


def _butter2(wn: float) -> tuple[np.ndarray, np.ndarray]:
    """2nd-order Butterworth low-pass (b, a) at ``wn`` × Nyquist by the bilinear transform in
    closed form: ``scipy.signal.butter(2, wn)`` without its polynomial products, whose last
    bits follow the machine's BLAS (numpy's convolve is a BLAS dot)."""
    K = math.tan(0.5 * math.pi * wn)
    s2 = math.sqrt(2.0)
    g = 1.0 / (1.0 + s2 * K + K * K)
    kk = K * K * g
    return np.array([kk, 2.0 * kk, kk]), np.array([1.0, 2.0 * (K * K - 1.0) * g, (1.0 - s2 * K + K * K) * g])


def _filtfilt(b: np.ndarray, a: np.ndarray, x: np.ndarray, padlen: int) -> np.ndarray:
    """``scipy.signal.filtfilt(b, a, x, padlen=padlen)`` (odd extension, the steady state of a
    step as initial state) with that state in closed form (scipy's lfilter_zi solves it with
    LAPACK); ``lfilter`` itself is a loop in a fixed order."""
    from scipy.signal import lfilter

    n = a.size
    B = b[1:] - a[1:] * b[0]
    zi = np.empty(n - 1)  # zi = A zi + B for the companion matrix A of a: solved by substitution
    zi[0] = float(np.sum(B)) / float(np.sum(a))
    asum, csum = 1.0, 0.0
    for k in range(1, n - 1):
        asum += a[k]
        csum += b[k] - a[k] * b[0]
        zi[k] = asum * zi[0] - csum
    ext = np.concatenate([2.0 * x[0] - x[padlen:0:-1], x, 2.0 * x[-1] - x[-2:-padlen - 2:-1]])
    y, _ = lfilter(b, a, ext, zi=zi * ext[0])
    y, _ = lfilter(b, a, y[::-1], zi=zi * y[-1])
    return y[::-1][padlen:-padlen]


def _lowpass(y: np.ndarray, Ts: float, f_hz: float, starts: np.ndarray) -> np.ndarray:
    """Zero-phase 2nd-order Butterworth low-pass per segment (edges padded by reflection)."""
    out = np.array(y, dtype=float, copy=True)
    b, a = _butter2(min(f_hz * 2.0 * Ts, 0.99))
    bounds = np.append(np.flatnonzero(starts), y.size)
    for s, e in zip(bounds[:-1], bounds[1:]):
        if e - s > 15:
            out[s:e] = _filtfilt(b, a, y[s:e], min(3 * max(len(a), len(b)), e - s - 1))
    return out


def _derivative(y: np.ndarray, Ts: float, starts: np.ndarray) -> np.ndarray:
    out = np.zeros_like(y)
    bounds = np.append(np.flatnonzero(starts), y.size)
    for s, e in zip(bounds[:-1], bounds[1:]):
        if e - s > 1:
            out[s:e] = np.gradient(y[s:e], Ts)
    return out


def equivalent_disturbance(x_r: np.ndarray, x: np.ndarray, Ts: float, theta: np.ndarray,
                           starts: np.ndarray) -> np.ndarray:
    """w (N,), mm/s²: the extra acceleration eq. 3.3 needs to reproduce the recorded ``x``.

    Parameters
    ----------
    x_r, x : commanded and recorded actual position, mm.
    Ts : sample period, s.
    theta : a1, a2, a3, b0, b1, b2, d0, d1 of eq. 3.3.
    starts : first sample of each segment (bool mask); nothing is differentiated or
        integrated across a segment start.
    """
    a1, a2, a3, b0, b1, b2, d0, d1 = (float(v) for v in theta)
    xf = _lowpass(x, Ts, DIFFERENTIATION_HZ, starts)
    v = _derivative(xf, Ts, starts)
    acc = _derivative(v, Ts, starts)
    v_r = _derivative(x_r, Ts, starts)
    a_r = _derivative(v_r, Ts, starts)
    z = np.empty_like(x)
    bounds = np.append(np.flatnonzero(starts), x.size)
    for s, e in zip(bounds[:-1], bounds[1:]):
        z[s:e] = np.concatenate([[0.0], np.cumsum((x_r[s:e] - x[s:e])[:-1]) * Ts])
    net = b0 * a_r + b1 * v_r + b2 * x_r - a1 * v - a2 * x + a3 * z  # drive without friction
    v_eps = max(1e-3 * float(np.max(np.abs(v_r)) or 1.0), 1e-4)
    moving = np.abs(v) > v_eps
    friction = np.where(v > 0, d0, d1)
    w = acc - net + np.where(moving, friction, 0.0)
    # at rest the friction supplies anything in [d1, d0]: only the excess is unexplained
    rest = ~moving
    w[rest] = acc[rest] - (net[rest] - np.clip(net[rest], min(d0, d1), max(d0, d1)))
    return w


def _explained(y: np.ndarray, A: np.ndarray) -> tuple[float, np.ndarray]:
    """(share of ‖y‖² the columns of A explain by least squares, the fit)."""
    den = sum_squares(y)
    if den <= 0 or A.size == 0:
        return 0.0, np.zeros_like(y)
    As = unit_columns(A)[0]
    fit = matvec(As, lstsq(As, y))
    return sum_squares(fit) / den, fit


def _blocks(y: np.ndarray, Ts: float, starts: np.ndarray) -> list[tuple[int, int]]:
    """Stretches where ``y`` stands out of its own robust spread (:func:`residuals.excursion_blocks`)."""
    return excursion_blocks(y, Ts, starts)


def _split_gain(c1: np.ndarray, a: int, b: int, m: int) -> tuple[float, int]:
    """The largest decrease of the squared error of one level on [a, b) by two levels, and where.

    ``c1``: the cumulative sum of y with a leading 0; pieces of at least ``m`` samples.
    The first largest wins a tie (a deterministic order).
    """
    k = np.arange(a + m, b - m + 1)
    if k.size == 0:
        return 0.0, -1
    nl, nr = k - a, b - k
    sl, sr = c1[k] - c1[a], c1[b] - c1[k]
    whole = (c1[b] - c1[a]) ** 2 / (b - a)
    gain = sl ** 2 / nl + sr ** 2 / nr - whole
    i = int(np.argmax(gain))
    return float(gain[i]), int(k[i])


def _step_blocks(y: np.ndarray, Ts: float, starts: np.ndarray) -> list[tuple[int, int]]:
    """Time windows where ``y`` sits at another constant level: a load that comes and goes.

    ``y`` is modelled as piecewise constant in time, the change points found by binary
    segmentation (each recording segment its own piece to start with; pieces of at least
    ``BLOCK_MIN_S``) and their number k chosen by the Bayesian information criterion,
    ``n_eff·ln(RSS_k/n) + 2k·ln(n_eff)`` (a level and a place per change), with
    ``n_eff = 2·B·T`` the independent samples of a signal low-passed to the band B over T
    seconds.  This finds a load that is on half of the time — pulses all through a run —
    where :func:`residuals.excursion_blocks`, which needs a quiet majority, sees none.
    The windows are the pieces at the level held for less of the time (the pieces' levels
    split in two by :func:`_two_levels`), leaving out those within ``SEGMENT_EDGE_S`` of a
    segment's ends (filter edges, restart transients).  Whether they are a load is the
    caller's test (:func:`_blocks_test`: significant beyond the state families, and
    independent of them).
    """
    n = y.size
    y = np.asarray(y, dtype=float)
    c1 = np.concatenate([[0.0], np.cumsum(y)])
    c2 = np.concatenate([[0.0], np.cumsum(y * y)])
    bounds = list(np.append(np.flatnonzero(starts), n))
    m = max(int(round(BLOCK_MIN_S / Ts)), 2)
    per_s = 2.0 * DISTURBANCE_BAND_HZ  # independent samples a second
    n_eff = max(per_s * n * Ts, 2.0)
    pieces = [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]

    terms: dict[tuple[int, int], float] = {}  # each piece's squared error about its level, once

    def rss(ps) -> float:
        for a, b in ps:
            if (a, b) not in terms:
                terms[a, b] = (c2[b] - c2[a]) - (c1[b] - c1[a]) ** 2 / (b - a)
        return float(sum([terms[p] for p in ps]))  # summed in the pieces' order, as ever

    gains = {p: _split_gain(c1, *p, m) for p in pieces}
    # the piece to split next: the largest gain, ties to the earliest piece (starts are
    # unique), popped from a heap instead of a scan of every piece at every split
    heap = [(-gains[p][0], p[0], p) for p in pieces]
    heapq.heapify(heap)
    pieces.sort()
    path = [list(pieces)]
    k_max = int(n * Ts / (2.0 * BLOCK_MIN_S))
    for _ in range(k_max):
        if not heap:
            break
        p = heapq.heappop(heap)[2]
        g, k = gains[p]
        if k < 0 or g <= 0.0:
            break
        pieces.remove(p)
        for q in ((p[0], k), (k, p[1])):
            bisect.insort(pieces, q)
            gains[q] = _split_gain(c1, *q, m)
            heapq.heappush(heap, (-gains[q][0], q[0], q))
        path.append(list(pieces))
    bic = [n_eff * math.log(max(rss(ps), 1e-300) / n) + 2.0 * j * math.log(n_eff) for j, ps in enumerate(path)]
    best = path[int(np.argmin(bic))]
    if len(best) == len(path[0]):
        return []
    levels = np.array([(c1[b] - c1[a]) / (b - a) for a, b in best])
    lengths = np.array([b - a for a, b in best], dtype=float)
    on = _two_levels(levels, lengths)
    edge = int(round(SEGMENT_EDGE_S / Ts))
    seg_of = np.searchsorted(bounds, np.arange(n), side="right") - 1
    out: list[tuple[int, int]] = []
    for (a, b), hit in zip(best, on):
        if hit and out and out[-1][1] == a:  # a window split in two pieces is one window
            out[-1] = (out[-1][0], b)
        elif hit:
            out.append((a, b))
    return [(a, b) for a, b in out if a - bounds[seg_of[a]] >= edge and bounds[seg_of[a] + 1] - b >= edge]


def _two_levels(levels: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Which pieces are at the load's level: the two duration-weighted means that fit the
    pieces' levels best (1-D 2-means, exact by sorting), the load the one held for less time."""
    order = np.argsort(levels, kind="stable")
    lv, ln = levels[order], lengths[order]
    w1, s1 = np.cumsum(ln)[:-1], np.cumsum(ln * lv)[:-1]
    w2, s2 = ln.sum() - w1, dot(ln, lv) - s1
    between = s1 ** 2 / w1 + s2 ** 2 / w2  # what a split explains; the within-cluster SS is the rest
    cut = int(np.argmax(between)) + 1
    low = np.zeros(levels.size, dtype=bool)
    low[order[:cut]] = True
    load_low = ln[:cut].sum() < ln[cut:].sum()
    return low if load_low else ~low


def _state_blocks(wl: np.ndarray, A: np.ndarray, Ts: float,
                  starts: np.ndarray) -> tuple[list[tuple[int, int]], np.ndarray]:
    """Blocks of ``wl`` the state regressors ``A`` leave, found robustly; (blocks, state fit).

    Fitted on every sample, the state families absorb part of a load that comes and goes
    (a position sinusoid lines up with pulses), and what they leave no longer shows the
    blocks.  So the blocks are first looked for in ``wl`` itself (or, when none stand out
    there, in what the state fit on all samples leaves; when none stand out there either,
    as the windows of a piecewise-constant level, :func:`_step_blocks`), then the state families (with a
    constant) are fitted *outside* the blocks only and the blocks looked for again in what
    they leave, until the blocks stop changing: a least-squares fit with the blocks as
    outliers.
    """
    A1 = np.column_stack([A, np.ones(wl.size)])
    fit = _explained(wl, A1)[1]
    find = _blocks
    spans = _blocks(wl, Ts, starts) or _blocks(wl - fit, Ts, starts)
    if not spans:  # no quiet majority to stand out of: a load on about half of the time?
        find = _step_blocks
        spans = _step_blocks(wl - fit, Ts, starts)
    for _ in range(BLOCK_ROUNDS):
        out = np.ones(wl.size, dtype=bool)
        for i, j in spans:
            out[i:j] = False
        if np.count_nonzero(out) <= A1.shape[1]:
            break
        fit = matvec(A1, _lstsq(A1[out], wl[out]))
        new = find(wl - fit, Ts, starts)
        if new == spans:
            break
        spans = new
    return spans, fit


def _lstsq(A: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least-squares coefficients with the columns scaled to unit norm (then unscaled)."""
    As, scale = unit_columns(A)
    return lstsq(As, y) / scale


def _block_columns(spans: list[tuple[int, int]], n: int) -> np.ndarray:
    """One indicator column per block, shape (n, len(spans))."""
    B = np.zeros((n, len(spans)))
    for k, (i, j) in enumerate(spans):
        B[i:j, k] = 1.0
    return B


def _blocks_test(wl: np.ndarray, A: np.ndarray, spans: list[tuple[int, int]]) -> dict:
    """How much the blocks explain beyond the state families, and whether that is significant.

    R² of the state families (with a constant), of the block indicators (with a constant)
    and of both; ``blocks_unique_share`` = (R²_both − R²_state) / R²_blocks, the part of what
    the blocks explain that the state families cannot.  Partial F-test of the blocks:
    ``F = ((R²_both − R²_state)/k) / ((1 − R²_both)/(n_eff − p))`` with k blocks, p columns
    in all, n_eff = N / τ (τ the correlation time of the joint fit's residual), against the
    F(k, n_eff − p) quantile at ``1 − BLOCK_ALPHA``.
    """
    from scipy.stats import f as f_dist

    from ident.diagnosis.diagnose import correlation_time  # lazy: diagnose imports this module

    n = wl.size
    one = np.ones((n, 1))
    B = _block_columns(spans, n)
    den = sum_squares(wl) or 1.0

    def r2(M: np.ndarray) -> tuple[float, np.ndarray]:
        res = wl - matvec(M, _lstsq(M, wl))
        return 1.0 - sum_squares(res) / den, res

    r2_state, _ = r2(np.column_stack([A, one]))
    r2_blocks, _ = r2(np.column_stack([B, one]))
    r2_both, res = r2(np.column_stack([A, B, one]))
    k, p = B.shape[1], A.shape[1] + B.shape[1] + 1
    n_eff = n / correlation_time(res)
    dof = n_eff - p
    unique = max(r2_both - r2_state, 0.0)
    if k == 0 or dof <= 1 or r2_both >= 1.0:
        F, crit = (math.inf if k and unique > 0 else 0.0), 0.0
    else:
        F = (unique / k) / ((1.0 - r2_both) / dof)
        crit = float(f_dist.ppf(1.0 - BLOCK_ALPHA, k, dof))
    return {"r2_state": r2_state, "r2_blocks": r2_blocks, "r2_both": r2_both,
            "blocks_unique_share": unique / r2_blocks if r2_blocks > 0 else 0.0,
            "f_statistic": float(F), "f_critical": crit, "effective_samples": float(n_eff),
            "significant": bool(k > 0 and F > crit)}


def block_input(n: int, blocks: list[dict], Ts: float) -> np.ndarray:
    """The piecewise-constant disturbance (mm/s²) of a block description, shape (n,)."""
    w = np.zeros(n)
    for b in blocks:
        i, j = int(round(b["t_start_s"] / Ts)), int(round(b["t_end_s"] / Ts)) + 1
        w[max(i, 0):min(j, n)] = b["mean_mm_s2"]
    return w


def analyse_disturbance(w: np.ndarray, x_r: np.ndarray, x: np.ndarray, v_r: np.ndarray, a_r: np.ndarray,
                        Ts: float, starts: np.ndarray) -> dict:
    """What the equivalent disturbance ``w`` (mm/s²) depends on, how large it is, in words.

    Returns a JSON-ready dict: ``rms_mm_s2``; ``explained`` — share of the band-limited
    disturbance's energy each family explains alone (velocity, position, after_reversal,
    acceleration, time_blocks); ``dominant``; ``blocks`` — time-localised excursions
    unexplained by the state families (start/end s, mean mm/s²); ``time_localised``;
    ``words``.
    """
    n = w.size
    t = np.arange(n) * Ts
    wl = _lowpass(w, Ts, DISTURBANCE_BAND_HZ, starts)
    wl = wl - float(np.mean(wl))
    res: dict = {"rms_mm_s2": float(np.sqrt(np.mean(wl ** 2))), "band_hz": DISTURBANCE_BAND_HZ}
    vmax = float(np.max(np.abs(v_r))) or 1.0
    v_eps = max(1e-3 * vmax, 1e-6)
    sgn = np.sign(np.where(np.abs(v_r) > v_eps, v_r, 0.0))
    sp = np.abs(v_r)
    families: dict[str, np.ndarray] = {}
    # velocity: a friction curve, either direction (Coulomb, viscous, Stribeck-like decays)
    cols = [sgn, v_r]
    for vs in (0.01 * vmax, 0.05 * vmax):
        cols.append(sgn * exp(-sp / vs))
    families["velocity"] = np.column_stack(cols)
    # position: the best single period of a periodogram against position
    span = float(np.ptp(x))
    if span > 0:
        periods = geomspace(max(span / 500.0, 0.05), span, 120)
        share, _ = position_periodogram(x, wl, periods, constant=False)
        if np.max(share) > 0.0:
            P = float(periods[int(np.argmax(share))])
            families["position"] = np.column_stack([np.sin(2 * np.pi * x / P), np.cos(2 * np.pi * x / P)])
            res["position_period_mm"] = P
    # time since the last reversal, signed by the new direction
    since = time_since(reversal_times(v_r, starts, v_eps), n, Ts)
    families["after_reversal"] = np.column_stack(
        [sgn * ((since >= lo) & (since < hi)) for lo, hi in ((0, 0.01), (0.01, 0.03), (0.03, 0.1), (0.1, 0.3))])
    families["acceleration"] = np.column_stack([a_r, np.abs(a_r) * sgn])
    explained = {name: _explained(wl, A)[0] for name, A in families.items()}
    A_state = np.column_stack(list(families.values()))
    share_state = _explained(wl, A_state)[0]
    # time: blocks the state families leave, found with the blocks left out of their fit
    spans, fit_state = _state_blocks(wl, A_state, Ts, starts)
    rest = wl - fit_state
    blocks = []
    for i, j in spans:
        m = float(np.mean(rest[i:j]))  # the block's level above what the motion explains
        blocks.append({"t_start_s": float(t[i]), "t_end_s": float(t[j - 1]), "mean_mm_s2": m})
    test = _blocks_test(wl, A_state, spans)
    explained["time_blocks"] = test["r2_blocks"]
    time_share = sum(j - i for i, j in spans) / max(n, 1)
    res["explained"] = explained
    res["state_families_together"] = share_state
    res["blocks_test"] = test
    # time blocks name the cause only when they are localised (an external load); otherwise
    # the family of state variables that explains most does
    states = {k: v for k, v in explained.items() if k != "time_blocks"}
    res["dominant"] = max(states, key=states.get)
    res["blocks"] = blocks
    res["blocks_time_share"] = float(time_share)
    res["time_localised"] = bool(
        blocks and explained["time_blocks"] >= BLOCK_MIN_SHARE and time_share <= BLOCK_MAX_TIME_SHARE
        and explained["time_blocks"] > max(states.values())
        and test["blocks_unique_share"] >= 1.0 - BLOCK_MAX_STATE_SHARE and test["significant"])
    res["words"] = _words(res)
    return res


def _words(res: dict) -> str:
    ex = res["explained"]
    if res["time_localised"]:
        b = res["blocks"]
        size = float(np.median([abs(x["mean_mm_s2"]) for x in b]))
        dur = float(np.median([x["t_end_s"] - x["t_start_s"] for x in b]))
        when = ", ".join(f"{x['t_start_s']:.2f}–{x['t_end_s']:.2f} s" for x in b[:6]) + (" …" if len(b) > 6 else "")
        period = ""
        if len(b) >= 3:
            gaps = np.diff([x["t_start_s"] for x in b])
            if np.std(gaps) < 0.2 * np.mean(gaps):
                period = f" every {float(np.mean(gaps)):.2f} s"
        return (f"an extra acceleration of about {size:.3g} mm/s² (force = that × the moving mass) in "
                f"{len(b)} block{'s' if len(b) != 1 else ''} of about {dur:.2f} s{period} ({when}), "
                f"independent of position and speed: an external load, not a drive effect")
    name = res["dominant"]
    what = {"velocity": "depends on velocity (a friction curve other than Coulomb)",
            "position": f"is periodic in position (period {res.get('position_period_mm', 0):.3g} mm)",
            "after_reversal": "follows reversals (lost motion or breakaway)",
            "acceleration": "follows the commanded acceleration (a limit or an unmodelled inertia)",
            "time_blocks": "comes in time blocks the motion does not explain"}[name]
    # a noun phrase: the diagnosis says "The model would need <this>."
    return (f"an acceleration that {what}: {100 * ex[name]:.0f} % of the unexplained acceleration "
            f"(rms {res['rms_mm_s2']:.3g} mm/s² below {res['band_hz']:.0f} Hz)")


"""Where the free-run residual concentrates, and whether what is left is white (issue 5, step 2).

The residual is ``r = e − ê = x̂ − x`` (mm): recorded tracking error minus the model's
free-run tracking error (SPEC §5).  :func:`localise` measures it

* in time — the worst windows, with timestamps, and the blocks of time where the residual
  stands out of its own robust spread (:func:`excursion_blocks`: where a load that comes
  and goes, not the motion, puts the error);
* by operating condition — commanded speed bins, time since the last reversal, time since
  the last acceleration change (jerk event), commanded acceleration bins, position along
  the axis and a periodogram of the residual against position;
* in frequency — Welch spectrum peaks and coherence with the commanded acceleration;
* for whiteness — autocorrelation of r and cross-correlation with the commanded velocity
  with 99 % confidence bounds ±2.58/√N, as in system-identification residual analysis
  (Ljung, *System Identification*, §16.6).

Every figure is a plain float/list so the result drops straight into the JSON of SPEC §6.
"""

from __future__ import annotations

import numpy as np

from ident.fixed_order import dot, lstsq, matvec, moving_mean, sum_squares
from ident.portable_math import geomspace

__all__ = [
    "reversal_times",
    "time_since",
    "energy_share",
    "worst_windows",
    "excursion_blocks",
    "position_periodogram",
    "spectrum_peaks",
    "peak_in_band",
    "whiteness",
    "localise",
]

_Z99 = 2.576  # two-sided 99 % normal quantile


def reversal_times(v_r: np.ndarray, starts: np.ndarray, v_eps: float) -> np.ndarray:
    """Indices where the commanded direction of motion reverses (dwells in between ignored).

    Parameters
    ----------
    v_r : commanded velocity, mm/s.
    starts : first sample of each segment (bool mask); direction memory resets there.
    v_eps : speed below which the axis counts as at rest, mm/s.
    """
    idx = []
    last = 0
    for k in range(v_r.size):
        if starts[k]:
            last = 0
        s = 1 if v_r[k] > v_eps else (-1 if v_r[k] < -v_eps else 0)
        if s != 0:
            if last != 0 and s != last:
                idx.append(k)
            last = s
    return np.asarray(idx, dtype=np.int64)


def time_since(events: np.ndarray, n: int, Ts: float) -> np.ndarray:
    """Time since the latest event at or before each sample, s (inf before the first)."""
    out = np.full(n, np.inf)
    if events.size == 0:
        return out
    k = np.arange(n)
    pos = np.searchsorted(events, k, side="right") - 1
    ok = pos >= 0
    out[ok] = (k[ok] - events[pos[ok]]) * Ts
    return out


def energy_share(r: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    """(share of residual energy, share of time) inside ``mask``."""
    tot = float(np.sum(r * r))
    if tot == 0.0 or r.size == 0:
        return 0.0, float(np.mean(mask)) if r.size else 0.0
    return float(np.sum(r[mask] ** 2) / tot), float(np.mean(mask))


def worst_windows(r: np.ndarray, t: np.ndarray, width_s: float, count: int = 5) -> list[dict]:
    """The ``count`` non-overlapping windows of ``width_s`` s with the most residual energy."""
    n = r.size
    Ts = float(np.median(np.diff(t))) if n > 1 else 1.0
    w = max(1, int(round(width_s / Ts)))
    if n < w:
        w = n
    c = np.concatenate([[0.0], np.cumsum(r * r)])
    e = c[w:] - c[:-w]
    tot = float(c[-1]) or 1.0
    taken = np.zeros(e.size, dtype=bool)
    out = []
    order = np.argsort(e)[::-1]
    for i in order:
        if len(out) >= count:
            break
        if taken[i]:
            continue
        out.append(
            {
                "t_start_s": float(t[i]),
                "t_end_s": float(t[min(i + w - 1, n - 1)]),
                "energy_share": float(e[i] / tot),
                "rms_mm": float(np.sqrt(e[i] / w)),
            }
        )
        taken[max(0, i - w + 1) : i + w] = True
    return out


#: An excursion block is where a signal, smoothed over 50 ms, exceeds this many robust
#: standard deviations of itself (a 1-in-10⁴ excursion for Gaussian noise) …
BLOCK_SIGMAS = 4.0
#: … for at least this long, s (shorter excursions are the loop's own transients).
BLOCK_MIN_S = 0.03
#: Blocks starting this soon after a segment start are the restart transient, and blocks
#: ending this close to a segment end the edge of the zero-phase filters, s.
SEGMENT_EDGE_S = 0.1


def excursion_blocks(y: np.ndarray, Ts: float, starts: np.ndarray) -> list[tuple[int, int]]:
    """Stretches (start, end index) where ``y`` smoothed over 50 ms stands out of its own robust spread.

    Robust: the median and 1.4826 × the median absolute deviation, so blocks covering less
    than half of the time do not hide themselves by inflating the spread.  A stretch that
    starts within ``SEGMENT_EDGE_S`` of a segment start, ends within it of the segment's
    end (where zero-phase filters and differences have no data beyond) or covers more than
    half of its segment is the segment's own character (the low-speed set as a whole, the
    start transient), not something arriving during the motion: it is left out.
    """
    k = max(int(round(0.05 / Ts)), 1)
    ys = moving_mean(y, k)
    sigma = 1.4826 * float(np.median(np.abs(ys - np.median(ys)))) or 1e-12
    hot = np.abs(ys - np.median(ys)) > BLOCK_SIGMAS * sigma
    out = []
    i, n, gap = 0, y.size, max(int(round(BLOCK_MIN_S / Ts)), 1)
    while i < n:
        if not hot[i]:
            i += 1
            continue
        j = i
        while j < n and (hot[j] or np.any(hot[j:j + gap])):
            j += 1
        if (j - i) * Ts >= BLOCK_MIN_S:
            out.append((i, j))
        i = j
    seg_start = np.maximum.accumulate(np.where(starts, np.arange(n), 0))
    bounds = np.append(np.flatnonzero(starts), n)
    seg_len = np.diff(bounds)[np.searchsorted(bounds, np.arange(n), side="right") - 1]
    seg_end = seg_start + seg_len
    edge = int(round(SEGMENT_EDGE_S / Ts))
    return [(i, j) for i, j in out
            if i - seg_start[i] >= edge and seg_end[i] - j >= edge and (j - i) <= 0.5 * seg_len[i]]


#: The blocks reported are the fewest, largest first, that hold this share of the energy of all.
MAIN_BLOCKS_SHARE = 0.95


def time_blocks(r: np.ndarray, Ts: float, starts: np.ndarray, count: int = 20) -> dict:
    """Where in time the residual stands out: its main excursion blocks, their energy and time share.

    Every excursion block of ``r`` (:func:`excursion_blocks`) is ranked by its energy and
    the fewest that hold ``MAIN_BLOCKS_SHARE`` of the energy of all blocks are kept (a
    coloured residual has many small excursions besides the ones that matter); they are
    listed in time order, the first ``count``.
    """
    spans = excursion_blocks(r, Ts, starts)
    energy = np.array([sum_squares(r[i:j]) for i, j in spans])
    keep: list[tuple[int, int]] = []
    if spans:
        order = np.argsort(energy)[::-1]
        need = MAIN_BLOCKS_SHARE * float(energy.sum())
        acc = 0.0
        for k in order:
            keep.append(spans[k])
            acc += energy[k]
            if acc >= need:
                break
        keep.sort()
    mask = np.zeros(r.size, dtype=bool)
    for i, j in keep:
        mask[i:j] = True
    share, time_share = energy_share(r, mask)
    return {"count": len(keep), "energy_share": share, "time_share": time_share,
            "blocks": [{"t_start_s": float(i * Ts), "t_end_s": float((j - 1) * Ts),
                        "rms_mm": float(np.sqrt(np.mean(r[i:j] ** 2)))} for i, j in keep[:count]]}


def _bins(values: np.ndarray, r: np.ndarray, edges: list[float], unit: str) -> list[dict]:
    tot = float(np.sum(r * r)) or 1.0
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (values >= lo) & (values < hi)
        if not np.any(m):
            continue
        rows.append(
            {
                f"from_{unit}": float(lo),
                f"to_{unit}": float(hi) if np.isfinite(hi) else None,
                "time_share": float(np.mean(m)),
                "energy_share": float(np.sum(r[m] ** 2) / tot),
                "rms_mm": float(np.sqrt(np.mean(r[m] ** 2))),
            }
        )
    return rows


def _sin_cos(ph: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """sin and cos of the phases ``ph`` (rad) to ~2e-7, five times faster than in float64.

    The phase is reduced to ±π in float64 first (it can reach 10⁵ rad, past float32's
    resolution), the sine and cosine are taken in float32 (vectorised in numpy), and the
    results are returned in float64 for the sums, which need its precision.  A periodogram
    ranks shares of the residual variance; an error of 1e-7 in them changes nothing.
    """
    two_pi = 2.0 * np.pi
    red = (ph - two_pi * np.round(ph * (1.0 / two_pi))).astype(np.float32)
    return np.sin(red).astype(float), np.cos(red).astype(float)


def position_periodogram(
    x: np.ndarray, r: np.ndarray, periods_mm: np.ndarray, constant: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Share of residual variance explained by ``c_s sin(2πx/P) + c_c cos(2πx/P)`` per period P.

    A least-squares (Lomb–Scargle-like) periodogram of the residual against position, mm;
    returns (explained share per period, complex amplitude c_s + j·c_c per period, mm).
    With ``constant`` an offset is fitted alongside (r's mean taken out first), otherwise
    the pair alone explains r.  Each period's fit is the 2×2 normal equations of the sine
    and cosine columns (centred with ``constant``: the same coefficients as the fit with an
    offset column), solved for a block of periods at once.
    """
    x = np.asarray(x, dtype=float)
    rc = r - r.mean() if constant else np.asarray(r, dtype=float)
    den = sum_squares(rc) or 1.0
    periods_mm = np.asarray(periods_mm, dtype=float)
    share = np.zeros(periods_mm.size)
    amp = np.zeros(periods_mm.size, dtype=complex)
    block = max(1, 400_000 // max(x.size, 1))  # periods per block: a few MB of sines
    for i0 in range(0, periods_mm.size, block):
        ph = (2.0 * np.pi / periods_mm[i0 : i0 + block])[:, None] * x[None, :]
        S, C = _sin_cos(ph)
        if constant:
            S -= S.mean(axis=1, keepdims=True)
            C -= C.mean(axis=1, keepdims=True)
        gss, gcc, gsc = (np.einsum("ij,ij->i", S, S), np.einsum("ij,ij->i", C, C),
                         np.einsum("ij,ij->i", S, C))
        bs, bc = matvec(S, rc), matvec(C, rc)
        det = gss * gcc - gsc ** 2
        for j in range(det.size):
            if det[j] > 1e-12 * gss[j] * gcc[j] and det[j] > 0:
                a = (gcc[j] * bs[j] - gsc[j] * bc[j]) / det[j]
                b = (gss[j] * bc[j] - gsc[j] * bs[j]) / det[j]
            else:  # sine and cosine (nearly) collinear over the travel: minimum-norm fit
                a, b = lstsq(np.column_stack([S[j], C[j]]), rc)
            share[i0 + j] = (a * bs[j] + b * bc[j]) / den
            amp[i0 + j] = a + 1j * b
    return share, amp


#: Lower edge of the band a peak's ``share_above_20_hz`` is taken in, Hz.
HIGH_BAND_HZ = 20.0


def spectrum_peaks(r: np.ndarray, Ts: float, count: int = 3, f_min: float = 2.0) -> tuple[list[dict], np.ndarray, np.ndarray]:
    """Welch spectrum of r and its ``count`` strongest local peaks above ``f_min`` Hz.

    Each peak: frequency (Hz), share of residual power in ±10 % around it, the same power
    as a share of the power above ``HIGH_BAND_HZ`` (a structural mode concentrates there, where
    the slow tracking-error residual does not mask it), and its prominence over the
    spectrum's median (ratio).
    """
    from scipy import signal  # half a second to import: only when the diagnosis runs

    nper = int(min(r.size, max(256, 2 ** int(np.log2(max(r.size // 8, 256))))))
    f, P = signal.welch(r - r.mean(), fs=1.0 / Ts, nperseg=nper)
    tot = float(np.sum(P)) or 1.0
    tot_high = float(np.sum(P[f > HIGH_BAND_HZ])) or 1.0
    med = float(np.median(P[f >= f_min])) if np.any(f >= f_min) else 1.0
    peaks, _ = signal.find_peaks(P)
    peaks = [p for p in peaks if f[p] >= f_min]
    peaks.sort(key=lambda p: P[p], reverse=True)
    rows = []
    for p in peaks[:count]:
        band = (f >= 0.9 * f[p]) & (f <= 1.1 * f[p])
        rows.append(
            {
                "freq_hz": float(f[p]),
                "power_share": float(np.sum(P[band]) / tot),
                "share_above_20_hz": float(np.sum(P[band]) / tot_high) if f[p] > HIGH_BAND_HZ else 0.0,
                "prominence": float(P[p] / med) if med > 0 else float("inf"),
            }
        )
    return rows, f, P


def peak_in_band(peaks: list[dict], lo_hz: float, hi_hz: float | None = None, tol: float = 0.2) -> bool:
    """True when one of ``peaks`` (:func:`spectrum_peaks`) lies in ``lo_hz`` … ``hi_hz``
    (``lo_hz`` alone when ``hi_hz`` is None), widened by ``tol`` in log-frequency either side."""
    hi_hz = lo_hz if hi_hz is None else hi_hz
    if not (np.isfinite(lo_hz) and np.isfinite(hi_hz) and 0 < lo_hz <= hi_hz):
        return False
    return any(pk["freq_hz"] > 0 and np.log(lo_hz) - tol < np.log(pk["freq_hz"]) < np.log(hi_hz) + tol
               for pk in peaks)


def _xcorr(a: np.ndarray, b: np.ndarray, lags: np.ndarray) -> np.ndarray:
    a = a - a.mean()
    b = b - b.mean()
    den = float(np.sqrt(sum_squares(a) * sum_squares(b))) or 1.0
    n = a.size
    out = np.empty(lags.size)
    for i, L in enumerate(lags):
        if L >= 0:
            out[i] = dot(a[L:], b[: n - L]) / den
        else:
            out[i] = dot(a[: n + L], b[-L:]) / den
    return out


def whiteness(r: np.ndarray, u: np.ndarray, max_lag: int = 50) -> dict:
    """Residual autocorrelation and cross-correlation with the command, 99 % bounds.

    Returns the bound ±2.58/√N, the fractions of lags 1..M (auto) and −M..M (cross)
    outside it, the worst lags, and the booleans ``white`` / ``uncorrelated_with_command``
    (at most 1 % of lags outside, as the bound allows by chance).
    """
    n = r.size
    bound = _Z99 / np.sqrt(max(n, 1))
    lags = np.arange(0, max_lag + 1)
    acf = _xcorr(r, r, lags)
    xl = np.arange(-max_lag, max_lag + 1)
    ccf = _xcorr(r, u, xl)
    out_a = np.abs(acf[1:]) > bound
    out_c = np.abs(ccf) > bound
    ic = int(np.argmax(np.abs(ccf)))
    return {
        "bound_99": float(bound),
        "autocorrelation_outside": float(np.mean(out_a)),
        "autocorrelation_lag1": float(acf[1]) if acf.size > 1 else 0.0,
        "cross_correlation_outside": float(np.mean(out_c)),
        "cross_correlation_peak": float(ccf[ic]),
        "cross_correlation_peak_lag_samples": int(xl[ic]),
        "white": bool(np.mean(out_a) <= 0.01),
        "uncorrelated_with_command": bool(np.mean(out_c) <= 0.01),
        "acf": acf,
        "ccf": ccf,
    }


def localise(
    r: np.ndarray,
    x_r: np.ndarray,
    x: np.ndarray,
    v_r: np.ndarray,
    a_r: np.ndarray,
    Ts: float,
    starts: np.ndarray,
) -> dict:
    """The full localisation of residual ``r`` (mm) for the JSON "mismatch" block.

    Parameters
    ----------
    r : residual e − ê = x̂ − x, mm.
    x_r, x : commanded and recorded actual position, mm.
    v_r, a_r : commanded velocity (mm/s) and acceleration (mm/s²).
    Ts : sample period, s.
    starts : first sample of each segment (bool mask).

    Keys ending in ``_`` hold arrays for plots and are dropped from the JSON.
    """
    n = r.size
    t = np.arange(n) * Ts
    vmax = float(np.max(np.abs(v_r))) or 1.0
    amax = float(np.max(np.abs(a_r))) or 1.0
    v_eps = max(1e-3 * vmax, 1e-6)
    tot = float(np.sum(r * r))
    res: dict = {"rms_mm": float(np.sqrt(tot / max(n, 1))), "duration_s": float(n * Ts)}

    res["worst_windows"] = worst_windows(r, t, 0.05)
    res["time_blocks"] = time_blocks(r, Ts, starts)

    speed = np.abs(v_r)
    edges = [0.0, v_eps, 0.01 * vmax, 0.1 * vmax, 0.3 * vmax, 0.6 * vmax, np.inf]
    res["by_speed"] = _bins(speed, r, edges, "mm_s")
    moving = speed > v_eps
    low = moving & (speed < 0.1 * vmax)
    res["low_speed_share"], res["low_speed_time_share"] = energy_share(r, low)
    res["at_rest_share"], res["at_rest_time_share"] = energy_share(r, ~moving)

    rev = reversal_times(v_r, starts, v_eps)
    res["reversals"] = int(rev.size)
    since_rev = time_since(rev, n, Ts)
    res["by_time_since_reversal"] = _bins(
        since_rev, r, [0.0, 0.01, 0.03, 0.1, 0.3, np.inf], "s"
    )
    res["after_reversal_30ms_share"], res["after_reversal_30ms_time_share"] = energy_share(r, since_rev < 0.03)
    res["after_reversal_100ms_share"], res["after_reversal_100ms_time_share"] = energy_share(r, since_rev < 0.1)

    da = np.abs(np.diff(a_r, prepend=a_r[0]))
    jerk_ev = np.flatnonzero(da > 0.2 * amax)
    since_jerk = time_since(jerk_ev, n, Ts)
    res["after_jerk_30ms_share"], res["after_jerk_30ms_time_share"] = energy_share(r, since_jerk < 0.03)
    res["by_acceleration"] = _bins(
        np.abs(a_r), r, [0.0, 0.05 * amax, 0.5 * amax, 0.9 * amax, np.inf], "mm_s2"
    )
    res["high_acceleration_share"], res["high_acceleration_time_share"] = energy_share(
        r, np.abs(a_r) >= 0.9 * amax
    )
    # speed dependence outside the first 100 ms after reversals: ratio of rms, fast vs slow half
    steady = moving & (since_rev >= 0.1)
    if np.count_nonzero(steady) > 20:
        med = float(np.median(speed[steady]))
        fast = steady & (speed >= med)
        slow = steady & (speed < med)
        rf = float(np.sqrt(np.mean(r[fast] ** 2))) if np.any(fast) else 0.0
        rs = float(np.sqrt(np.mean(r[slow] ** 2))) if np.any(slow) else 0.0
        res["fast_to_slow_rms_ratio"] = rf / rs if rs > 0 else float("inf")
    else:
        res["fast_to_slow_rms_ratio"] = 1.0

    # position along the axis, and a periodogram against position
    lo, hi = float(np.min(x)), float(np.max(x))
    span = hi - lo
    pedges = list(np.linspace(lo, hi + 1e-9, 6)) if span > 0 else [lo, lo + 1.0]
    res["by_position"] = _bins(x, r, pedges, "mm")
    if span > 0:
        p_min = max(4.0 * float(np.median(np.abs(np.diff(x))[moving[1:]] if np.any(moving[1:]) else [1e-3])), 0.05)
        p_min = max(p_min, span / 2000.0)
        periods = geomspace(p_min, max(span, p_min * 1.5), 300)
        share, amp = position_periodogram(x, r, periods)
        i = int(np.argmax(share))
        res["position_periodic"] = {
            "period_mm": float(periods[i]),
            "explained_share": float(share[i]),
            "amplitude_mm": float(abs(amp[i])),
            "median_share": float(np.median(share)),
        }
        res["position_periodogram_"] = (periods, share)
    else:
        res["position_periodic"] = {"period_mm": 0.0, "explained_share": 0.0, "amplitude_mm": 0.0, "median_share": 0.0}

    peaks, f, P = spectrum_peaks(r, Ts)
    res["spectrum_peaks"] = peaks
    res["spectrum_"] = (f, P)
    if n >= 512:
        from scipy import signal

        fc, coh = signal.coherence(a_r, r, fs=1.0 / Ts, nperseg=min(1024, n // 4))
        res["coherence_with_command_mean"] = float(np.mean(coh[fc > 1.0])) if np.any(fc > 1.0) else 0.0
        res["coherence_"] = (fc, coh)
    else:
        res["coherence_with_command_mean"] = 0.0
    res["whiteness"] = whiteness(r, v_r)
    return res

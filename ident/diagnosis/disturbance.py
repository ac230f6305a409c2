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

import math

import numpy as np
from scipy import signal

from ident.diagnosis.residuals import reversal_times, time_since

__all__ = ["equivalent_disturbance", "analyse_disturbance", "block_input", "DISTURBANCE_BAND_HZ"]

#: Low-pass of the recorded position before differentiation, Hz (keeps ẍ's noise bounded).
DIFFERENTIATION_HZ = 40.0
#: Band a load or a slow drive effect acts in: w is analysed low-passed to this, Hz.
DISTURBANCE_BAND_HZ = 10.0
#: A time block is where the unexplained disturbance, smoothed over 50 ms, exceeds this
#: many robust standard deviations of itself (a 1-in-10⁴ excursion for Gaussian noise) …
BLOCK_SIGMAS = 4.0
#: … for at least this long, s (shorter excursions are the loop's own transients).
BLOCK_MIN_S = 0.03
#: Blocks starting this soon after a segment start are the restart transient, s.
SEGMENT_EDGE_S = 0.1
#: The disturbance is called time-localised (an external load) when the blocks explain at
#: least this share of its energy while covering at most ``BLOCK_MAX_TIME_SHARE`` of the time …
BLOCK_MIN_SHARE = 0.5
BLOCK_MAX_TIME_SHARE = 0.5
#: … and explain more than any state family (velocity, position, reversal, acceleration).


def _lowpass(y: np.ndarray, Ts: float, f_hz: float, starts: np.ndarray) -> np.ndarray:
    """Zero-phase 2nd-order Butterworth low-pass per segment (edges padded by reflection)."""
    out = np.array(y, dtype=float, copy=True)
    wn = min(f_hz * 2.0 * Ts, 0.99)
    b, a = signal.butter(2, wn)
    bounds = np.append(np.flatnonzero(starts), y.size)
    for s, e in zip(bounds[:-1], bounds[1:]):
        if e - s > 15:
            out[s:e] = signal.filtfilt(b, a, y[s:e], padlen=min(3 * max(len(a), len(b)), e - s - 1))
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
    den = float(y @ y)
    if den <= 0 or A.size == 0:
        return 0.0, np.zeros_like(y)
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    coef, *_ = np.linalg.lstsq(A / scale, y, rcond=None)
    fit = (A / scale) @ coef
    return float(fit @ fit) / den, fit


def _blocks(y: np.ndarray, Ts: float, starts: np.ndarray) -> list[tuple[int, int]]:
    """Contiguous stretches where ``y`` smoothed over 50 ms stands out of its own robust spread.

    A stretch that starts within ``SEGMENT_EDGE_S`` of a segment start or covers more than
    half of its segment is the segment's own character (the low-speed set as a whole, the
    start transient), not a load arriving during the motion: it is left out.
    """
    k = max(int(round(0.05 / Ts)), 1)
    ys = np.convolve(y, np.ones(k) / k, mode="same")
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
    edge = int(round(SEGMENT_EDGE_S / Ts))
    return [(i, j) for i, j in out if i - seg_start[i] >= edge and (j - i) <= 0.5 * seg_len[i]]


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
        cols.append(sgn * np.exp(-sp / vs))
    families["velocity"] = np.column_stack(cols)
    # position: the best single period of a periodogram against position
    span = float(np.ptp(x))
    if span > 0:
        best = (0.0, None)
        for P in np.geomspace(max(span / 500.0, 0.05), span, 120):
            ph = 2 * np.pi * x / P
            A = np.column_stack([np.sin(ph), np.cos(ph)])
            s, _ = _explained(wl, A)
            if s > best[0]:
                best = (s, A, P)
        if best[1] is not None:
            families["position"] = best[1]
            res["position_period_mm"] = float(best[2])
    # time since the last reversal, signed by the new direction
    since = time_since(reversal_times(v_r, starts, v_eps), n, Ts)
    families["after_reversal"] = np.column_stack(
        [sgn * ((since >= lo) & (since < hi)) for lo, hi in ((0, 0.01), (0.01, 0.03), (0.03, 0.1), (0.1, 0.3))])
    families["acceleration"] = np.column_stack([a_r, np.abs(a_r) * sgn])
    explained = {name: _explained(wl, A)[0] for name, A in families.items()}
    # time: what the state families together leave, in blocks
    share_state, fit_state = _explained(wl, np.column_stack(list(families.values())))
    rest = wl - fit_state
    spans = _blocks(rest, Ts, starts)
    blocks = []
    bw = np.zeros(n)
    for i, j in spans:
        m = float(np.mean(rest[i:j]))
        bw[i:j] = m
        blocks.append({"t_start_s": float(t[i]), "t_end_s": float(t[j - 1]), "mean_mm_s2": m})
    den = float(wl @ wl) or 1.0
    explained["time_blocks"] = float(np.clip(1.0 - float((wl - bw) @ (wl - bw)) / den, 0.0, 1.0))
    time_share = sum(j - i for i, j in spans) / max(n, 1)
    res["explained"] = explained
    res["state_families_together"] = share_state
    # time blocks name the cause only when they are localised (an external load); otherwise
    # the family of state variables that explains most does
    states = {k: v for k, v in explained.items() if k != "time_blocks"}
    res["dominant"] = max(states, key=states.get)
    res["blocks"] = blocks[:20]
    res["blocks_time_share"] = float(time_share)
    res["time_localised"] = bool(
        blocks and explained["time_blocks"] >= BLOCK_MIN_SHARE and time_share <= BLOCK_MAX_TIME_SHARE
        and explained["time_blocks"] > max(v for k, v in explained.items() if k != "time_blocks"))
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
    return (f"the unexplained acceleration (rms {res['rms_mm_s2']:.3g} mm/s² below {res['band_hz']:.0f} Hz) "
            f"{what}: {100 * ex[name]:.0f} % of it")


def fit_pct(e: np.ndarray, r: np.ndarray) -> float:
    """SPEC §5 tracking-error fit of a residual ``r`` = x̂ − x against ``e`` = x_r − x, %."""
    den = float(np.linalg.norm(e - e.mean()))
    return 100.0 * (1.0 - float(np.linalg.norm(r)) / den) if den > 0 else math.nan

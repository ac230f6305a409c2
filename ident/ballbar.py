"""A synthetic ballbar test: the ISO 230-4 circular test read as a Renishaw QC20 user reads it.

A run is one full circle of a two-axis machine about a nominal centre ``c`` with radius
``R`` at path speed ``v``, started and stopped at θ = 45° so that the four axis reversals
are in steady motion.  θ is counter-clockwise from the +X (first) axis about ``c``; the
radial deviation is ``dr = |p − c| − R`` (mm).  The first axis reverses where its
position is extreme, at θ = 0° and 180°; the second at 90° and 270°.

What is read from ``dr(θ)`` (orders are harmonics in θ, coefficients in mm)::

    dr ≈ a0 + a1 cos θ + b1 sin θ + a2 cos 2θ + b2 sin 2θ + bx·gx(θ) + by·gy(θ) + ripple

* order 1: the offset of the path's centre from ``c``; order 0: radius error;
* ``b2``: the X and Y lags differ.  Commanded (R cos ωt, R sin ωt), X late by τx and
  Y by τy: |p|² = R²[1 + sin(ω(τx−τy)) sin(2θ − ω(τx+τy))], so
  ``|p| ≈ R[1 + ½ω(τx−τy) sin 2θ]`` for ccw (ω > 0) and the sign flips for cw.  With
  ``v = ωR``: ``b2_ccw − b2_cw = v·Δτ``, ``Δτ = τx − τy`` (servo mismatch);
* ``a2``: the axes' gains differ.  x scaled by 1+ε gives dr ≈ Rε cos²θ, so
  ``a2 = Rε/2`` (scale mismatch, same in both directions);
* the direction-symmetric part of ``b2``: x' = x + αy gives dr ≈ (αR/2) sin 2θ
  (squareness; a drive model has none);
* ``gx, gy``: lost motion.  An axis that trails its command by b/2 after each reversal
  shifts the half-circle it draws: ``gx = ½ s·sign(sin θ)·cos θ``,
  ``gy = −½ s·sign(cos θ)·sin θ`` (s = +1 ccw, −1 cw), a step of +b in dr at every
  reversal of that axis (Renishaw's "backlash" step);
* reversal spikes: what is left in a short window after a reversal;
* ripple: many-lobed periodic error ("cyclic error"), orders 3…60.

References: ISO 230-4:2005, circular tests for numerically controlled machine tools
(circular deviation G, circular hysteresis H); Renishaw QC20-W ballbar system
description and diagnostics (servo mismatch, scale mismatch, squareness, reversal
spikes, backlash, cyclic error).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import InputError

__all__ = ["BallbarRun", "ballbar_run", "check_test_size", "Reversal", "AxisReversals", "RunFeatures",
           "BallbarResult", "analyse_ballbar", "words", "plot_ballbar"]

#: Commanded path speed below this fraction of the feed is feed-in/feed-out (not used).
STEADY_FRACTION = 0.99
#: Without the commanded path, this much travel (rad) is dropped at each end.
EDGE_ANGLE = np.radians(10.0)
#: Spike window after a reversal: the arc travelled in this time (s).  A servo recovers
#: from a reversal in a few closed-loop time constants, tens of ms.
SPIKE_TIME = 0.040
#: The window opens this fraction of it before the reversal (10 ms): where the reversal
#: falls depends on whose angle is used (actual, commanded, or a QC20's time-based one).
SPIKE_LEAD = 0.25
#: Samples averaged either side of a reversal to read the step: at least this arc (rad).
STEP_ARC = np.radians(3.0)
#: Cyclic-error orders searched.
CYCLIC_ORDERS = (3, 60)
#: Wording rule: a feature is worded when its size ≥ max(FLOOR_UM, FRACTION × largest G);
#: a cyclic order must also be CYCLIC_PROMINENCE × the median of the spectrum.
FLOOR_UM, FRACTION, CYCLIC_PROMINENCE = 1.0, 0.05, 3.0


@dataclass(frozen=True, eq=False)
class BallbarRun:
    """One circle run prepared for analysis (arrays shape (N,), in order of travel).

    ``theta`` is the angle of the actual point about the nominal centre (rad, wrapped
    to [0, 2π), ccw from +X; order of travel is the sample order); ``dr`` its radial
    deviation |p − c| − R (mm); ``used`` the samples in steady motion.
    """

    direction: str
    feed: float
    radius: float
    centre: tuple[float, float]
    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    dr: np.ndarray
    used: np.ndarray

    @property
    def sense(self) -> int:
        """+1 for ccw, −1 for cw."""
        return 1 if self.direction == "ccw" else -1


def check_test_size(radius: float, feed: float) -> None:
    """Refuse a test radius or feed that is not positive, naming the one that is not, and a
    feed too fast for the radius: the axes reverse every quarter turn, and a reversal's
    windows (its spike, then the step read after it, :func:`_analyse_run`) must end before
    the next reversal's begin, else nothing is left to fit the baseline between them and
    every figure would be read from reversal transients."""
    for name, value, unit in (("radius", radius, "mm"), ("feed", feed, "mm/s")):
        if not value > 0:
            raise InputError.about(name, f"{name} must be > 0 {unit}, got {value:g}")
    w, wm = _reversal_arcs(feed, radius)
    if 3 * w + wm > 0.5 * np.pi:  # the spike zone [−w, 2w], then the step's window wm
        quarter_ms = 1e3 * 0.5 * np.pi * radius / feed
        raise InputError.about("feed", f"feed {feed:g} mm/s on radius {radius:g} mm: a quarter turn takes "
                                       f"{quarter_ms:.3g} ms, and a reversal's spike and step are read over "
                                       f"{4e3 * SPIKE_TIME:.0f} ms; give a feed of at most "
                                       f"{np.pi * radius / (8 * SPIKE_TIME):.3g} mm/s on this radius")


def _reversal_arcs(feed: float, radius: float) -> tuple[float, float]:
    """(w, wm), rad: the arc travelled in SPIKE_TIME at ``feed`` on ``radius``, and the width of
    the windows a reversal's step is read over on either side of its spike zone."""
    w = feed * SPIKE_TIME / radius
    return w, max(STEP_ARC, w)


def ballbar_run(x: np.ndarray, y: np.ndarray, *, centre: tuple[float, float], radius: float,
                feed: float, direction: str, xc: np.ndarray | None = None,
                yc: np.ndarray | None = None, dt: float | None = None) -> BallbarRun:
    """Prepare one run.

    Parameters
    ----------
    x, y : actual positions, mm, shape (N,), in order of travel.
    centre, radius : nominal circle, mm.
    feed : programmed path speed, mm/s.
    direction : "ccw" or "cw".
    xc, yc : commanded positions, mm, shape (N,).  When given, samples whose commanded
        speed is not within 1 % of ``feed`` are dropped; otherwise the first and last 10°
        of travel are.  θ is always the actual point's angle: with the commanded angle
        a lag of both axes tilts the servo ellipse by ω(τx+τy)/2 and leaks
        −½Rω²Δτ(τx+τy) into cos 2θ (0.3 µm of false scale mismatch at 25 mm/s).
    dt : sample period, s; without it the commanded speed is compared with the median
        step (uniform sampling, mostly steady motion).
    """
    if direction not in ("ccw", "cw"):
        raise InputError.about("direction", f"direction {direction!r}: choose ccw or cw")
    check_test_size(radius, feed)
    x, y = np.asarray(x, float).ravel(), np.asarray(y, float).ravel()
    if x.shape != y.shape or x.size < 20:
        raise InputError(f"x has {x.size} samples and y {y.size}: need two equal arrays of ≥ 20")
    cx, cy = map(float, centre)
    s = 1 if direction == "ccw" else -1
    dr = np.hypot(x - cx, y - cy) - radius
    ang = np.arctan2(y - cy, x - cx)
    if (xc is None) != (yc is None):
        raise InputError.about("xc", "give both xc and yc, or neither")
    if xc is not None:
        xc, yc = np.asarray(xc, float).ravel(), np.asarray(yc, float).ravel()
        if xc.shape != x.shape or yc.shape != x.shape:
            raise InputError(f"xc/yc have {xc.size}/{yc.size} samples but x has {x.size}")
        step = np.hypot(np.diff(xc), np.diff(yc))
        ref = feed * dt if dt else float(np.median(step[step > 0])) if np.any(step > 0) else 1.0
        # A sample is steady when the steps on both sides of it are at the feed (within 1 %:
        # a rapid onto the circle is fast but not the test).
        fast = (step >= STEADY_FRACTION * ref) & (step <= ref / STEADY_FRACTION)
        used = np.r_[False, fast] & np.r_[fast, False]
    else:
        used = None
    travel = s * (np.unwrap(ang) - np.unwrap(ang)[0])
    if travel[-1] <= 0:
        raise InputError.about("direction",
                               f"direction {direction!r} but the path runs the other way")
    if used is None:
        used = (travel >= EDGE_ANGLE) & (travel <= travel[-1] - EDGE_ANGLE)
    if used.sum() < 20:
        raise InputError(f"only {int(used.sum())} samples in steady motion at feed {feed} mm/s")
    return BallbarRun(direction, float(feed), float(radius), (cx, cy), x, y,
                      np.mod(ang, 2 * np.pi), dr, used)


@dataclass(frozen=True)
class Reversal:
    """One axis reversal in one run, µm.

    With w the arc travelled in SPIKE_TIME (40 ms) at the feed, d the arc from the
    reversal in the direction of travel: ``spike_um`` is the signed extreme (+ outward)
    of dr − baseline for −w/4 ≤ d ≤ w, the baseline being harmonics ≤ 2, the lost motion
    and the dominant ripple fitted away from −w ≤ d ≤ 2w; ``step_um`` is the mean of
    dr − harmonics over 2w < d ≤ 2w + max(3°, w) minus that over −w − max(3°, w) ≤ d < −w
    (+: lost motion, the axis trailing its command after the reversal).
    """

    axis: str
    angle_deg: float
    direction: str
    spike_um: float
    step_um: float


@dataclass(frozen=True)
class AxisReversals:
    """One axis's reversals over all runs: mean |spike| and mean step, µm; the first
    axis reverses at 0° and 180°, the second at 90° and 270°."""

    axis: str
    angles_deg: tuple[float, float]
    spike_um: float
    step_um: float


@dataclass(frozen=True)
class RunFeatures:
    """Per-run figures, µm: circular deviation G about the least-squares circle (LSC)
    centre, the LSC centre offset from the nominal centre and LSC radius error, and the
    harmonic coefficients about the nominal centre (a1, b1, a2, b2) with lost motion
    removed."""

    direction: str
    feed: float
    circularity_um: float
    lsc_offset_um: tuple[float, float]
    lsc_radius_error_um: float
    harmonics_um: tuple[float, float, float, float]
    reversals: tuple[Reversal, ...]


@dataclass(frozen=True, eq=False)
class BallbarResult:
    """The figures of a ballbar test (see the module docstring for each definition).

    ``servo_mismatch_ms`` is Δτ = τx − τy (+: the first axis lags) and
    ``servo_mismatch_um`` = ½·v·Δτ the ellipse's radial amplitude; ``servo_ellipse_deg``
    gives per direction the diagonal (45: X+Y+, 135: X−Y+) along which it lies;
    ``scale_mismatch_um`` = a2 (mean over runs), ``scale_mismatch_ppm`` = 2·a2/R
    (+: the first axis draws longer); ``squareness_um`` = (b2_ccw + b2_cw)/2,
    ``squareness_urad`` = 2·squareness/R (+: stretched along 45°, as from an axis angle
    below 90°), None with one direction; ``hysteresis_um``: ISO 230-4 H, max
    |r_ccw(θ) − r_cw(θ)| about the mean of the two LSC centres, None with one
    direction; ``cyclic_spectrum_um``: amplitude of orders 3…60 of the residual (mean
    over runs), ``cyclic_order`` its largest; ``threshold_um``: the wording threshold
    (:func:`words`); ``data``: the runs analysed (for plots, not in :meth:`to_dict`).
    """

    axes: tuple[str, str]
    radius: float
    runs: tuple[RunFeatures, ...]
    hysteresis_um: float | None
    servo_mismatch_ms: float
    servo_mismatch_um: float
    servo_ellipse_deg: dict[str, int]
    servo_from_one_direction: bool
    scale_mismatch_um: float
    scale_mismatch_ppm: float
    squareness_um: float | None
    squareness_urad: float | None
    axis_reversals: tuple[AxisReversals, ...]
    cyclic_order: int
    cyclic_amplitude_um: float
    cyclic_spectrum_um: tuple[float, ...]
    threshold_um: float
    data: tuple[BallbarRun, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form (NaN → None; the arrays in ``data`` are left out)."""
        d = asdict(self)
        d.pop("data")
        d["cyclic_orders"] = list(CYCLIC_ORDERS)
        return _clean(d)


def _clean(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _clean(w) for k, w in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(w) for w in v]
    if isinstance(v, (float, np.floating)):
        return None if not np.isfinite(v) else float(v)
    if isinstance(v, np.integer):
        return int(v)
    return v


def _nanmean(v: Sequence[float]) -> float:
    v = np.asarray(v, float)
    return float(v[np.isfinite(v)].mean()) if np.isfinite(v).any() else float("nan")


def _harmonics(theta: np.ndarray) -> np.ndarray:
    return np.column_stack([np.ones_like(theta), np.cos(theta), np.sin(theta),
                            np.cos(2 * theta), np.sin(2 * theta)])


def _lost_motion(theta: np.ndarray, s: int) -> np.ndarray:
    """Columns gx, gy: dr per mm of lost motion on each axis (module docstring)."""
    return np.column_stack([0.5 * s * np.sign(np.sin(theta)) * np.cos(theta),
                            -0.5 * s * np.sign(np.cos(theta)) * np.sin(theta)])


def _spectrum(theta: np.ndarray, res: np.ndarray) -> np.ndarray:
    """Amplitude (mm) of each order in CYCLIC_ORDERS, fitted one order at a time: a joint
    fit of ~60 orders is ill-conditioned across the gaps (feed-in, reversal windows)."""
    out = []
    for k in range(CYCLIC_ORDERS[0], CYCLIC_ORDERS[1] + 1):
        A = np.column_stack([np.ones_like(theta), np.cos(k * theta), np.sin(k * theta)])
        out.append(np.hypot(*np.linalg.lstsq(A, res, rcond=None)[0][1:]))
    return np.array(out)


def _lsc(run: BallbarRun) -> tuple[np.ndarray, float, float]:
    """Least-squares circle (Gauss–Newton on the radial residual): centre, radius, G (mm)."""
    p = np.column_stack([run.x, run.y])[run.used]
    c = np.array(run.centre, float)
    for _ in range(4):
        d = p - c
        r = np.hypot(*d.T)
        A = np.column_stack([np.ones_like(r), d[:, 0] / r, d[:, 1] / r])
        sol = np.linalg.lstsq(A, r, rcond=None)[0]
        c = c + sol[1:]
    r = np.hypot(*(p - c).T)
    return c, float(r.mean()), float(np.ptp(r))


_REVERSALS = ((0, 0.0), (0, np.pi), (1, 0.5 * np.pi), (1, 1.5 * np.pi))


def _analyse_run(run: BallbarRun, axes: tuple[str, str]):
    s, th, dr, used = run.sense, run.theta, run.dr, run.used
    w, wm = _reversal_arcs(run.feed, run.radius)      # spike window, step windows, rad
    # d: signed arc from each reversal in the direction of travel, rad.
    d = [s * (np.mod(th - a + np.pi, 2 * np.pi) - np.pi) for _, a in _REVERSALS]
    zone = np.any([(di >= -w) & (di <= 2 * w) for di in d], axis=0)
    fit = used & ~zone
    H, G = _harmonics(th), _lost_motion(th, s)
    b, ripple = np.zeros(2), None
    # Alternate: (1) harmonics ≤ 2 plus the dominant ripple, with the lost motion found
    # so far removed; (2) the lost motion from the local steps, which a smooth baseline
    # cannot bias (fitted jointly, a step would leak into sin 2θ, being 85 % like it);
    # (3) the ripple order, so that a cyclic error is not read as steps or spikes.
    for _ in range(4):
        Hx = H if ripple is None else np.column_stack([H, np.cos(ripple * th), np.sin(ripple * th)])
        h = np.linalg.lstsq(Hx[fit], (dr - G @ b)[fit], rcond=None)[0]
        steps = []
        for (ax, _), di in zip(_REVERSALS, d):
            # The other axis's lost motion has a slope here; this axis's is flat.
            res_h = dr - Hx @ h - G[:, 1 - ax] * b[1 - ax]
            after = used & (di > 2 * w) & (di <= 2 * w + wm)
            before = used & (di < -w) & (di >= -w - wm)
            ok = after.any() and before.any()
            steps.append(res_h[after].mean() - res_h[before].mean() if ok else np.nan)
        b = np.nan_to_num([_nanmean(steps[:2]), _nanmean(steps[2:])])
        res = dr - H @ h[:5] - G @ b                  # ripple kept: its spectrum
        spec = _spectrum(th[fit], res[fit])
        k = int(np.argmax(spec))
        ripple = CYCLIC_ORDERS[0] + k if spec[k] >= CYCLIC_PROMINENCE * np.median(spec) else None
    smooth = res - (Hx[:, 5:] @ h[5:])               # ripple removed
    revs = []
    for (ax, a), di, st in zip(_REVERSALS, d, steps):
        win = used & (di >= -SPIKE_LEAD * w) & (di <= w)
        spike = smooth[win][np.argmax(np.abs(smooth[win]))] if win.any() else np.nan
        revs.append(Reversal(axes[ax], float(np.degrees(a)), run.direction,
                             float(1e3 * spike), float(1e3 * st)))
    c, r_lsc, g = _lsc(run)
    feat = RunFeatures(run.direction, run.feed, 1e3 * g,
                       tuple(float(v) for v in 1e3 * (c - np.array(run.centre))),
                       1e3 * (r_lsc - run.radius),
                       tuple(float(v) for v in 1e3 * h[1:5]), tuple(revs))
    return feat, spec, c, r_lsc


def _hysteresis(runs: Sequence[BallbarRun], centres: Sequence[np.ndarray]) -> float:
    """ISO 230-4 H: max |r_ccw(θ) − r_cw(θ)| about the mean of the two LSC centres, mm."""
    c = np.mean(centres, axis=0)
    grid = np.radians(np.arange(0.0, 360.0, 0.1))
    ok = np.ones(grid.shape, bool)
    rs = []
    for run in runs:
        th, r = run.theta[run.used], np.hypot(run.x - c[0], run.y - c[1])[run.used]
        o = np.argsort(th)
        th, r = th[o], r[o]
        rs.append(np.interp(grid, th, r, period=2 * np.pi))
        # Leave out angles the run has no sample near (its feed-in/feed-out gap).
        ext = np.r_[th[-1] - 2 * np.pi, th, th[0] + 2 * np.pi]
        i = np.searchsorted(ext, grid)
        gap = np.minimum(ext[i] - grid, grid - ext[i - 1])
        ok &= gap < np.radians(0.5)
    return float(np.max(np.abs(rs[0] - rs[1])[ok])) if ok.any() else float("nan")


def analyse_ballbar(runs: Sequence[BallbarRun | Mapping[str, Any]],
                    axes: tuple[str, str] = ("X", "Y")) -> BallbarResult:
    """Analyse one run, or a ccw and a cw run at the same radius and feed.

    ``runs`` are :class:`BallbarRun` or mappings of :func:`ballbar_run`'s arguments.
    With one direction, the sin 2θ term cannot be split into servo mismatch and
    squareness: it is all read as servo mismatch, Δτ = 2·s·b2/v, and squareness is None.
    """
    runs = [r if isinstance(r, BallbarRun) else ballbar_run(**r) for r in runs]
    dirs = [r.direction for r in runs]
    if not 1 <= len(runs) <= 2 or len(set(dirs)) != len(runs):
        raise InputError.about("runs", f"runs {dirs}: give one run, or one ccw and one cw")
    if len(runs) == 2 and (not np.isclose(runs[0].feed, runs[1].feed, rtol=0.01)
                           or not np.isclose(runs[0].radius, runs[1].radius, rtol=1e-6)):
        raise InputError.about("runs", "the ccw and cw runs must share radius and feed")
    runs.sort(key=lambda r: r.direction != "ccw")
    out = [_analyse_run(r, tuple(axes)) for r in runs]
    feats = tuple(o[0] for o in out)
    R, v = runs[0].radius, float(np.mean([r.feed for r in runs]))
    a2 = float(np.mean([f.harmonics_um[2] for f in feats]))
    b2 = {f.direction: f.harmonics_um[3] for f in feats}
    if len(runs) == 2:
        servo_um = 0.5 * (b2["ccw"] - b2["cw"])          # = ½·v·Δτ
        square_um = 0.5 * (b2["ccw"] + b2["cw"])
        hyst = 1e3 * _hysteresis(runs, [o[2] for o in out])
    else:
        servo_um, square_um, hyst = runs[0].sense * b2[runs[0].direction], None, None
    dtau_ms = 2 * servo_um / v                          # µm / (mm/s) = ms
    # ccw: +½vΔτ·sin 2θ, cw: −½vΔτ·sin 2θ; + puts the major axis on 45°/225°.
    ellipse = {d: (45 if servo_um * sgn >= 0 else 135) for d, sgn in (("ccw", 1), ("cw", -1))
               if d in dirs}
    by_axis = []
    for i, name in enumerate(axes):
        rv = [r for f in feats for r in f.reversals if r.axis == name]
        by_axis.append(AxisReversals(name, (0.0, 180.0) if i == 0 else (90.0, 270.0),
                                     _nanmean([abs(r.spike_um) for r in rv]),
                                     _nanmean([r.step_um for r in rv])))
    spec = 1e3 * np.mean([o[1] for o in out], axis=0)
    # Orders that are multiples of 4 repeat with the four axis reversals: what is left of
    # the reversal features shows there, so cyclic error is read from the other orders.
    orders = np.arange(CYCLIC_ORDERS[0], CYCLIC_ORDERS[0] + spec.size)
    k = int(np.argmax(np.where(orders % 4 == 0, -np.inf, spec)))
    return BallbarResult(
        axes=tuple(axes), radius=R, runs=feats, hysteresis_um=hyst,
        servo_mismatch_ms=dtau_ms, servo_mismatch_um=servo_um, servo_ellipse_deg=ellipse,
        servo_from_one_direction=len(runs) == 1, scale_mismatch_um=a2,
        scale_mismatch_ppm=2e3 * a2 / R, squareness_um=square_um,
        squareness_urad=None if square_um is None else 2e3 * square_um / R,
        axis_reversals=tuple(by_axis), cyclic_order=CYCLIC_ORDERS[0] + k,
        cyclic_amplitude_um=float(spec[k]), cyclic_spectrum_um=tuple(map(float, spec)),
        threshold_um=max(FLOOR_UM, FRACTION * max(f.circularity_um for f in feats)),
        data=tuple(runs))


def words(result: BallbarResult) -> list[str]:
    """What a QC20 user reads: the circularity line, then each feature whose size is
    ≥ ``result.threshold_um`` = max(1 µm, 5 % of the largest circularity)."""
    t, X, Y = result.threshold_um, *result.axes
    out = ["circularity " + ", ".join(f"{f.circularity_um:.1f} µm {f.direction}" for f in result.runs)
           + " (ISO 230-4 G about the least-squares centre)"]
    if result.hysteresis_um is not None and result.hysteresis_um >= t:
        out.append(f"circular hysteresis {result.hysteresis_um:.1f} µm between the ccw and cw runs")
    if abs(result.servo_mismatch_um) >= t:
        lag = f"{X} lags {Y}" if result.servo_mismatch_ms > 0 else f"{Y} lags {X}"
        ell = ", ".join(f"{deg}° in {d}" for d, deg in result.servo_ellipse_deg.items())
        one = ("; from one direction only, squareness would read the same"
               if result.servo_from_one_direction else "")
        out.append(f"servo mismatch {abs(result.servo_mismatch_ms):.2f} ms ({lag}): ellipse "
                   f"{abs(result.servo_mismatch_um):.1f} µm along the diagonal at {ell}{one}")
    if abs(result.scale_mismatch_um) >= t:
        longer = X if result.scale_mismatch_ppm > 0 else Y
        out.append(f"scale mismatch {abs(result.scale_mismatch_ppm):.0f} ppm ({longer} draws longer, "
                   f"ellipse {abs(result.scale_mismatch_um):.1f} µm along the {longer} axis)")
    if result.squareness_um is not None and abs(result.squareness_um) >= t:
        diag = 45 if result.squareness_um > 0 else 135
        out.append(f"squareness {abs(result.squareness_urad):.0f} µrad (ellipse "
                   f"{abs(result.squareness_um):.1f} µm along {diag}° in both directions)")
    off = np.mean([f.lsc_offset_um for f in result.runs], axis=0)
    if np.hypot(*off) >= t:
        out.append(f"centre offset {X} {off[0]:+.1f} µm, {Y} {off[1]:+.1f} µm "
                   "(setup or a position offset)")
    for a in result.axis_reversals:
        where = f"{a.axis} at {a.angles_deg[0]:.0f}° and {a.angles_deg[1]:.0f}°"
        if a.spike_um >= t:
            out.append(f"reversal spikes on {where}: {a.spike_um:.1f} µm "
                       f"(friction or a servo lag at the {a.axis} reversals)")
        if abs(a.step_um) >= t:
            # a plot alone cannot tell a gap from friction holding the axis back after a reversal
            out.append(f"reversal step on {where}: {a.step_um:+.1f} µm (lost motion of {a.axis}: backlash, or "
                       f"friction holding it back)")
    spec = np.asarray(result.cyclic_spectrum_um)
    amp = result.cyclic_amplitude_um
    if amp >= t and amp >= CYCLIC_PROMINENCE * np.median(spec):
        out.append(f"cyclic error: {result.cyclic_order} lobes per turn, {amp:.1f} µm")
    return out


def plot_ballbar(result: BallbarResult, measured: BallbarResult | None = None, *,
                 um_per_div: float | None = None, path: str | Path | None = None):
    """The classic polar plot: each run's dr (µm, centre offset removed) at angle θ.

    The rings are ``um_per_div`` apart (auto: 1-2-5 steps, 4 divisions either side of
    the nominal circle, which is drawn bold); ``measured`` runs are overlaid dashed.
    Returns the matplotlib Figure; saves it to ``path`` when given (format by suffix).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sets = [(result, "-", "predicted" if measured is not None else "")]
    if measured is not None:
        sets.append((measured, "--", "measured"))
    curves = []
    for res, ls, tag in sets:
        for run in res.data:
            H = _harmonics(run.theta)[:, :3]
            c1 = np.linalg.lstsq(H[run.used], run.dr[run.used], rcond=None)[0]
            # Centred; NaN breaks the line at the feed-in/feed-out gap.
            dr = np.where(run.used, run.dr - H[:, 1:] @ c1[1:], np.nan)
            step = max(1, len(dr) // 4000)
            curves.append((run.theta[::step], 1e3 * dr[::step], ls,
                           f"{run.direction} {tag}".strip()))
    span = max(np.nanmax(np.abs(c[1])) for c in curves)
    if um_per_div is None:
        raw = max(span, 0.1) / 4
        mag = 10 ** np.floor(np.log10(raw))
        um_per_div = float(mag * min(m for m in (1, 2, 5, 10) if m * mag >= raw))
    lim = 4 * um_per_div
    fig = plt.figure(figsize=(6.5, 6.5))
    ax = fig.add_subplot(projection="polar")
    ax.set_rorigin(-2 * lim)
    ax.set_ylim(-lim, lim)
    ax.set_yticks(np.arange(-4, 5) * um_per_div)
    ax.set_yticklabels([])
    full = np.linspace(0, 2 * np.pi, 361)
    ax.plot(full, np.zeros_like(full), color="k", lw=1.2, label="nominal")
    colours = {"ccw": "C0", "cw": "C3"}
    for th, dr, ls, label in curves:
        ax.plot(th, np.clip(dr, -lim, lim), ls=ls, lw=1.0, color=colours[label.split()[0]], label=label)
    X, Y = result.axes
    for a, name in ((0, X), (np.pi, X), (0.5 * np.pi, Y), (1.5 * np.pi, Y)):
        ax.plot([a], [0], "k^", ms=6)
        ax.text(a, -2.5 * um_per_div, f"{name} rev", fontsize=8, ha="center", va="center")
    ax.set_title(f"ballbar R {result.radius:g} mm, {um_per_div:g} µm/div (centre offset removed)",
                 pad=18)
    ax.legend(loc="lower left", bbox_to_anchor=(-0.1, -0.12), fontsize=8, ncol=3)
    if path is not None:
        fig.savefig(path, bbox_inches="tight")
    return fig

"""The CNC interpolator: a program's blocks → commanded axis positions sampled at Ts.

Model (the interpolator the thesis's identification experiment assumes, §3.3-3.4):

* **Exact stop** (default): every block starts and ends at rest, as G61.  The feed F
  (mm/s, path speed) and the acceleration ``a_max`` (mm/s², along the path) are never
  exceeded; a rapid (G0) runs at ``rapid_feed``.
* **Velocity profile** per block, rest to rest along the path length L:
  trapezoidal — accelerate at a_max to F, cruise, decelerate — or triangular when
  L < F²/a_max, peak speed sqrt(a_max·L).  This is the "S-curve disabled" setting the
  thesis recommends for identification (sharper transients, richer excitation).
  With ``j_max`` (mm/s³) the profile is the 7-phase jerk-limited S-curve: acceleration
  ramps at ±j_max to at most a_max; when the move is too short the peak speed is lowered
  (closed forms in :func:`plan_profile`).
* **Sampling on the servo grid**: every block lasts an integer number of periods Ts.
  The profile's duration T is stretched to n·Ts, n = ceil(T/Ts), by evaluating
  s(k·T/n): time scaling by c = n·Ts/T >= 1 divides speed by c, acceleration by c² and jerk
  by c³, so no limit is exceeded, and the block's end point lands exactly on a sample (it is
  written there exactly, not computed).  Samples are at t = k·Ts, k = 0, 1, …; sample 0 is
  the start position.
* **Several axes** move together on a straight line (G0/G1): each axis's share of the path
  speed and acceleration is its direction cosine, so none exceeds the path limits.
* **Arcs** (G2/G3, XY plane, optional helical axes moving linearly): the speed is also
  lowered so the centripetal acceleration v²/r stays <= a_max/√2, and the tangential
  acceleration is limited to sqrt(a_max² - (v²/r)²), so the total acceleration vector stays
  <= a_max.  The jerk limit (if any) applies along the path only.
* **Per-axis limits** (``axis_limits``, LinuxCNC's planner): instead of one path
  acceleration, each axis has its own maximum velocity and acceleration (LinuxCNC INI
  ``[AXIS_x]``/``[JOINT_n]`` MAX_VELOCITY/MAX_ACCELERATION).  A line with unit direction u
  runs at path speed <= min_i v_i/|u_i| and path acceleration <= min_i a_i/|u_i| (as
  LinuxCNC's canon computes them: 2000 mm/s² per axis is 2828 mm/s² along a 45° line).  An
  arc in the XY plane takes a = min(a_X, a_Y) and v <= min(v_X, v_Y), the speed lowered so
  the centripetal v²/r stays <= 0.866·a (LinuxCNC's BLEND_ACC_RATIO_NORMAL); the tangential
  acceleration is sqrt(a² − (v_l²/r)²) with v_l the arc's speed *limit* (not its feed; half
  of a when v_l is cut: LinuxCNC 2.9's ``pmCircleActualMaxVel`` on the segment's maxvel).
* **G64 P blending** (with ``axis_limits``; the path mode read from the program's text,
  :mod:`gcode_gen.path_mode`): consecutive G1 lines under G64 P run as one chain through
  tangent arcs at the corners whose middle passes P from the corner, at the speed the
  normal acceleration allows there, as LinuxCNC 2.9's tangent-arc blends (:func:`_blend`);
  a move under G64 that ends without a blend runs at half its acceleration (LinuxCNC's
  "parabolic" end condition).
* **Blending** (``blending=True``, the G64 idea restricted to what keeps the limits exact):
  consecutive linear blocks with the same direction and feed are run as one move, without
  stopping in between; any corner, reversal, feed change, arc or dwell still stops.

The result is a :class:`Trajectory`.  :func:`concatenate` joins trajectories into
segments of one continuous-time trajectory, and :func:`interpolate_programs` runs several
programs one after another, each starting where the previous one ended.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from core.errors import InputError
from core.run_limits import check_run_size
from gcode_gen.path_mode import path_tolerances
from gcode_gen.program import ARC_ORDER, Block, Program

__all__ = ["Trajectory", "Profile", "interpolate", "interpolate_programs", "concatenate", "plan_profile",
           "AxisLimits", "ARC_NORMAL_RATIO_PATH", "ARC_NORMAL_RATIO_LINUXCNC"]

#: Centripetal share of the acceleration limit on an arc: the path-limited interpolator's.
ARC_NORMAL_RATIO_PATH = 1.0 / math.sqrt(2.0)
#: ... and LinuxCNC's (tp's BLEND_ACC_RATIO_NORMAL, used with per-axis limits).
ARC_NORMAL_RATIO_LINUXCNC = 0.8660

#: Per-axis limits: axis letter -> (maximum velocity mm/s, maximum acceleration mm/s²).
AxisLimits = Mapping[str, "tuple[float, float]"]


@dataclass(frozen=True)
class Trajectory:
    """Commanded positions sampled at t = k·Ts.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Time in s, exactly k·Ts.
    axes : dict[str, ndarray]
        Commanded position per axis letter, mm (deg for rotary axes), each shape (N,).
    block : ndarray of int, shape (N,)
        Program line number of the block being executed at each sample (0 for the initial
        sample, which is the start position before the first block).
    Ts : float
        Sample period in s.
    """

    t: np.ndarray
    axes: dict[str, np.ndarray]
    block: np.ndarray
    Ts: float = 0.001

    @property
    def duration(self) -> float:
        """t[-1] in s."""
        return float(self.t[-1]) if len(self.t) else 0.0

    @property
    def end(self) -> dict[str, float]:
        """Last commanded position per axis, mm."""
        return {ax: float(x[-1]) for ax, x in self.axes.items()}


@dataclass(frozen=True)
class Profile:
    """A rest-to-rest motion profile along a path of length L (mm).

    Acceleration phase (duration Ta = 2·Tj + Tk): jerk +j for Tj, constant acceleration
    ap for Tk, jerk -j for Tj (trapezoid: Tj = 0, ap = a_max); cruise at vp for Tc;
    deceleration mirrors acceleration.  Total T = 2·Ta + Tc (s).
    """

    L: float
    vp: float
    ap: float
    j: float
    Tj: float
    Tk: float
    Tc: float

    @property
    def Ta(self) -> float:
        return 2.0 * self.Tj + self.Tk

    @property
    def T(self) -> float:
        return 2.0 * self.Ta + self.Tc


def plan_profile(L: float, v: float, a: float, j: float | None = None) -> Profile:
    """Time-optimal rest-to-rest profile for length L (mm), speed v (mm/s), acceleration a
    (mm/s²) and, if given, jerk j (mm/s³).

    Trapezoid: vp = v if L >= v²/a, else vp = sqrt(a·L) (triangle).
    S-curve: the acceleration phase to speed vp has Tj = a/j, Tk = vp/a - a/j when
    vp >= a²/j, else Tj = sqrt(vp/j), Tk = 0; it covers vp·Ta/2.  If both phases together
    (vp·Ta) exceed L, vp solves L = vp·Ta(vp): vp = (L·sqrt(j)/2)^(2/3) when that is
    <= a²/j, else vp² + vp·a²/j - L·a = 0.
    """
    if j is None or math.isinf(j):
        if L >= v * v / a:
            return Profile(L, v, a, 0.0, 0.0, v / a, (L - v * v / a) / v)
        vp = math.sqrt(a * L)
        return Profile(L, vp, a, 0.0, 0.0, vp / a, 0.0)

    def phases(vp: float) -> tuple[float, float, float]:
        if vp * j >= a * a:
            Tj = a / j
            return Tj, vp / a - Tj, a
        Tj = math.sqrt(vp / j)
        return Tj, 0.0, j * Tj

    Tj, Tk, ap = phases(v)
    if v * (2 * Tj + Tk) <= L:
        return Profile(L, v, ap, j, Tj, Tk, (L - v * (2 * Tj + Tk)) / v)
    vp = (L * math.sqrt(j) / 2.0) ** (2.0 / 3.0)
    if vp * j > a * a:
        q = a * a / j
        vp = (-q + math.sqrt(q * q + 4.0 * L * a)) / 2.0
    vp = min(vp, v)
    Tj, Tk, ap = phases(vp)
    return Profile(L, vp, ap, j, Tj, max(Tk, 0.0), 0.0)


def _s_acc(t: np.ndarray, Tj: np.ndarray, Tk: np.ndarray, ap: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Distance covered in the acceleration phase after time t (0 <= t <= Ta), vectorised."""
    # A move of an axis without limits (one the INI does not list) has ap = ∞ over Tk = 0: the
    # phases it never enters read ∞·0, and np.where takes the phase each sample is in.
    with np.errstate(invalid="ignore"):
        v1 = 0.5 * j * Tj * Tj
        S1 = j * Tj**3 / 6.0
        v2 = v1 + ap * Tk
        S2 = S1 + v1 * Tk + 0.5 * ap * Tk * Tk
        t2 = t - Tj
        t3 = t - Tj - Tk
        s1 = j * t**3 / 6.0
        s2 = S1 + v1 * t2 + 0.5 * ap * t2 * t2
        s3 = S2 + v2 * t3 + 0.5 * ap * t3 * t3 - j * t3**3 / 6.0
        return np.where(t < Tj, s1, np.where(t < Tj + Tk, s2, s3))


def _evaluate(tau: np.ndarray, p: dict[str, np.ndarray]) -> np.ndarray:
    """Path distance s(tau) for per-sample profile parameters p (see :class:`Profile`)."""
    Ta = 2.0 * p["Tj"] + p["Tk"]
    T = 2.0 * Ta + p["Tc"]
    D = 0.5 * p["vp"] * Ta
    acc = _s_acc(np.minimum(tau, Ta), p["Tj"], p["Tk"], p["ap"], p["j"])
    dec = p["L"] - _s_acc(np.clip(T - tau, 0.0, Ta), p["Tj"], p["Tk"], p["ap"], p["j"])
    cruise = D + p["vp"] * (tau - Ta)
    return np.where(tau <= Ta, acc, np.where(tau <= Ta + p["Tc"], cruise, dec))


@dataclass
class _Segment:
    """One interpolated motion: a block, or several blended linear blocks."""

    kind: str  # "line", "arc", "dwell"
    p0: np.ndarray
    p1: np.ndarray
    L: float
    v: float
    a: float
    lines: list[int]
    breaks: list[float]  # cumulative path length at the end of each block (blended lines)
    arc: tuple | None = None  # (cx, cy, r0, r1, theta0, dtheta, ix, iy)
    dwell_s: float = 0.0
    motion: str = ""
    feed: float = 0.0
    tolerance: float = 0.0  # G64 P in force (LinuxCNC planner): blend into the next line within it
    pieces: list | None = None  # a blended chain: [(kind, L, vmax, a, geometry, line)], see _chain


def _check(Ts: float, a_max: float, j_max: float | None, rapid_feed: float) -> None:
    for name, value, unit in (("Ts", Ts, "s"), ("a_max", a_max, "mm/s²"), ("rapid_feed", rapid_feed, "mm/s")):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise InputError(f"{name} must be a positive number of {unit}, got {value}")
    if j_max is not None and not (math.isfinite(j_max) and j_max > 0):
        raise InputError(f"j_max must be a positive number of mm/s³ or None, got {j_max}")


def _line_limits(d: np.ndarray, vmax: np.ndarray | None, amax: np.ndarray | None, a_path: float) -> tuple[float, float]:
    """(path speed cap, path acceleration) of a line of direction ``d`` (mm) under per-axis limits.

    Each axis i moves |u_i| of the path: v <= v_i/|u_i|, a <= a_i/|u_i| (LinuxCNC's canon).
    Without per-axis limits: no speed cap, the path acceleration ``a_path``.
    """
    if vmax is None:
        return math.inf, a_path
    u = np.abs(d) / float(np.linalg.norm(d))
    moving = u > 1e-12
    return float(np.min(vmax[moving] / u[moving])), float(np.min(amax[moving] / u[moving]))


def _segments(program: Program, names: list[str], p: np.ndarray, a_max: float, rapid_feed: float, blending: bool,
              axis_limits: AxisLimits | None = None) -> list[_Segment]:
    index = {ax: i for i, ax in enumerate(names)}
    tolerances = path_tolerances(program.blocks) if axis_limits else {}
    vmax = amax = None
    if axis_limits:
        vmax = np.array([axis_limits[ax][0] if ax in axis_limits else math.inf for ax in names])
        amax = np.array([axis_limits[ax][1] if ax in axis_limits else math.inf for ax in names])
    segs: list[_Segment] = []
    for b in program.blocks:
        if b.motion == "G4":
            segs.append(_Segment("dwell", p.copy(), p.copy(), 0.0, 0.0, a_max, [b.line], [0.0], dwell_s=float(b.dwell_s or 0.0)))
            continue
        q = p.copy()
        for ax, value in b.target.items():
            q[index[ax]] = value
            if axis_limits and ax not in axis_limits and value != p[index[ax]]:
                raise InputError(f"line {b.line}: moves axis {ax}, for which the per-axis limits give no "
                                 f"velocity and acceleration (limits for {', '.join(axis_limits)})")
        if b.motion == "G0":
            feed = rapid_feed
        else:
            if b.feed is None or not b.feed > 0:
                raise InputError(f"line {b.line}: {b.motion} block without a positive feed")
            # LinuxCNC: the rapid speed is the path speed cap, feeds above it are lowered to it
            feed = float(b.feed) if vmax is None else min(float(b.feed), rapid_feed)
        if b.motion in ("G2", "G3"):
            if vmax is None:
                segs.append(_arc_segment(b, p, q, index, feed, a_max))
            else:
                plane = [index[a] for a in _plane_axes(b) if a in index]
                v_limit = min(float(np.min(vmax[plane])), rapid_feed)
                segs.append(_arc_segment(b, p, q, index, min(feed, v_limit), float(np.min(amax[plane])),
                                         ARC_NORMAL_RATIO_LINUXCNC, v_limit))
        else:
            L = float(np.linalg.norm(q - p))
            if L <= 1e-12:
                p = q
                continue
            v_cap, a_line = _line_limits(q - p, vmax, amax, a_max)
            feed = min(feed, v_cap)
            prev = segs[-1] if segs else None
            if (blending and prev is not None and prev.kind == "line" and prev.motion == b.motion
                    and prev.feed == feed
                    and float(np.dot(prev.p1 - prev.p0, q - p)) >= (1.0 - 1e-12) * prev.L * L):
                prev.p1 = q.copy()
                prev.L += L
                prev.lines.append(b.line)
                prev.breaks.append(prev.L)
            else:
                segs.append(_Segment("line", p.copy(), q.copy(), L, feed, a_line, [b.line], [L], motion=b.motion, feed=feed,
                                     tolerance=float(tolerances.get(b.line) or 0.0)))
        p = q
    if vmax is not None:
        segs = _blend(segs, names, amax)
    return segs


def _blend(segs: list[_Segment], names: list[str], amax: np.ndarray) -> list[_Segment]:
    """Consecutive G1 lines under G64 P (tolerance > 0) run as one blended chain (LinuxCNC's
    tangent-arc blends): at each corner an arc tangent to both lines whose midpoint is
    ``tolerance`` from the corner, R = P·sinθ/(1 − sinθ) (θ half the corner's interior angle),
    its tangent points at most half a line from the corner; the speed on it
    min(feed, sqrt(0.866·a·R)) with a the smallest acceleration of the axes either line moves;
    the lines accelerate and decelerate at their per-axis limits between the arcs."""
    out: list[_Segment] = []
    for sg in segs:
        prev = out[-1] if out else None
        chainable = sg.kind == "line" and sg.motion == "G1"
        if (chainable and prev is not None and prev.kind in ("line", "chain") and prev.motion == "G1"
                and prev.tolerance > 0 and np.allclose(prev.p1, sg.p0)):
            if prev.kind == "line":
                prev = out[-1] = _Segment("chain", prev.p0, prev.p1, prev.L, prev.v, prev.a, list(prev.lines),
                                          list(prev.breaks), motion="G1", feed=prev.feed, tolerance=prev.tolerance,
                                          pieces=[("line", prev.L, prev.v, prev.a, (prev.p0.copy(), prev.p1.copy()),
                                                   prev.lines[0])])
            _append_blended(prev, sg, amax)
            continue
        out.append(sg)
    for sg in out:
        # Under G64 a move that ends without a blend into the next one (its end condition stays
        # LinuxCNC's "parabolic") runs at half its acceleration (tp's tpGetScaledAccel).
        if sg.kind == "line" and sg.tolerance > 0:
            sg.a *= 0.5
        elif sg.kind == "chain" and sg.tolerance > 0:
            kind, L, v, a, geom, line = sg.pieces[-1]
            sg.pieces[-1] = (kind, L, v, 0.5 * a, geom, line)
    return out


def _append_blended(chain: _Segment, sg: _Segment, amax: np.ndarray) -> None:
    """Add line ``sg`` to ``chain`` through a blend arc at their common corner (see :func:`_blend`)."""
    kind, L0, v0, a0, (A, C), line0 = chain.pieces[-1]
    u1 = (C - A) / L0
    u2 = (sg.p1 - sg.p0) / sg.L
    interior = math.acos(max(-1.0, min(1.0, float(np.dot(-u1, u2)))))
    theta = 0.5 * interior
    tol = chain.tolerance
    if interior > math.pi - 1e-9:  # straight on: no arc
        d = R = 0.0
    elif interior < 1e-6:  # a reversal cannot be blended
        d = R = 0.0
    else:
        # 1 − sin θ as 2·sin²(π/4 − θ/2): for a corner within 1e-8 of straight, sin θ rounds to 1
        R = tol * math.sin(theta) / (2.0 * math.sin(0.25 * math.pi - 0.5 * theta) ** 2)
        d = min(R / math.tan(theta), 0.5 * L0, 0.5 * sg.L)
        R = d * math.tan(theta)
    moving = (np.abs(u1) > 1e-12) | (np.abs(u2) > 1e-12)
    a_arc = float(np.min(amax[moving]))
    if R > 0:
        v_b = min(v0, sg.v, math.sqrt(ARC_NORMAL_RATIO_LINUXCNC * a_arc * R))
        chain.pieces[-1] = (kind, L0 - d, v0, a0, (A, C - u1 * d), line0)
        w = u2 - u1
        centre = C + w / np.linalg.norm(w) * (R / math.sin(theta))
        turn = math.pi - interior
        chain.pieces.append(("arc", R * turn, v_b, 0.5 * a_arc, (centre, C - u1 * d, u1, R, turn), sg.lines[0]))
    elif interior < 1e-6:
        chain.pieces.append(("stop", 0.0, 0.0, a_arc, (C,), sg.lines[0]))
    chain.pieces.append(("line", sg.L - d, sg.v, sg.a, (sg.p0 + u2 * d, sg.p1.copy()), sg.lines[0]))
    chain.p1 = sg.p1.copy()
    chain.L += sg.L
    chain.lines.append(sg.lines[0])
    chain.breaks.append(chain.L)
    chain.tolerance = sg.tolerance


def _chain_profile(pieces: list) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per piece (v_start, v_peak, v_end, duration): trapezoids joined at the speeds each
    boundary allows (the smaller of its pieces' speed limits), lowered where a piece is too
    short to reach the next boundary's speed (forward and backward passes); rest at both ends."""
    n = len(pieces)
    L = np.array([p[1] for p in pieces])
    vmax = np.array([p[2] for p in pieces])
    a = np.array([p[3] for p in pieces])
    w = np.zeros(n + 1)
    w[1:-1] = np.minimum(vmax[:-1], vmax[1:])
    for k in range(n):  # forward
        w[k + 1] = min(w[k + 1], math.sqrt(w[k] ** 2 + 2 * a[k] * L[k]))
    for k in range(n - 1, -1, -1):  # backward
        w[k] = min(w[k], math.sqrt(w[k + 1] ** 2 + 2 * a[k] * L[k]))
    vp = np.minimum(vmax, np.sqrt(a * L + 0.5 * (w[:-1] ** 2 + w[1:] ** 2)))
    vp = np.maximum(vp, np.maximum(w[:-1], w[1:]))
    d_acc = (vp ** 2 - w[:-1] ** 2) / (2 * a)
    d_dec = (vp ** 2 - w[1:] ** 2) / (2 * a)
    cruise = np.where(vp > 0, np.maximum(L - d_acc - d_dec, 0.0) / np.maximum(vp, 1e-300), 0.0)
    T = (vp - w[:-1]) / a + (vp - w[1:]) / a + cruise
    return w[:-1], vp, w[1:], T


def _chain_positions(sg: _Segment, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Positions (axes, n) at τ = T·k/n, k = 1…n, and the program line of each sample, of a chain."""
    v0, vp, v1, Tp = _chain_profile(sg.pieces)
    T = float(Tp.sum())
    tau = T * np.arange(1, n + 1) / n
    start = np.concatenate([[0.0], np.cumsum(Tp)[:-1]])
    which = np.clip(np.searchsorted(start, tau, side="right") - 1, 0, len(sg.pieces) - 1)
    pos = np.empty((len(sg.p0), n))
    line = np.empty(n, dtype=np.int64)
    for i, (kind, L, _vmax, a, geom, ln) in enumerate(sg.pieces):
        k = which == i
        if not k.any():
            continue
        t = np.clip(tau[k] - start[i], 0.0, Tp[i])
        ta, td = (vp[i] - v0[i]) / a, (vp[i] - v1[i]) / a
        tc = Tp[i] - ta - td
        s_acc = v0[i] * np.minimum(t, ta) + 0.5 * a * np.minimum(t, ta) ** 2
        s_cru = vp[i] * np.clip(t - ta, 0.0, tc)
        t3 = np.clip(t - ta - tc, 0.0, td)
        s = np.minimum(s_acc + s_cru + vp[i] * t3 - 0.5 * a * t3 ** 2, L)
        line[k] = ln
        if kind == "line":
            A, B = geom
            u = s / L if L > 0 else np.ones_like(s)
            pos[:, k] = B[:, None] - (1.0 - u)[None, :] * (B - A)[:, None]
        elif kind == "arc":
            centre, S, tangent, R, turn = geom
            psi = s / R
            e1 = (S - centre) / R
            pos[:, k] = centre[:, None] + R * (np.cos(psi)[None, :] * e1[:, None] + np.sin(psi)[None, :] * tangent[:, None])
        else:
            pos[:, k] = geom[0][:, None]
    pos[:, -1] = sg.p1
    return pos, line


def _plane_axes(b: Block) -> tuple[str, str]:
    """The arc plane's (first, second) axes: G3 turns from the first towards the second
    (G17 X→Y, G18 Z→X, G19 Y→Z, as RS274/NGC counts the sense seen from the third axis's +)."""
    return ARC_ORDER[b.plane]


def _arc_segment(b: Block, p: np.ndarray, q: np.ndarray, index: dict[str, int], feed: float, a_max: float,
                 normal_ratio: float = ARC_NORMAL_RATIO_PATH, v_limit: float | None = None) -> _Segment:
    """An arc block in its plane (``Block.plane``), ``Block.turns`` full turns counted;
    ``v_limit`` (LinuxCNC): the tangential acceleration is set for the arc's
    speed limit, not its feed (tc's ``pmCircleActualMaxVel`` with the segment's maxvel),
    so a feed override could raise the speed without exceeding the limits."""
    a1, a2 = _plane_axes(b)
    if b.center is None or a1 not in index or a2 not in index or a1 not in b.center or a2 not in b.center:
        raise InputError(f"line {b.line}: arc without a {a1}{a2} centre")
    ix, iy = index[a1], index[a2]
    cx, cy = b.center[a1], b.center[a2]
    x0, y0, x1, y1 = p[ix], p[iy], q[ix], q[iy]
    r0, r1 = math.hypot(x0 - cx, y0 - cy), math.hypot(x1 - cx, y1 - cy)
    if min(r0, r1) <= 1e-9:
        raise InputError(f"line {b.line}: arc radius is zero")
    th0, th1 = math.atan2(y0 - cy, x0 - cx), math.atan2(y1 - cy, x1 - cx)
    extra = 2 * math.pi * max(int(b.turns) - 1, 0)  # P: full turns beyond the first sweep
    if b.motion == "G3":
        dth = (th1 - th0) % (2 * math.pi)
        if dth < 1e-9:
            dth = 2 * math.pi  # end = start: full circle
        dth += extra
    else:
        dth = -((th0 - th1) % (2 * math.pi))
        if dth > -1e-9:
            dth = -2 * math.pi
        dth -= extra
    other = q - p
    other[ix] = other[iy] = 0.0
    L = math.hypot(0.5 * (r0 + r1) * abs(dth), float(np.linalg.norm(other)))
    r = min(r0, r1)
    # Centripetal v²/r <= normal_ratio·a_max; tangential limited so |a| stays <= a_max.
    v_cut = math.sqrt(a_max * r * normal_ratio)
    v = min(feed, v_cut)
    an = min(v_limit, v_cut) ** 2 / r if v_limit is not None else v * v / r
    at = math.sqrt(max(a_max * a_max - an * an, 0.0))
    return _Segment("arc", p.copy(), q.copy(), L, v, at, [b.line], [L], arc=(cx, cy, r0, r1, th0, dth, ix, iy), motion=b.motion, feed=feed)


def interpolate(
    program: Program,
    *,
    Ts: float = 0.001,
    a_max: float = 2000.0,
    j_max: float | None = None,
    rapid_feed: float = 200.0,
    start: dict[str, float] | None = None,
    blending: bool = False,
    axis_limits: AxisLimits | None = None,
) -> Trajectory:
    """Commanded trajectory of ``program`` sampled every ``Ts`` seconds.

    Parameters
    ----------
    program : Program
        From :func:`gcode_gen.interpreter.parse_program`.
    Ts : float
        Interpolation (servo) period, s (default 0.001).
    a_max : float
        Path acceleration limit, mm/s² (default 2000, thesis §3.4).
    j_max : float or None
        Path jerk limit, mm/s³; None (default) for trapezoidal profiles.
    rapid_feed : float
        Path speed of G0 moves, mm/s.
    start : dict[str, float] or None
        Position before the first block, mm.  Axes not given start at the first value
        the program commands for them (so the opening positioning move costs nothing).
    blending : bool
        Run consecutive same-direction, same-feed linear blocks without stopping.
    axis_limits : dict or None
        Axis letter -> (max velocity mm/s, max acceleration mm/s²): plan with per-axis
        limits as LinuxCNC does (module docstring); ``a_max`` is then not used.  An axis
        not named is unlimited.

    Returns
    -------
    Trajectory
        Samples at t = k·Ts; the axes are those of ``start`` and of the program.
    """
    _check(Ts, a_max, j_max, rapid_feed)
    names = list(dict.fromkeys(list(start or {}) + list(program.axes)))
    first: dict[str, float] = {}
    for b in program.blocks:
        for ax, v in b.target.items():
            first.setdefault(ax, v)
    p0 = np.array([(start or {}).get(ax, first.get(ax, 0.0)) for ax in names], dtype=float)
    if axis_limits:
        for ax, (v, a) in axis_limits.items():
            if not (math.isfinite(v) and v > 0 and math.isfinite(a) and a > 0):
                raise InputError(f"axis {ax}: limits must be positive numbers, got velocity {v}, acceleration {a}")
    segs = _segments(program, names, p0, a_max, rapid_feed, blending, axis_limits)

    # Per segment: profile and number of samples on the Ts grid.
    n = np.zeros(len(segs), dtype=np.int64)
    keys = ("L", "vp", "ap", "j", "Tj", "Tk", "Tc")
    par = {k: np.zeros(len(segs)) for k in keys}
    T = np.zeros(len(segs))
    for i, sg in enumerate(segs):
        if sg.kind == "dwell":
            n[i] = math.ceil(sg.dwell_s / Ts - 1e-9) if sg.dwell_s > 0 else 0
            continue
        if sg.kind == "chain":
            T[i] = float(_chain_profile(sg.pieces)[3].sum())
            n[i] = max(1, math.ceil(T[i] / Ts - 1e-9))
            par["L"][i] = par["vp"][i] = par["ap"][i] = 1.0  # not evaluated: _chain_positions
            continue
        prof = plan_profile(sg.L, sg.v, sg.a, j_max)
        T[i] = prof.T
        n[i] = max(1, math.ceil(prof.T / Ts - 1e-9))
        for k in keys:
            par[k][i] = getattr(prof, k)

    total = int(n.sum())
    check_run_size(total, Ts, len(names), program.name or "the program")  # before the first array of that length
    seg_of = np.repeat(np.arange(len(segs)), n)
    first_k = np.concatenate([[0], np.cumsum(n)[:-1]]) if len(segs) else np.zeros(0, dtype=np.int64)
    k_local = np.arange(total) - np.repeat(first_k, n) + 1  # 1..n within each segment
    frac = k_local / np.repeat(n, n).astype(float)  # k/n, exactly 1.0 at each segment end
    tau = T[seg_of] * frac
    s = _evaluate(tau, {k: v[seg_of] for k, v in par.items()})

    pos = np.empty((len(names), total))
    line_of = np.empty(total, dtype=np.int64)
    for i, sg in enumerate(segs):
        sl = slice(int(first_k[i]), int(first_k[i] + n[i]))
        if n[i] == 0:
            continue
        if sg.kind == "dwell":
            pos[:, sl] = sg.p0[:, None]
            line_of[sl] = sg.lines[0]
            continue
        if sg.kind == "chain":
            pos[:, sl], line_of[sl] = _chain_positions(sg, int(n[i]))
            continue
        si = np.clip(s[sl], 0.0, sg.L)
        u = si / sg.L
        # p1 - (1-u)·d: exact end point at u = 1.
        pos[:, sl] = sg.p1[:, None] - (1.0 - u)[None, :] * (sg.p1 - sg.p0)[:, None]
        if sg.kind == "arc":
            cx, cy, r0, r1, th0, dth, ix, iy = sg.arc
            th = th0 + u * dth
            r = r0 + u * (r1 - r0)
            pos[ix, sl] = cx + r * np.cos(th)
            pos[iy, sl] = cy + r * np.sin(th)
            pos[:, sl.stop - 1] = sg.p1
        if len(sg.lines) == 1:
            line_of[sl] = sg.lines[0]
        else:
            idx = np.searchsorted(np.asarray(sg.breaks), si, side="left")
            line_of[sl] = np.asarray(sg.lines)[np.minimum(idx, len(sg.lines) - 1)]

    t = np.arange(total + 1) * Ts
    axes = {ax: np.concatenate([[p0[i]], pos[i]]) for i, ax in enumerate(names)}
    block = np.concatenate([[0], line_of]).astype(np.int64)
    return Trajectory(t=t, axes=axes, block=block, Ts=float(Ts))


def concatenate(trajectories: Sequence[Trajectory]) -> tuple[Trajectory, np.ndarray]:
    """Join trajectories one after another in continuous time.

    Each trajectory's first sample follows the previous one's last sample by one period
    Ts.  An axis missing from one trajectory holds its last known value (or, before it
    appears, its first value).

    Returns
    -------
    (Trajectory, ndarray of int)
        The joined trajectory and, per sample, the index of the trajectory it came from.
    """
    if not trajectories:
        raise InputError("no trajectory to concatenate")
    Ts = trajectories[0].Ts
    for tr in trajectories:
        if not math.isclose(tr.Ts, Ts, rel_tol=1e-12):
            raise InputError(f"cannot concatenate trajectories with sample periods {Ts} s and {tr.Ts} s")
    names = list(dict.fromkeys(ax for tr in trajectories for ax in tr.axes))
    last: dict[str, float] = {}
    for ax in names:  # value before an axis first appears: its first value
        last[ax] = next(float(tr.axes[ax][0]) for tr in trajectories if ax in tr.axes)
    parts: dict[str, list[np.ndarray]] = {ax: [] for ax in names}
    for tr in trajectories:
        for ax in names:
            x = tr.axes.get(ax)
            if x is None:
                x = np.full(len(tr.t), last[ax])
            parts[ax].append(x)
            if len(x):
                last[ax] = float(x[-1])
    lengths = [len(tr.t) for tr in trajectories]
    total = sum(lengths)
    segment = np.repeat(np.arange(len(trajectories)), lengths)
    joined = Trajectory(
        t=np.arange(total) * Ts,
        axes={ax: np.concatenate(parts[ax]) for ax in names},
        block=np.concatenate([tr.block for tr in trajectories]).astype(np.int64),
        Ts=Ts,
    )
    return joined, segment


def interpolate_programs(programs: Sequence[Program], *, start: dict[str, float] | None = None, **kwargs) -> tuple[Trajectory, np.ndarray]:  # noqa: ANN003
    """Interpolate programs one after another, each starting where the previous ended.

    ``kwargs`` go to :func:`interpolate` (Ts, a_max, j_max, rapid_feed, blending).
    Returns the joined trajectory and the per-sample program index (see :func:`concatenate`).
    """
    trs: list[Trajectory] = []
    pos = dict(start or {})
    for prog in programs:
        tr = interpolate(prog, start=pos or None, **kwargs)
        trs.append(tr)
        pos = {**pos, **tr.end}
    return concatenate(trs)

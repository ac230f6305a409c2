"""Contour error of a two-axis motion: distance from the actual point to the commanded path.

The thesis compares predicted and measured contouring on circle and diamond toolpaths
(Figs 3.6, 3.7, 4.9, 4.10).  The contour error is the deviation normal to the path,
not the tracking error along it: each actual point is projected onto the commanded
path (a polyline through the commanded samples) and the signed distance kept, positive
to the left of the direction of travel (outside a counter-clockwise circle is right).
"""

from __future__ import annotations

import numpy as np

__all__ = ["contour_error", "path_contour_error", "TIME_WEIGHT"]

#: mm per second of time difference in the nearest-point search of :func:`path_contour_error`:
#: small against the path travelled while the axes lag (≤ 0.05 s at most feeds → 25 µm),
#: large against contour errors for parts of the path visited seconds apart.
TIME_WEIGHT = 0.5

#: rad: a point this close to straight ahead of a vertex (or of the path's end) is on its left.
AHEAD_RAD = 1e-3


def contour_error(path_x: np.ndarray, path_y: np.ndarray, x: np.ndarray, y: np.ndarray,
                  window: int = 3) -> np.ndarray:
    """Signed contour error, mm, shape (N,), of points (x, y) against the commanded path.

    Parameters
    ----------
    path_x, path_y : commanded positions, mm, shape (M,), in order of travel.
    x, y : actual (or simulated) positions, mm, shape (N,).
    window : how many path segments either side of the nearest vertex are searched.
    """
    return path_contour_error(np.column_stack([path_x, path_y]), np.column_stack([x, y]), window=window)


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def _side(P: np.ndarray, Q: np.ndarray, seg: np.ndarray, s: np.ndarray) -> np.ndarray:
    """+1 left of travel, −1 right, for points Q whose nearest path point is at ``s`` ∈ [0, 1] of chord ``seg``.

    Inside a chord the side is that of its direction.  Where the nearest point is a vertex
    (a corner, or a point beyond a chord's end on its extension, where the cross product
    with that chord is 0 or a rounding error's sign), the side is taken against the mean
    of the unit directions into and out of the vertex: the corner's bisector, so an
    overshoot past a corner is outside it whichever chord is nearer.  A point straight
    ahead of the path's last point (or behind its first) is on neither side: within
    ``AHEAD_RAD`` of the tangent it counts as left (+), so a rounding error in its
    position cannot flip the sign.
    """
    D = _unit(np.diff(P, axis=0))  # unit direction of each chord
    at_vertex = (s <= 0.0) | (s >= 1.0)
    v = np.where(s >= 1.0, seg + 1, seg)  # the vertex, where at_vertex
    into = D[np.clip(v - 1, 0, len(D) - 1)] * (v >= 1)[:, None]
    out = D[np.clip(v, 0, len(D) - 1)] * (v <= len(D) - 1)[:, None]
    T = np.where(at_vertex[:, None], into + out, D[seg])
    base = np.where(at_vertex[:, None], P[v], P[seg])
    R = Q - base
    cross = T[:, 0] * R[:, 1] - T[:, 1] * R[:, 0]
    tol = AHEAD_RAD * np.linalg.norm(T, axis=1) * np.linalg.norm(R, axis=1)
    return np.where(cross < -tol, -1.0, 1.0)


def path_contour_error(commanded: np.ndarray, actual: np.ndarray, *, arcs: list[tuple[np.ndarray, float, float]] | None = None,
                       arc_of_vertex: np.ndarray | None = None, plane: tuple[int, int] = (0, 1),
                       t: np.ndarray | None = None, window: int = 5) -> np.ndarray:
    """Contour error, mm, shape (N,): normal distance of each actual point from the programmed path.

    The thesis's definition (§4.3.3): the shortest distance from the actual position to
    the commanded path, not the tracking error along it.  The path is the commanded
    samples (N, k) for any number k of axes; on a line block that polyline *is* the
    programmed line, on an arc block the distance is taken to the arc itself (|q − c| − r
    in its plane, plus any out-of-plane deviation), so the chord of the sampled arc adds
    no error.  Signed for two axes (positive to the left of travel, as
    :func:`contour_error`), a magnitude for three or more.

    Parameters
    ----------
    commanded, actual : (N, k) positions, mm, in order of travel.
    arcs : (centre (2,), radius, direction +1 ccw / −1 cw) per arc, in the ``plane`` axes.
    arc_of_vertex : (N,) index into ``arcs`` of the block each commanded sample belongs to, −1 for lines.
    t : (N,) sample times, s.  The nearest part of the path is looked for near the same
        time (time enters the search as a coordinate of ``TIME_WEIGHT`` mm/s), so a point
        near where a closed path ends is measured against its last side, not the first.
    """
    P = np.asarray(commanded, dtype=float)
    Q = np.asarray(actual, dtype=float)
    if P.ndim == 1:
        P, Q = P[:, None], Q[:, None]
    keep = np.concatenate([[True], np.any(np.diff(P, axis=0) != 0, axis=1)])
    idx = np.flatnonzero(keep)
    Pk = P[idx]
    if len(Pk) < 2:
        return np.linalg.norm(Q - Pk[0], axis=1)
    from scipy.spatial import cKDTree  # lazy: 0.3 s of import every command would pay

    if t is None:
        _, nearest = cKDTree(Pk).query(Q)
    else:
        tw = TIME_WEIGHT * np.asarray(t, dtype=float)
        _, nearest = cKDTree(np.column_stack([Pk, tw[idx]])).query(np.column_stack([Q, tw]))
    best = np.full(len(Q), np.inf)
    seg = np.zeros(len(Q), dtype=np.int64)
    frac = np.zeros(len(Q))
    two = P.shape[1] == 2
    for off in range(-window, window):
        i = np.clip(nearest + off, 0, len(Pk) - 2)
        A, B = Pk[i], Pk[i + 1]
        AB = B - A
        s = np.clip(np.einsum("ij,ij->i", Q - A, AB) / np.einsum("ij,ij->i", AB, AB), 0.0, 1.0)
        d = np.linalg.norm(Q - (A + s[:, None] * AB), axis=1)
        better = d < best
        best[better], seg[better], frac[better] = d[better], i[better], s[better]
    out = _side(Pk, Q, seg, frac) * best if two else best
    if arcs and arc_of_vertex is not None:
        # The end vertex of the nearest chord decides its block (its sample lies on the block).
        which = np.asarray(arc_of_vertex)[idx[seg + 1]]
        ia, ib = plane
        for k, (c, r, direction) in enumerate(arcs):
            on = which == k
            if not on.any():
                continue
            radial = np.hypot(Q[on, ia] - c[0], Q[on, ib] - c[1]) - r
            if two:
                out[on] = -direction * radial  # outside a ccw arc is right of travel
            else:
                rest = [j for j in range(P.shape[1]) if j not in plane]
                A = Pk[seg[on]][:, rest]
                B = Pk[seg[on] + 1][:, rest]
                # Out-of-plane deviation from the (linear, helical) motion of the other axes.
                off_plane = Q[on][:, rest] - 0.5 * (A + B)
                out[on] = np.sqrt(radial ** 2 + np.sum(off_plane ** 2, axis=1))
    return out

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


def contour_error(path_x: np.ndarray, path_y: np.ndarray, x: np.ndarray, y: np.ndarray,
                  window: int = 3) -> np.ndarray:
    """Signed contour error, mm, shape (N,), of points (x, y) against the commanded path.

    Parameters
    ----------
    path_x, path_y : commanded positions, mm, shape (M,), in order of travel.
    x, y : actual (or simulated) positions, mm, shape (N,).
    window : how many path segments either side of the nearest vertex are searched.
    """
    P = np.column_stack([path_x, path_y]).astype(float)
    Q = np.column_stack([x, y]).astype(float)
    # Drop repeated vertices (standstill) so every segment has a direction.
    keep = np.concatenate([[True], np.any(np.diff(P, axis=0) != 0, axis=1)])
    P = P[keep]
    if len(P) < 2:
        return np.hypot(Q[:, 0] - P[0, 0], Q[:, 1] - P[0, 1])
    from scipy.spatial import cKDTree  # lazy: 0.3 s of import every command would pay

    _, nearest = cKDTree(P).query(Q)
    best = np.full(len(Q), np.inf)
    signed = np.zeros(len(Q))
    for off in range(-window, window):
        i = np.clip(nearest + off, 0, len(P) - 2)
        A, B = P[i], P[i + 1]
        AB = B - A
        L2 = np.einsum("ij,ij->i", AB, AB)
        s = np.clip(np.einsum("ij,ij->i", Q - A, AB) / L2, 0.0, 1.0)
        foot = A + s[:, None] * AB
        d = np.hypot(*(Q - foot).T)
        side = np.sign(AB[:, 0] * (Q - A)[:, 1] - AB[:, 1] * (Q - A)[:, 0])
        better = d < best
        best[better] = d[better]
        signed[better] = (side * d)[better]
    return signed


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
    from scipy.spatial import cKDTree  # lazy, as above

    if t is None:
        _, nearest = cKDTree(Pk).query(Q)
    else:
        tw = TIME_WEIGHT * np.asarray(t, dtype=float)
        _, nearest = cKDTree(np.column_stack([Pk, tw[idx]])).query(np.column_stack([Q, tw]))
    best = np.full(len(Q), np.inf)
    seg = np.zeros(len(Q), dtype=np.int64)
    signed = np.zeros(len(Q))
    two = P.shape[1] == 2
    for off in range(-window, window):
        i = np.clip(nearest + off, 0, len(Pk) - 2)
        A, B = Pk[i], Pk[i + 1]
        AB = B - A
        s = np.clip(np.einsum("ij,ij->i", Q - A, AB) / np.einsum("ij,ij->i", AB, AB), 0.0, 1.0)
        d = np.linalg.norm(Q - (A + s[:, None] * AB), axis=1)
        better = d < best
        best[better], seg[better] = d[better], i[better]
        if two:
            side = np.sign(AB[:, 0] * (Q - A)[:, 1] - AB[:, 1] * (Q - A)[:, 0])
            signed[better] = (side * d)[better]
    out = signed if two else best
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

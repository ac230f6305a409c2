"""Contour error of a two-axis motion: distance from the actual point to the commanded path.

The thesis compares predicted and measured contouring on circle and diamond toolpaths
(Figs 3.6, 3.7, 4.9, 4.10).  The contour error is the deviation normal to the path,
not the tracking error along it: each actual point is projected onto the commanded
path (a polyline through the commanded samples) and the signed distance kept, positive
to the left of the direction of travel (outside a counter-clockwise circle is right).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["contour_error"]


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

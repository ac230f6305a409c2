"""Commanded trajectories for the virtual-CNC tests: exact-stop moves with trapezoidal velocity."""

from __future__ import annotations

import numpy as np

TS = 0.001


def point_to_point(targets, a_max: float = 2000.0, v_max: float = 200.0, dwell: float = 0.05,
                   x0: float = 0.0) -> np.ndarray:
    """Commanded positions [mm] at 1 kHz through ``targets`` [mm], resting ``dwell`` s at each."""
    out = [np.full(int(dwell / TS), x0)]
    x = x0
    for target in targets:
        dist = abs(target - x)
        v = min(v_max, np.sqrt(dist * a_max))
        ta = v / a_max
        tc = (dist - v * ta) / v
        T = 2 * ta + tc
        t = np.minimum(np.arange(1, int(np.ceil(T / TS)) + 1) * TS, T)
        p = np.where(t < ta, 0.5 * a_max * t**2,
                     np.where(t < ta + tc, 0.5 * a_max * ta**2 + v * (t - ta), dist - 0.5 * a_max * (T - t) ** 2))
        out += [x + np.sign(target - x) * p, np.full(int(dwell / TS), target)]
        x = target
    return np.concatenate(out)

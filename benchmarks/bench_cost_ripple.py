"""How rough the free-run cost is in the base parameters, model by model, and whether the exact
slope (complex-step sensitivities) is the slope of its trend.

For each model of the augmented simulator (eq. 3.3 plus one effect, continuous and sampled
controller) a noisy recording is simulated from it, the base θ is moved 2 % off, and the
weighted cost is evaluated on 41 points across ±0.5 % of a1, b1 and d0, then of each of the
effect's own parameters (a second table; the effect's parameters stay at their true values
while the base is off).  Printed per parameter: the ripple (standard deviation of the cost about its quadratic trend, relative to
the cost) and the exact slope over the trend's slope at the centre (1: the exact slope is
the trend's).  A run discontinuous in a parameter (a switch decided for a whole sample or
sub-step) shows as a ripple with a slope ratio far from 1; a continuous but very
sensitive run (a loop that clips often, over a whole recording) as a large ripple too.

    python benchmarks/bench_cost_ripple.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ident.diagnosis.augmented import EP_INDEX, N_EP, segment_starts, sensitivities  # noqa: E402
from ident.diagnosis.spec import ModelSpec, make_chunk, sim_substeps, simulate_spec, sse  # noqa: E402
from tests.test_diagnosis_units import point_to_point  # noqa: E402  (the unit tests' moves)

TS = 1e-3
#: A PID drive with velocity feed-forward (the fadal-pid preset's loop), eq. 3.3 parameters.
THETA = np.array([192.65, 44356.0, 316830.0, 0.0, 190.1, 44356.0, 441.0, -302.0])
MODELS = {
    "base": (None, {}, None),
    "backlash, semi-closed": ("backlash", {"gap_mm": 0.06}, 0),
    "backlash, two-mass": ("backlash", {"gap_mm": 0.06, "motor_fraction": 0.75}, 1),
    "stribeck": ("stribeck", {"static_to_coulomb_ratio": 2.0, "stribeck_velocity_mm_s": 1.0}, None),
    # limit_slope started off 0, else its relative span is no span
    "saturation, anti-windup": ("saturation", {"limit": 3000.0, "limit_slope": 20.0}, 0),
    "saturation, no anti-windup": ("saturation", {"limit": 3000.0, "limit_slope": 20.0}, 1),
    "saturation, psi 0.5": ("saturation", {"limit": 3000.0, "limit_slope": 20.0, "position_motor_share": 0.5}, 0),
    "resonance, two-mass": ("resonance", {"freq_hz": 40.0, "damping": 0.05, "motor_fraction": 0.7}, 1),
    "time delay, in the loop": ("time_delay", {"delay_s": 0.0023}, 1),
}


#: θ's slots by name (the bench's base columns).
THETA_INDEX = {"a1": 0, "b1": 4, "d0": 6}


def ripple(spec: ModelSpec, chunk, name: str, span: float = 0.005) -> tuple[float, float]:
    """(ripple, exact slope / trend slope) of the cost along the parameter ``name`` (a slot of
    θ in :data:`THETA_INDEX` or an effect parameter of ``EP_INDEX``) around ``spec``."""
    vec, j = (spec.theta, THETA_INDEX[name]) if name in THETA_INDEX else (spec.ep, EP_INDEX[name])
    base = vec[j]
    u = np.linspace(-span, span, 41)
    c = []
    for du in u:
        s = spec.copy()
        (s.theta if vec is spec.theta else s.ep)[j] = base * (1.0 + du)
        c.append(sse(s, chunk))
    c = np.array(c)
    trend = np.polyfit(u, c, 2)
    d_th = np.zeros((1, 8))
    d_ep = np.zeros((1, N_EP))
    (d_th if vec is spec.theta else d_ep)[0, j] = base
    D = sensitivities(chunk.x_r, chunk.x, chunk.Ts, spec.theta, spec.ep, d_th, d_ep,
                      flags=spec.flags(), modes=spec.modes, starts=chunk.starts, derivs=chunk.derivs,
                      nsub=sim_substeps(spec, chunk.Ts), warm=chunk.warm)[0]
    m = chunk.score
    r = chunk.w[m] * (simulate_spec(spec, chunk)[m] - chunk.x[m])
    exact = 2.0 * float(r @ (chunk.w[m] * D[m]))
    return float(np.std(c - np.polyval(trend, u)) / c[len(u) // 2]), exact / trend[1]


def main() -> None:
    x_r = point_to_point(3)
    starts = segment_starts(x_r.size, None)
    rows = []
    print(f"{'model':26s} ctrl  " + "  ".join(f"{n:>22s}" for n in THETA_INDEX))
    for name, (effect, params, variant) in MODELS.items():
        for controller in (0, 1):
            true = ModelSpec(THETA.copy()) if effect is None else ModelSpec(THETA.copy()).with_effect(
                effect, params, variant)
            true.modes[4] = controller
            x = simulate_spec(true, make_chunk(x_r, x_r, TS, starts))
            x = x + np.random.default_rng(0).normal(0.0, 5e-5, x.size)
            chunk = make_chunk(x_r, x, TS, starts)
            off = true.copy()
            off.theta = off.theta * 1.02
            cells = [ripple(off, chunk, j) for j in THETA_INDEX]
            print(f"{name:26s} {controller:4d}  " + "  ".join(f"ripple {r:7.1e} slope {s:+6.2f}" for r, s in cells))
            rows.append((name, controller, off, chunk, list(params)))
    print(f"\n{'model':26s} ctrl  the effect's own parameters")
    for name, controller, off, chunk, names in rows:
        if names:
            cells = [(p, *ripple(off, chunk, p)) for p in names]
            print(f"{name:26s} {controller:4d}  " + "  ".join(
                f"{p} ripple {r:7.1e} slope {s:+6.2f}" for p, r, s in cells))


if __name__ == "__main__":
    main()

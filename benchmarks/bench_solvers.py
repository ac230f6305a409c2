"""Benchmark of the three solvers on a 25 s / 1 kHz synthetic recording (25 000 rows).

Prints, measured in this one run:

* wall time of ``ls``, ``exact`` and the GA (thesis defaults 4000 x 500) with the reduced
  objective of eq. 4.12;
* the same GA evaluating eq. 3.12 directly on the full Phi: only a few generations are run
  and the time per generation is extrapolated to 500 (said so in the output); the speed-up
  ratio (thesis section 4.2.5 claims 2-3 orders of magnitude);
* the GA-vs-exact cost gap over 20 seeds per case, and how many seeds are within 0.1 %.

Data: the PID drive of thesis Table 3.4 and the P-PI drive of Table 3.3 simulated on a
random point-to-point command (tests/_synthetic.py), regression columns from positions
only (central differences, eq. 3.9) with 0.1 um position noise.

Usage: python benchmarks/bench_solvers.py [--seeds 20] [--direct-generations 3] [--quick]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from _synthetic import PID_X, PPI_X, build_regression, simulate  # noqa: E402
from ident.model import Bounds  # noqa: E402
from ident.solvers import ReducedObjective, solve_exact, solve_ga, solve_ls  # noqa: E402

TS = 1e-3


def timed(fn, *args, **kw):
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    return out, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--direct-generations", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="population 1000 x 200 for the seed sweep")
    args = ap.parse_args()
    pop, gens = 4000, 500

    sim = simulate(PID_X, duration=25.0, Ts=TS, seed=11)
    Phi, Y = build_regression(sim, noise_mm=1e-4, seed=1)
    print(f"recording: 25 s at 1 kHz, regression {Phi.shape[0]} x {Phi.shape[1]} (PID drive, Table 3.4)")

    b = Bounds(zeta_max=0.3)  # makes a constraint active so that exact does its global search
    ls, t_ls = timed(solve_ls, Phi, Y)
    ex, t_ex = timed(solve_exact, Phi, Y, b, sample_period=TS)
    ex_free, t_ex_free = timed(solve_exact, Phi, Y, Bounds(), sample_period=TS)
    print(f"ls:                               {t_ls * 1e3:8.1f} ms  (condition number {ls.condition_number:.3g})")
    print(f"exact, LS feasible (Case 1):      {t_ex_free * 1e3:8.1f} ms")
    print(f"exact, zeta_max = 0.3 active:     {t_ex * 1e3:8.1f} ms  (certificate kkt_ok="
          f"{ex.details['certificate']['kkt_ok']}, grid {ex.details['certificate']['grid_points']} points)")

    t0 = time.perf_counter()
    obj = ReducedObjective(Phi, Y)
    t_pre = time.perf_counter() - t0
    ga, t_ga = timed(solve_ga, Phi, Y, b, sample_period=TS, seed=0, reduced=obj, population=pop, generations=gens)
    per_gen_fast = t_ga / gens
    print(f"precompute eq. 4.12 (one pass):   {t_pre * 1e3:8.1f} ms")
    print(f"GA {pop} x {gens}, eq. 4.12:        {t_ga:8.2f} s   ({per_gen_fast * 1e3:.2f} ms/generation, "
          f"fitness {ga.details['fitness_time_s'] / (gens + 1) * 1e3:.2f} ms/generation)")

    g = args.direct_generations
    gd, t_gd = timed(solve_ga, Phi, Y, b, sample_period=TS, seed=0, reduced=obj, population=pop, generations=g,
                     objective="direct")
    per_gen_direct = t_gd / (g + 1)  # g generations + the initial population's evaluation
    fit_direct = gd.details["fitness_time_s"] / (g + 1)
    fit_fast = ga.details["fitness_time_s"] / (gens + 1)
    print(f"GA {pop} x {g}, eq. 3.12 direct:     {t_gd:8.2f} s   ({per_gen_direct * 1e3:.1f} ms/generation) -- "
          f"only {g} generations run; EXTRAPOLATED to {gens}: {per_gen_direct * (gens + 1):.0f} s")
    print(f"speed-up of eq. 4.12 over eq. 3.12: whole GA {per_gen_direct / per_gen_fast:.0f}x, "
          f"fitness evaluation alone {fit_direct / fit_fast:.0f}x")

    # GA vs exact over seeds
    sweep_pop, sweep_gens = (1000, 200) if args.quick else (pop, gens)
    cases = [
        ("PID, default bounds (LS feasible)", PID_X, Bounds(), "deb"),
        ("PID, zeta_max = 0.3 (active)", PID_X, Bounds(zeta_max=0.3), "deb"),
        ("P-PI, default bounds", PPI_X, Bounds(), "deb"),
        ("PID, zeta_max = 0.3, thesis-printed SBX", PID_X, Bounds(zeta_max=0.3), "thesis"),
    ]
    print(f"\nGA ({sweep_pop} x {sweep_gens}) vs exact, {args.seeds} seeds, relative cost gap (f_GA - f_exact)/f_exact:")
    for name, model, bounds, sbx in cases:
        if model is PID_X:
            P, Yc, o = Phi, Y, obj
        else:
            P, Yc = build_regression(simulate(model, duration=25.0, Ts=TS, seed=12), noise_mm=1e-4, seed=2)
            o = ReducedObjective(P, Yc)
        e = solve_exact(P, Yc, bounds, sample_period=TS, objective=o)
        gaps = []
        t0 = time.perf_counter()
        for seed in range(args.seeds):
            r = solve_ga(P, Yc, bounds, sample_period=TS, seed=seed, reduced=o, population=sweep_pop,
                         generations=sweep_gens, sbx=sbx)
            gaps.append((r.cost - e.cost) / e.cost)
        gaps = np.array(gaps)
        print(f"  {name:42s} within 0.1 %: {int(np.sum(gaps < 1e-3)):2d}/{args.seeds}   "
              f"median {np.median(gaps):9.2e}  max {gaps.max():9.2e}  min {gaps.min():9.2e}   "
              f"active {list(e.active_constraints)}   ({(time.perf_counter() - t0) / args.seeds:.2f} s/run)")


if __name__ == "__main__":
    main()

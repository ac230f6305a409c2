"""GA (thesis §4.2, eq. 4.12 objective) vs the exact constrained solver on real regressions.

For each thesis preset (25 s identification run) and for the EMPS recording, build the
regression of eq. 3.11 as `agent identify` does, solve it exactly, then run the GA with
20 seeds (thesis defaults 4000 x 500 unless --population/--generations are given) and
count the seeds whose best cost is within 0.1 % of the exact one, and whether any is
lower beyond rounding.

    python benchmarks/bench_ga_vs_exact.py [--seeds 20] [--population 4000] [--generations 500]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from _recordings import PRESETS, emps_recording, preset_recording
from ident.model import Bounds
from ident.preprocessing import prepare_recording
from ident.regression import build_regression
from ident.solvers import solve_exact, solve_ga


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--population", type=int, default=4000)
    ap.add_argument("--generations", type=int, default=500)
    args = ap.parse_args()
    cases = [(name, preset_recording(name)) for name in PRESETS]
    emps = emps_recording()
    if emps is not None:
        cases.append(("EMPS", emps))
    print(f"GA {args.population} x {args.generations}, {args.seeds} seeds per case")
    print(f"{'case':10s} {'exact cost':>12s} {'exact s':>8s} {'GA s/run':>9s} {'within 0.1 %':>13s} "
          f"{'worst gap':>10s} {'below exact':>12s}")
    for name, rec in cases:
        rec = prepare_recording(rec)
        tr = rec.axes["X"]
        Ts = rec.sample_period
        reg = build_regression(tr.commanded, tr.actual, Ts, rec.segment)
        bounds = Bounds()
        t0 = time.perf_counter()
        ex = solve_exact(reg.Phi, reg.Y, bounds, sample_period=Ts)
        t_ex = time.perf_counter() - t0
        gaps, t_ga = [], 0.0
        for seed in range(args.seeds):
            t0 = time.perf_counter()
            ga = solve_ga(reg.Phi, reg.Y, bounds, sample_period=Ts, seed=1000 + seed,
                          population=args.population, generations=args.generations)
            t_ga += time.perf_counter() - t0
            gaps.append((ga.cost - ex.cost) / ex.cost)
        gaps = np.array(gaps)
        within = int(np.sum(gaps <= 1e-3))
        below = int(np.sum(gaps < -1e-9))
        print(f"{name:10s} {ex.cost:12.6g} {t_ex:8.3f} {t_ga / args.seeds:9.2f} {within:>6d}/{args.seeds:<6d} "
              f"{gaps.max():10.2e} {below:>12d}")


if __name__ == "__main__":
    main()

"""Wall time of the model free-run simulation and of the output-error refinement (issue 3).

* ``simulate``: eq. 3.3 with Coulomb friction, 25 s at 1 kHz (25 000 samples), after the
  numba warm-up, for 8 friction sub-steps (default) and 2 (the refinement's search);
  target ≤ 50 ms.
  Its accuracy: the friction-free model against ``scipy.signal.lsim`` of G_track (an
  independent reference; the simulator's feed-forward reads the central differences of
  eq. 3.9, lsim the transfer function, which leaves a floor of O(Ts²)), and with friction
  against the same simulator on 64 sub-steps, as rms over the tracking error's spread.
* ``refine``: from a perturbed start on a 25 s synthetic recording (thesis Table 4.1
  drive, 0.1 µm noise), and on EMPS (shared/data/emps) from the exact constrained solver;
  target ≲ 1 s.

Figures are medians of several runs in one process, printed with their ratio to the target.
The machine is shared: rerun when the load average is high.

Run:  python benchmarks/bench_model_simulation.py
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from ident.model import BASE_KEYS, Bounds, DriveModel, base_vector
from ident.refine import refine
from ident.regression import build_regression
from ident.simulation import simulate

TS = 1e-3
N = 25_000
WN, ZETA, P = 2 * np.pi * 33, 0.45, 2 * np.pi * 1.17
A2 = WN**2 + 2 * P * ZETA * WN
MODEL = DriveModel.from_search(WN, ZETA, P, 1.0, 190.1 / A2, 0.0, 441.0 / A2, -302.0 / A2)
EMPS = Path(__file__).resolve().parents[2] / "shared/data/emps/DATA_EMPS.mat"


def command(n: int = N, seed: int = 0) -> np.ndarray:
    """Random back-and-forth moves (trapezoid-like, smoothed velocity plateaus), mm."""
    rng = np.random.default_rng(seed)
    v = np.repeat(rng.uniform(-100, 100, n // 200 + 1), 200)[:n]
    v = np.convolve(v, np.ones(30) / 30, mode="same")
    return np.cumsum(v) * TS


def median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main() -> None:
    print(f"load average: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    x_r = command()
    t0 = time.perf_counter()
    simulate(MODEL, x_r[:100], TS)
    print(f"first call (numba cache load or compile): {time.perf_counter() - t0:.3f} s")
    for sub in (8, 2):
        t = median_time(lambda: simulate(MODEL, x_r, TS, substeps=sub), 21)
        print(f"simulate 25 s @ 1 kHz, {sub} sub-steps: {t * 1e3:7.2f} ms  "
              f"(target 50 ms: ratio {t / 0.05:.3f})")

    from scipy import signal

    ramp = x_r * np.minimum(np.arange(N) / 500.0, 1.0) ** 3  # from rest, as lsim starts
    t = np.arange(N) * TS
    linear = DriveModel(*[0.0 if k in ("d0", "d1") else v for k, v in zip(BASE_KEYS, base_vector(MODEL))])
    num, den = linear.tracking_tf()
    _, y, _ = signal.lsim((np.trim_zeros(num, "f"), den), ramp, t)
    fine = simulate(MODEL, ramp, TS, substeps=64)
    spread = np.std(ramp - fine)
    for sub in (2, 4, 8):
        lin = np.sqrt(np.mean((simulate(linear, ramp, TS, substeps=sub) - y) ** 2)) / np.std(ramp - y)
        fr = np.sqrt(np.mean((simulate(MODEL, ramp, TS, substeps=sub) - fine) ** 2)) / spread
        print(f"accuracy, {sub} sub-steps: friction-free vs lsim {lin:.1e}, with friction vs 64 sub-steps {fr:.1e} "
              "(rms over the tracking error's std)")

    rng = np.random.default_rng(1)
    x = simulate(MODEL, x_r, TS) + rng.normal(0, 1e-4, N)
    start = DriveModel.from_search(WN * 1.2, ZETA * 0.8, P * 1.5, 1.0, 1.2 * 190.1 / A2, 0.0,
                                   0.7 * 441.0 / A2, 1.3 * -302.0 / A2)
    times, res = [], None
    for _ in range(3):
        t0 = time.perf_counter()
        res = refine(start, x_r, x, TS)
        times.append(time.perf_counter() - t0)
    t = float(np.median(times))
    print(f"refine 25 s synthetic: {t:.3f} s (target 1 s: ratio {t:.2f}), {res.nfev} simulations, "
          f"fit {res.fit_before.tracking_error_fit_pct:.2f} % -> {res.fit_after.tracking_error_fit_pct:.3f} %")

    if EMPS.exists():
        from scipy.io import loadmat

        from ident.solvers import solve

        d = loadmat(EMPS)
        qg, qm = d["qg"].ravel() * 1e3, d["qm"].ravel() * 1e3
        t0 = time.perf_counter()
        R = build_regression(qg, qm, TS)
        t_reg = time.perf_counter() - t0
        t0 = time.perf_counter()
        ex = solve("exact", R.Phi, R.Y, Bounds(), sample_period=TS)
        t_ex = time.perf_counter() - t0
        times = []
        for _ in range(3):
            t0 = time.perf_counter()
            res = refine(ex.model, qg, qm, TS, shift=R.shift, regression=R)
            times.append(time.perf_counter() - t0)
        t = float(np.median(times))
        wn, zeta, p = res.model.search_variables(Bounds(), TS)
        print(f"EMPS ({qg.size} samples): regression {t_reg:.3f} s (shift {R.shift}, "
              f"threshold {R.vel_threshold:.3f} mm/s), exact solver {t_ex:.3f} s, "
              f"refine {t:.3f} s (target 1 s: ratio {t:.2f}), {res.nfev} simulations")
        print(f"EMPS fit: exact {res.fit_before.tracking_error_fit_pct:.2f} % "
              f"({res.fit_before.tracking_error_rms_mm * 1e3:.2f} µm rms) -> refined "
              f"{res.fit_after.tracking_error_fit_pct:.2f} % ({res.fit_after.tracking_error_rms_mm * 1e3:.2f} µm rms); "
              f"wn {wn / 2 / np.pi:.2f} Hz, zeta {zeta:.3f}, p {p / 2 / np.pi:.3f} Hz, "
              f"active {list(res.active_constraints)}")


if __name__ == "__main__":
    main()

"""Can the diagnosis's kernel simulate the identified model in place of the exact discretisation? (issue 39 item 1)

The identified eq. 3.3 model is simulated by ``ident.simulation`` (exact first-order-hold
discretisation of the linear part by matrix exponential, Karnopp friction on sub-steps);
the diagnosis's models by the kernel of ``ident.diagnosis.augmented`` (semi-implicit Euler
on sub-steps).  One kernel for both would need the kernel to reproduce the first.  This
script gives the kernel the identification's inputs — the feed-forward b0·ẍ_r + b1·ẋ_r as
one signal linear between samples (the kernel's velocity input with b0 = 0, b1 = 1), each
segment starting with the integral at zero and ẋ = ẋ_r (a warm start whose acceleration
leaves the integral at zero) — and compares, for the model identified on each recording:

* the difference to the exact discretisation (8 sub-steps, its default), rms over the
  tracking error's std, for the kernel on n sub-steps and for two runs on n and 2n
  extrapolated to second order (Richardson, 2·x̂(2n) − x̂(n));
* the free-run fit % (SPEC §5) each gives the same model;
* CPU time per simulation (median of 15, thread CPU time: the machine is shared).

Recordings: the three presets' identification runs (seed 1) and EMPS, and, when
../shared/data is present, drive-zoo-dev2 case_013 (a development case whose loop has a
pole near 500 Hz).

    python benchmarks/bench_one_kernel.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import ident  # noqa: E402
from _recordings import PRESETS, emps_recording, preset_recording  # noqa: E402
from ident.diagnosis.augmented import command_derivatives, segment_starts, simulate_augmented  # noqa: E402
from ident.metrics import fit_result  # noqa: E402
from ident.model import base_vector  # noqa: E402
from ident.preprocessing import shift_command  # noqa: E402
from ident.simulation import simulate  # noqa: E402

ZOO2 = Path(__file__).resolve().parents[2] / "shared" / "data" / "drive-zoo-dev2"


def kernel_run(theta: np.ndarray, x_r: np.ndarray, x0: np.ndarray, Ts: float, segment, nsub: int) -> np.ndarray:
    """The kernel's free run of eq. 3.3 (no effect, continuous) with the identification's inputs."""
    starts = segment_starts(x_r.size, segment)
    vr, ar = command_derivatives(x_r, Ts, starts)
    a1, a2, _, b0, b1, b2, d0, d1 = theta
    feed = b0 * ar + b1 * vr
    friction = np.where(vr > 0.0, d0, np.where(vr < 0.0, d1, 0.0))
    acc = (feed + b2 * x_r - a2 * x0 - a1 * vr - friction) / (1.0 - 0.5 * (Ts / nsub) * a1)
    th = theta.copy()
    th[3:5] = 0.0, 1.0
    return simulate_augmented(x_r, x0, Ts, th, starts=starts, derivs=(feed, np.zeros_like(x_r)), nsub=nsub,
                              warm=(starts, vr, acc))


def cpu_ms(fn, reps: int = 15) -> float:
    fn()
    times = []
    for _ in range(reps):
        t0 = time.thread_time()
        fn()
        times.append(time.thread_time() - t0)
    return 1e3 * float(np.median(times))


def main() -> None:
    recordings = {p: preset_recording(p) for p in PRESETS}
    emps = emps_recording()
    if emps is not None:
        recordings["EMPS"] = emps
    if (ZOO2 / "case_013.csv").exists():
        recordings["dev2 case_013"] = ident.load(ZOO2 / "case_013.csv")
    print("| recording | simulator | rms diff / std(e) | fit % | CPU ms |")
    print("|---|---|---|---|---|")
    for name, rec in recordings.items():
        r = next(iter(ident.identify(rec, diagnose=False).axes.values()))
        tr = rec.axes[r.axis]
        Ts, seg = rec.sample_period, rec.segment
        x_r = shift_command(tr.commanded, r.shift, seg)
        x0 = np.ascontiguousarray(tr.actual, dtype=float)
        theta = base_vector(r.model)
        e = tr.commanded - tr.actual
        runs = {"exact, 8 sub-steps": lambda: simulate(r.model, x_r, Ts, segment=seg, x0=x0),
                "exact, 2 sub-steps": lambda: simulate(r.model, x_r, Ts, segment=seg, x0=x0, substeps=2)}
        for n in (2, 4, 8, 16):
            runs[f"kernel, {n} sub-steps"] = (lambda n=n: kernel_run(theta, x_r, x0, Ts, seg, n))
        for n in (2, 4, 8):
            runs[f"kernel, {n} and {2 * n} extrapolated"] = (
                lambda n=n: 2.0 * kernel_run(theta, x_r, x0, Ts, seg, 2 * n) - kernel_run(theta, x_r, x0, Ts, seg, n))
        exact = runs["exact, 8 sub-steps"]()
        for label, run in runs.items():
            x_hat = run()
            diff = float(np.sqrt(np.mean((x_hat - exact) ** 2)) / np.std(e))
            fit = fit_result(e, tr.commanded - x_hat).tracking_error_fit_pct
            print(f"| {name} | {label} | {diff:.1e} | {fit:.3f} | {cpu_ms(run):.2f} |")


if __name__ == "__main__":
    main()

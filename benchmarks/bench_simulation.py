"""Wall time of the virtual CNC servo simulation (issue 2 item 6).

Simulates a 25 s program at the 1 kHz servo rate on two axes (X, Y of the default
preset) with the plant integrated at 20 kHz (20 substeps) and 10 kHz (10 substeps) and
prints the wall time and its ratio to real time (25 s), excluding and including the
numba JIT compilation.  "Cold" runs in a fresh interpreter with an empty numba cache
(full compilation); "cached" in a fresh interpreter with the on-disk cache.

Run:  python benchmarks/bench_simulation.py
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace

import numpy as np

DURATION_S = 25.0
TS = 0.001


def trajectory(n: int, seed: int = 0) -> np.ndarray:
    """Random point-to-point moves with 2000 mm/s² trapezoids, like the identification program."""
    rng = np.random.default_rng(seed)
    out = np.empty(n)
    x, k = 0.0, 0
    a_max, v_max = 2000.0, 200.0
    while k < n:
        target = rng.uniform(-10, 10)
        dist = abs(target - x)
        v = min(v_max, np.sqrt(dist * a_max))
        ta = v / a_max
        tc = (dist - v * ta) / v if v > 0 else 0.0
        T = 2 * ta + tc
        t = np.arange(1, int(np.ceil(T / TS)) + 1) * TS
        t = np.minimum(t, T)
        p = np.where(t < ta, 0.5 * a_max * t**2,
                     np.where(t < ta + tc, 0.5 * a_max * ta**2 + v * (t - ta), dist - 0.5 * a_max * (T - t) ** 2))
        seg = np.concatenate([x + np.sign(target - x) * p, np.full(20, target)])
        m = min(seg.size, n - k)
        out[k:k + m] = seg[:m]
        k += m
        x = target
    return out


def run_once(substeps: int) -> float:
    from virtual_cnc.presets import DEFAULT_MACHINE, load_machine
    from virtual_cnc.servo import simulate_machine

    m = load_machine(DEFAULT_MACHINE)
    m = replace(m, axes={k: replace(a, substeps=substeps) for k, a in m.axes.items()})
    n = int(round(DURATION_S / TS))
    cmd = {"X": trajectory(n, 1), "Y": trajectory(n, 2)}
    t0 = time.perf_counter()
    simulate_machine(cmd, m, seed=0)
    return time.perf_counter() - t0


def first_call_in_fresh_process(cache_dir: str | None) -> float:
    env = dict(os.environ)
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    code = ("import sys; sys.path.insert(0, %r); import bench_simulation as b; "
            "print(b.run_once(20))" % os.path.dirname(os.path.abspath(__file__)))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def main() -> None:
    print(f"simulated: {DURATION_S:g} s program, servo 1 kHz, 2 axes (default preset)")
    with tempfile.TemporaryDirectory() as tmp:
        cold = first_call_in_fresh_process(tmp)
    cached = first_call_in_fresh_process(None)
    print(f"  first call, cold JIT compile   : {cold:7.3f} s wall  ({cold / DURATION_S:.3f} x real time)")
    print(f"  first call, numba cache on disk: {cached:7.3f} s wall  ({cached / DURATION_S:.3f} x real time)")
    run_once(20)  # warm up in this process
    for substeps in (20, 10):
        times = [run_once(substeps) for _ in range(3)]
        best = min(times)
        print(f"  after warm-up, plant {substeps / TS / 1000:.0f} kHz: {best:7.3f} s wall "
              f"(best of 3)  ({best / DURATION_S:.4f} x real time, {DURATION_S / best:.0f}x faster than real time)")


if __name__ == "__main__":
    main()

"""Wall time of predicting a part program on the identified drives (issue 15).

A 60 s, three-axis part program (lines and arcs in XY at 30–150 mm/s, Z steps between
passes) run on a virtual machine identified from a fadal-pid (Table 3.4) capture — the
X model is also used for Z — at 1 kHz: interpolation, the free run of every axis and the
contour-error analysis, after start-up (the first run, which loads numba's cache, is
reported apart).  Once on the plain identified model (eq. 3.3, exact discretisation) and
once with a backlash and a Stribeck effect on every axis (the diagnosis's simulator).
Target: ≤ 1 s.  Figures are medians of 5 runs in one process.

Run:  python benchmarks/bench_predict.py
"""

from __future__ import annotations

import json
import math
import os
import time

import numpy as np

import gcode_gen
import ident
import virtual_cnc
from gcode_gen.program import Block, Toolpath
from ident.prediction import analyse

TARGET_S = 1.0


def part_program(duration_s: float = 60.0, seed: int = 0) -> Toolpath:
    """Random lines and quarter/half arcs in XY with Z steps, about ``duration_s`` long at its feeds."""
    rng = np.random.default_rng(seed)
    blocks = [Block(line=1, n=None, motion="G0", target={"X": 0.0, "Y": 0.0, "Z": 0.0})]
    x = y = z = 0.0
    t = 0.0
    while t < duration_s:
        feed = float(rng.choice([30.0, 60.0, 100.0, 150.0]))
        if rng.random() < 0.5:
            nx, ny = (round(float(v), 3) for v in rng.uniform(-40, 40, 2))
            blocks.append(Block(line=len(blocks) + 1, n=None, motion="G1", target={"X": nx, "Y": ny}, feed=feed))
            t += math.hypot(nx - x, ny - y) / feed + 0.05
        else:
            r = float(rng.uniform(3, 15))
            sweep = float(rng.choice([0.5, 1.0])) * math.pi
            a0 = float(rng.uniform(0, 2 * math.pi))
            cx, cy = x - r * math.cos(a0), y - r * math.sin(a0)
            nx, ny = round(cx + r * math.cos(a0 + sweep), 3), round(cy + r * math.sin(a0 + sweep), 3)
            blocks.append(Block(line=len(blocks) + 1, n=None, motion="G3", target={"X": nx, "Y": ny}, feed=feed,
                                center={"X": cx, "Y": cy}))
            t += r * sweep / feed + 0.05
        x, y = nx, ny
        if rng.random() < 0.1:
            z = round(z - 0.5, 3)
            blocks.append(Block(line=len(blocks) + 1, n=None, motion="G1", target={"Z": z}, feed=20.0))
            t += 0.5 / 20.0 + 0.05
    return Toolpath(name="part", blocks=tuple(blocks), header={"program": "bench part"})


def machine(effects: bool) -> ident.VirtualMachine:
    rec = virtual_cnc.simulate(gcode_gen.generate(["X", "Y"], seed=3), "fadal-pid", seed=3)
    doc = json.loads(ident.identify(rec, diagnose=False).to_json())
    doc["axes"]["Z"] = doc["axes"]["X"]
    if effects:
        for r in doc["axes"].values():
            r["virtual_model"]["effects"] = {"backlash": {"gap_mm": 0.01},
                                             "stribeck": {"static_to_coulomb_ratio": 1.5, "stribeck_velocity_mm_s": 1.0}}
            r["virtual_model"]["preview_shift_samples"] = 0
    return ident.VirtualMachine.from_result(doc, "fadal-pid (identified)" + (" + effects" if effects else ""))


def main() -> None:
    print(f"load average: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    program = part_program()
    for effects in (False, True):
        vm = machine(effects)
        t0 = time.perf_counter()
        first = analyse(vm.run([program]))
        startup = time.perf_counter() - t0
        times = []
        for _ in range(5):
            t0 = time.perf_counter()
            analyse(vm.run([program]))
            times.append(time.perf_counter() - t0)
        rec = first.prediction.recording
        wall = float(np.median(times))
        print(f"{vm.name}: {rec.duration:.1f} s program, {len(rec.axes)} axes, {rec.n_samples} samples: "
              f"{wall:.3f} s (first run {startup:.3f} s); {wall / TARGET_S:.2f} x the {TARGET_S:g} s target, "
              f"{rec.duration / wall:.0f} x faster than real time; max contour error {first.contour_max_mm * 1e3:.1f} µm")


if __name__ == "__main__":
    main()

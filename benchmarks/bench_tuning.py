"""Tuning on the virtual CNC (issue 42): plant recovery and the ballbar before and after.

For each machine — the presets fadal-pid (thesis Table 3.4) and fadal-ppi (Table 3.3), and
a detuned, mismatched fadal-pid whose Y loop is soft (Kp 20, Ki 60, Kd 0.10) — the
identification programs (X and Y, seed 3) are run on the virtual CNC and identified
(no diagnosis); ``ident.tuning.tune`` derives the plants from the identified models and the
machine's gains and proposes gains for the ISO 230-4 ballbar (R 100 mm at 1000 mm/min);
the virtual CNC then runs the ballbar pair with the original and the proposed gains
(encoder noise seed 4).  Printed: the recovered plant against the machine's, the
predicted and measured circularity (larger of ccw/cw) before and after, and the servo
mismatch the measured plots read.  One run; the figures in docs/tuning.md come from here.

Run:  python benchmarks/bench_tuning.py
"""

from __future__ import annotations

import json
import time
from dataclasses import replace

import gcode_gen
import ident
import virtual_cnc
from gcode_gen.toolpaths import circle
from ident.synthetic_ballbar import ballbar_of_recording
from ident.tuning import Criterion, Gains, tune
from virtual_cnc.drive import Controller
from virtual_cnc.presets import PRESETS

RADIUS, FEED = 100.0, 1000.0 / 60.0


def detuned():
    m = PRESETS["fadal-pid"]
    y = m.axes["Y"]
    return replace(m, name="detuned-xy", axes={**m.axes, "Y": replace(y, controller=Controller("pid", 20.0, 60.0, 0.10))})


def measured(machine):
    recs = [virtual_cnc.simulate([circle(size=2 * RADIUS, feed=FEED, axes=("X", "Y"), direction=d, start_deg=45.0,
                                         name=f"bb_{d}")], machine, seed=4) for d in ("ccw", "cw")]
    return ballbar_of_recording(recs, ("X", "Y"), RADIUS, FEED)


def main() -> None:
    for machine, form in ((PRESETS["fadal-pid"], "pid"), (PRESETS["fadal-ppi"], "p-pi"), (detuned(), "pid")):
        rec = virtual_cnc.simulate(gcode_gen.generate(["X", "Y"], seed=3), machine, seed=3)
        vm = ident.VirtualMachine.from_result(json.loads(ident.identify(rec, diagnose=False).to_json()), machine.name)
        gains = {a: Gains(form, {"Kp": d.controller.Kp, "Ki": d.controller.Ki, "Kd": d.controller.Kd}, u_max=d.plant.u_max)
                 for a, d in machine.axes.items()}
        t0 = time.perf_counter()
        result = tune(vm, gains, Criterion.ballbar(vm, ("X", "Y"), RADIUS, FEED))
        dt = time.perf_counter() - t0
        print(f"{machine.name} ({form}), tune {dt:.1f} s")
        for a, p in result.plants.items():
            t = machine.axes[a].plant
            print(f"  {a}: K/J {p.kj:.1f} ({100 * (p.kj / t.K_over_J - 1):+.1f} %), B/J {p.bj:.2f} (true {t.B_over_J:.2f}), "
                  f"d+ {p.d_plus:.3f} ({100 * (p.d_plus / t.d_plus - 1):+.1f} %), "
                  f"d- {p.d_minus:.3f} ({100 * (p.d_minus / t.d_minus - 1):+.1f} %)")
        tuned = replace(machine, axes={a: replace(d, controller=Controller(d.controller.kind, *result.after[a].law()[1:]))
                                       for a, d in machine.axes.items()})
        mb, ma = measured(machine), measured(tuned)
        cb, ca = (max(f.circularity_um for f in r.runs) for r in (mb, ma))
        print(f"  circularity predicted {result.predicted_before:.2f} -> {result.predicted_after:.2f} µm "
              f"({100 * (result.predicted_after / result.predicted_before - 1):+.0f} %), measured {cb:.2f} -> {ca:.2f} µm "
              f"({100 * (ca / cb - 1):+.0f} %); after: measured/predicted {ca / result.predicted_after:.3f}")
        print(f"  servo mismatch measured {mb.servo_mismatch_ms:+.3f} -> {ma.servo_mismatch_ms:+.3f} ms; "
              f"design {result.design}")


if __name__ == "__main__":
    main()

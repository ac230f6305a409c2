"""Tuning on the virtual CNC (issue 42): plant recovery and the ballbar before and after.

For each machine — the presets fadal-pid (thesis Table 3.4) and fadal-ppi (Table 3.3), and
a detuned, mismatched fadal-pid whose Y loop is soft (Kp 20, Ki 60, Kd 0.10) — the
identification programs (X and Y, seed 3) are run on the virtual CNC and identified
(no diagnosis).  The plants are derived both ways — fitted to the recording through the
controller's sampled loop (``derive_plant(..., recording=rec)``, docs/tuning.md) and from
the identified model alone — and printed against the machine's.  ``ident.tuning.tune``
with the recording then proposes gains for two ballbar tests: the ISO 230-4 one (R 100 mm at
1000 mm/min) and the short fast circle of tests/test_tuning.py (R 20 mm at 50 mm/s); the
virtual CNC runs each ballbar pair with the original and the proposed gains (encoder noise
seed 4).  Printed: the predicted and measured circularity (larger of ccw/cw) before and
after, and the servo mismatch the measured plots read.  One run; the figures in
docs/tuning.md come from here.

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
from ident.tuning import Criterion, Gains, derive_plant, tune
from virtual_cnc.drive import Controller
from virtual_cnc.presets import PRESETS

TESTS = ((100.0, 1000.0 / 60.0), (20.0, 50.0))  # (radius mm, feed mm/s)


def detuned():
    m = PRESETS["fadal-pid"]
    y = m.axes["Y"]
    return replace(m, name="detuned-xy", axes={**m.axes, "Y": replace(y, controller=Controller("pid", 20.0, 60.0, 0.10))})


def measured(machine, radius, feed):
    recs = [virtual_cnc.simulate([circle(size=2 * radius, feed=feed, axes=("X", "Y"), direction=d, start_deg=45.0,
                                         name=f"bb_{d}")], machine, seed=4) for d in ("ccw", "cw")]
    return ballbar_of_recording(recs, ("X", "Y"), radius, feed)


def pct(x: float, true: float) -> str:
    return f"{x:.4g} ({100 * (x / true - 1):+.1f} %)"


def main() -> None:
    for machine, form in ((PRESETS["fadal-pid"], "pid"), (PRESETS["fadal-ppi"], "p-pi"), (detuned(), "pid")):
        rec = virtual_cnc.simulate(gcode_gen.generate(["X", "Y"], seed=3), machine, seed=3)
        vm = ident.VirtualMachine.from_result(json.loads(ident.identify(rec, diagnose=False).to_json()), machine.name)
        gains = {a: Gains(form, {"Kp": d.controller.Kp, "Ki": d.controller.Ki, "Kd": d.controller.Kd}, u_max=d.plant.u_max)
                 for a, d in machine.axes.items()}
        print(f"{machine.name} ({form})")
        for how, rec_or_none in (("fitted to the recording", rec), ("from the identified model", None)):
            t0 = time.perf_counter()
            plants = {a: derive_plant(vm.axes[a], gains[a], a, recording=rec_or_none) for a in machine.axes}
            print(f"  plant {how} ({time.perf_counter() - t0:.1f} s)")
            for a, p in plants.items():
                t = machine.axes[a].plant
                fit = f", fit {p.fit_pct:.2f} %" if p.fit_pct is not None else ""
                print(f"    {a}: K/J {pct(p.kj, t.K_over_J)}, B/J {pct(p.bj, t.B_over_J)}, "
                      f"d+ {pct(p.d_plus, t.d_plus)}, d- {pct(p.d_minus, t.d_minus)}{fit}")
        for radius, feed in TESTS:
            t0 = time.perf_counter()
            result = tune(vm, gains, Criterion.ballbar(vm, ("X", "Y"), radius, feed), recording=rec)
            dt = time.perf_counter() - t0
            tuned = replace(machine, axes={a: replace(d, controller=Controller(d.controller.kind,
                                                                               *result.after[a].law()[1:]))
                                           for a, d in machine.axes.items()})
            mb, ma = measured(machine, radius, feed), measured(tuned, radius, feed)
            cb, ca = (max(f.circularity_um for f in r.runs) for r in (mb, ma))
            print(f"  ballbar R {radius:g} mm at {feed:.4g} mm/s (tune {dt:.1f} s): predicted "
                  f"{result.predicted_before:.2f} -> {result.predicted_after:.2f} µm "
                  f"({100 * (result.predicted_after / result.predicted_before - 1):+.0f} %), measured {cb:.2f} -> "
                  f"{ca:.2f} µm ({100 * (ca / cb - 1):+.0f} %); before: measured/predicted "
                  f"{cb / result.predicted_before:.3f}, after: {ca / result.predicted_after:.3f}")
            print(f"    servo mismatch measured {mb.servo_mismatch_ms:+.3f} -> {ma.servo_mismatch_ms:+.3f} ms; "
                  f"design {result.design}; notes {list(result.notes)}")


if __name__ == "__main__":
    main()

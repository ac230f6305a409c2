"""Write fixtures/pid_law/reference.csv: the servo outputs of both position-loop kernels on a
fixed command whose step drives the output into its limit (the anti-windup acts).

The two kernels — the virtual CNC's servo (:func:`virtual_cnc.servo.simulate_axis_response`)
and the tuner's sampled loop (:func:`ident.tuning.loop.simulate_loop`) — share one law,
:func:`core.pid_law.position_law`; tests/test_pid_law.py checks that they still give these
numbers bit for bit.  The file was first written by the kernels as they were before the law
was shared (each with its own copy).  Run: ``PYTHONPATH=. python scripts/make_pid_law_reference.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ident.tuning.loop import Timing, simulate_loop
from virtual_cnc.effects import Saturation
from virtual_cnc.presets import load_machine
from virtual_cnc.servo import simulate_axis_response

OUT = Path(__file__).resolve().parents[1] / "fixtures" / "pid_law" / "reference.csv"
TS = 1e-3
N = 300

#: gains of the tuner's loop per form (PID in LinuxCNC's terms with every feed-forward on)
LOOP_GAINS = {"pid": dict(Kp=30.0, Ki=400.0, Kd=0.2, Kv=0.03, Ka=0.0005, Kf0=0.01),
              "ppi": dict(Kp=40.0, Ki=60.0, Kd=0.3, Kv=1.0, Ka=0.002)}
#: the LinuxCNC-like timing (velocity measured, one period late, previous target)
LATE = Timing(central_reference=False, measured_velocity=True, delay=1, previous_target=True)


def command() -> np.ndarray:
    """A sine with a 5 mm step at 0.1 s, mm: the step saturates the output."""
    t = np.arange(N) * TS
    return 20.0 * np.sin(2 * np.pi * 1.5 * t) + 5.0 * (t >= 0.1)


def outputs() -> dict[str, np.ndarray]:
    """Column name → the kernel's output on :func:`command`."""
    xr = command()
    out = {}
    for kind, gains in LOOP_GAINS.items():
        for integration, timing in (("continuous", Timing()), ("euler", LATE)):
            x, u = simulate_loop(xr, TS, kind=kind, **gains, kj=1000.0, bj=2.5, d_plus=0.4, d_minus=-0.3,
                                 u_max=8.0, timing=timing, integration=integration)
            out[f"loop_{kind}_{integration}_x"], out[f"loop_{kind}_{integration}_u"] = x, u
    for machine in ("fadal-ppi", "fadal-pid"):
        r = simulate_axis_response(xr, load_machine(machine).axes["X"], (Saturation(limit_v=3.0),),
                                   rng=np.random.default_rng(5))
        out[f"servo_{machine}_actual"], out[f"servo_{machine}_u"] = r.actual, r.u
    return out


def main() -> None:
    cols = outputs()
    OUT.parent.mkdir(parents=True, exist_ok=True)
    with OUT.open("w") as f:
        f.write(",".join(cols) + "\n")
        for row in zip(*cols.values()):
            f.write(",".join(repr(float(v)) for v in row) + "\n")  # repr: the exact double
    print(f"wrote {OUT} ({len(cols)} columns x {N} samples)")


if __name__ == "__main__":
    main()

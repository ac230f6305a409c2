"""Predicted vs measured contour error and cycle time on the two-axis LinuxCNC (issue 41).

The headless LinuxCNC of fixtures/linuxcnc started with X and Y (`machine.py start --axes
XY`: different gains on X and Y), identified from its own capture (agent capture over
linuxcnc://, agent identify), then each program is run on LinuxCNC while captured and
predicted stand-alone by `agent predict PROGRAM --machine result.json --ini machine.ini
--against RECORDING`: the program planned here with LinuxCNC's per-axis limits from the
INI and run on the identified drives, against the measured contour error over the same
feed moves, and the program's run time; and the same with the path-limited planner (no
--ini), to show what planning with per-axis limits changes.  Programs: circle and diamond
(20 mm) at 10 and 100 mm/s, the diamond at 100 mm/s blended (G64 P0.01 and P0.1), the
ballbar test (`agent ballbar --program-out`: R 10 mm at 1000 mm/min, ccw and cw with 180°
feed-in/out arcs, one program) and a small part (fixtures/linuxcnc/part.ngc).
Every run starts with the machine switched off and on (the loop's state at zero, the
state the prediction assumes).  Targets: max within 5 %, rms of the difference <= 10 % of
the measured rms, cycle time within 1 %.  One run each; LinuxCNC runs in real time, so the
servo thread may be disturbed by other load on the computer.

Run (where LinuxCNC is installed; about 2 minutes):  python benchmarks/bench_linuxcnc_contour.py [--set y.static_n=24 ...]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
AGENT = [sys.executable, "-m", "agent.cli"]
PORT = "linuxcnc://?joints=0,1&axes=X,Y"

_spec = importlib.util.spec_from_file_location("linuxcnc_machine", ROOT / "fixtures/linuxcnc/machine.py")
lm = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(lm)


def agent(*args: object) -> str:
    res = subprocess.run(AGENT + [str(a) for a in args], cwd=ROOT, capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(f"agent {' '.join(map(str, args))}: {res.stderr.strip()}")
    return res.stdout


def capture(m, programs: list[Path], out: Path, port: str = PORT) -> None:
    """Capture ``out`` while the machine (switched off and on first) runs ``programs``.

    A following-error trip aborts the program: client.py then fails and so does this."""
    proc = subprocess.Popen(AGENT + ["capture", "--quiet", "--port", port, "-o", str(out)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    while not out.exists():
        if proc.poll() is not None:
            raise SystemExit(f"capture: {proc.stderr.read()}")
        time.sleep(0.05)
    time.sleep(0.2)
    m.run(*programs, restart=True)
    _, err = proc.communicate(timeout=60)
    if proc.returncode != 0:
        raise SystemExit(f"capture: {err}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="a [PLANT] value (machine.py)")
    a = ap.parse_args()
    why = lm.missing()
    if why:
        print(why)
        return 1
    work = Path(tempfile.mkdtemp(prefix="bench-linuxcnc-"))
    overrides = dict(kv.split("=", 1) for kv in a.set)
    with lm.Machine(overrides, axes="XY") as m:
        agent("generate", "--axes", "X,Y", "--dialect", "linuxcnc", "--seed", 1, "--n-high", 30, "-o", work / "ident")
        capture(m, [work / "ident/ident_low.ngc", work / "ident/ident_high.ngc"], work / "ident.mcap")
        t0 = time.monotonic()
        agent("identify", work / "ident.mcap", "--json", work / "result.json")
        print(f"identified from {work / 'ident.mcap'} in {time.monotonic() - t0:.0f} s "
              f"(LinuxCNC {', '.join(f'{k}={v}' for k, v in overrides.items()) or 'clean'})")
        ini = m.run_dir / "machine.ini"
        cases = []
        for kind in ("circle", "diamond"):
            for feed in (10, 100):
                agent("generate", "--toolpath", kind, "--size", 20, "--feed", feed, "--dialect", "linuxcnc",
                      "-o", work / f"{kind}{feed}")
                cases.append((f"{kind} {feed} mm/s", work / f"{kind}{feed}" / f"{kind}.ngc", f"{kind}{feed}"))
        # blended (G64 P): the generator's P0.01 and a copy with P0.1
        agent("generate", "--toolpath", "diamond", "--size", 20, "--feed", 100, "--dialect", "linuxcnc", "--blending",
              "-o", work / "blend")
        text = (work / "blend/diamond.ngc").read_text()
        (work / "blend/diamond_p01.ngc").write_text(text.replace("G64 P0.01", "G64 P0.1"))
        cases.append(("diamond 100 mm/s G64 P0.01", work / "blend/diamond.ngc", "blend001"))
        cases.append(("diamond 100 mm/s G64 P0.1", work / "blend/diamond_p01.ngc", "blend01"))
        agent("ballbar", "--machine", work / "result.json", "--ini", ini, "--radius", 10, "--feed", 1000 / 60,
              "--program-out", work / "ballbar.ngc")
        cases.append(("ballbar ccw+cw R10 1000 mm/min", work / "ballbar.ngc", "ballbar"))
        cases.append(("part (fixtures/linuxcnc/part.ngc)", ROOT / "fixtures/linuxcnc/part.ngc", "part"))
        rows = []
        for name, prog, stem in cases:
            rec = work / f"{stem}.mcap"
            capture(m, [prog], rec)
            agent("predict", prog, "--machine", work / "result.json", "--ini", ini, "--against", rec,
                  "--json", work / "p.json")
            c = json.loads((work / "p.json").read_text())["comparisons"][0]
            s = c["standalone"]
            # the same with the path-limited planner (no --ini): what per-axis planning changes
            agent("predict", prog, "--machine", work / "result.json", "--against", rec, "--json", work / "q.json")
            q = json.loads((work / "q.json").read_text())["comparisons"][0]
            rows.append((name, c["measured_max_abs_mm"] * 1e3, s["predicted_max_abs_mm"] * 1e3, s["max_ratio"] - 1,
                         s["rms_difference_ratio"], c["rms_difference_ratio"], c["measured_cycle_time_s"],
                         c["predicted_cycle_time_s"], q["standalone"]["max_ratio"] - 1,
                         q["predicted_cycle_time_s"] / q["measured_cycle_time_s"] - 1))
        bb = agent("ballbar", "--machine", work / "result.json", "--ini", ini, "--radius", 10, "--feed", 1000 / 60,
                   "--against", work / "ballbar.mcap")
    print(f"\n{'program':34s} {'measured':>9s} {'predicted':>9s} {'max':>7s} {'rms diff':>8s} {'(rec cmd)':>9s}"
          f" {'cycle meas.':>11s} {'pred.':>7s} {'diff':>7s} | path-limited: {'max':>7s} {'cycle':>7s}")
    for name, mm, pm, dmax, rms, rms_rec, cm, cp, path_max, path_cycle in rows:
        print(f"{name:34s} {mm:7.2f}µm {pm:7.2f}µm {dmax * 100:+6.1f}% {rms * 100:7.1f}% {rms_rec * 100:8.1f}%"
              f" {cm:10.3f}s {cp:6.3f}s {(cp / cm - 1) * 100:+6.2f}% | {'':14s}"
              f"{path_max * 100:+6.1f}% {path_cycle * 100:+6.2f}%")
    print("\nagent ballbar --against the recorded test:")
    print("\n".join("  " + ln for ln in bb.splitlines() if "circularity" in ln or "hysteresis" in ln or "recorded" in ln))
    ok = all(abs(r[3]) <= 0.05 and r[4] <= 0.10 and abs(r[7] / r[6] - 1) <= 0.01 for r in rows)
    print(f"\nall within max 5 %, rms 10 %, cycle 1 %: {ok}   (recordings in {work})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

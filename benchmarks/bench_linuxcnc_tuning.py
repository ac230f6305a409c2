"""`agent tune` proven on the two-axis LinuxCNC (issue 42 item 3): poor, mismatched pid gains
→ capture, identify, tune, apply the proposed INI lines, run again, measure.

1. The headless LinuxCNC of fixtures/linuxcnc with X and Y (`machine.py start --axes XY`),
   started from a copy of machine.ini whose [JOINT_0]/[JOINT_1] pid gains are deliberately
   poor and different on X and Y (POOR below: X 10.8 Hz ζ 0.49, Y 8.6 Hz ζ 0.45 with a
   3× faster integrator, on the true plants).
2. The identification programs captured over linuxcnc:// and identified (`agent identify
   --no-diagnose`: the machine is clean).
3. The ballbar test (`agent ballbar --program-out`: R 10 mm at 1000 mm/min, ccw and cw) and
   fixtures/linuxcnc/part.ngc run and captured with the poor gains.
4. `agent tune --machine result.json --ballbar --lead-deg 180 --ini machine.ini --plant-integration
   euler` (the test as `agent ballbar --program-out` wrote it; the fixture's HAL plant takes one
   Euler step per period, docs/tuning.md; planned with the INI's per-axis limits) proposes the
   gains; the same proposal checked on the part (`agent tune --program part.ngc --propose …`)
   gives its predicted max contour error.  The printed INI diff is applied with `patch` to a
   copy of the running machine's INI; LinuxCNC is restarted from that copy (`machine.py
   start --ini`): agent tune never writes to a controller.
5. Ballbar and part run and captured again.  Measured: the circularity of the recorded test
   (`agent ballbar --against`, the larger of ccw and cw, the figure agent tune predicts) and
   the part's max |contour error| over its feed moves (`agent predict --against`).

Targets: both drop by ≥ 30 % against the poor gains; the tuned run's measured figures within
10 % of agent tune's prediction; no following-error trip (LinuxCNC would abort the program).

Run (where LinuxCNC is installed; about 3 minutes):  python benchmarks/bench_linuxcnc_tuning.py
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

from bench_linuxcnc_contour import agent, capture, lm  # benchmarks/ is on sys.path

ROOT = Path(__file__).resolve().parent.parent
PART = ROOT / "fixtures/linuxcnc/part.ngc"
RADIUS, FEED, LEAD = 10.0, 1000.0 / 60.0, 180.0  # the test: R, feed, feed-in/out arcs (agent ballbar's)
# deliberately poor and mismatched: [JOINT_n] key -> value
POOR = {0: {"P": 5.0, "I": 25.0, "D": 0.07}, 1: {"P": 3.0, "I": 40.0, "D": 0.05}}

def with_gains(src: Path, dst: Path, gains: dict[int, dict[str, float]]) -> None:
    """A copy of the INI with these [JOINT_n] keys set."""
    lines, section = [], ""
    for line in src.read_text().splitlines():
        s = line.strip()
        if s.startswith("["):
            section = s.strip("[]")
        else:
            j = int(section[6:]) if re.fullmatch(r"JOINT_\d+", section) else None
            key = s.split("=", 1)[0].strip() if "=" in s and not s.startswith("#") else None
            if j in gains and key in gains[j]:
                line = f"{key} = {gains[j][key]!r}"
        lines.append(line)
    dst.write_text("\n".join(lines) + "\n")


def measure(m, work: Path, tag: str, ballbar: Path, ini: Path, result: Path) -> dict[str, float]:
    """Run ballbar and part on the machine; circularity (larger of ccw, cw), part max |contour error|, µm."""
    capture(m, [ballbar], work / f"ballbar-{tag}.mcap")
    agent("ballbar", "--machine", result, "--ini", ini, "--radius", RADIUS, "--feed", FEED, "--lead-deg", LEAD,
          "--against", work / f"ballbar-{tag}.mcap", "--json", work / f"bb-{tag}.json")
    runs = json.loads((work / f"bb-{tag}.json").read_text())["tests"][0]["measured"]["runs"]
    capture(m, [PART], work / f"part-{tag}.mcap")
    agent("predict", PART, "--machine", result, "--ini", ini, "--against", work / f"part-{tag}.mcap",
          "--json", work / f"part-{tag}.json")
    c = json.loads((work / f"part-{tag}.json").read_text())["comparisons"][0]
    return {"circularity_um": max(r["circularity_um"] for r in runs),
            "runs": {r["direction"]: r["circularity_um"] for r in runs},
            "contour_error_max_um": c["measured_max_abs_mm"] * 1e3}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, help="keep the recordings, JSONs and INIs here (default: a new temporary directory)")
    a = ap.parse_args()
    why = lm.missing()
    if why:
        print(why)
        return 1
    work = a.work or Path(tempfile.mkdtemp(prefix="bench-linuxcnc-tuning-"))
    work.mkdir(parents=True, exist_ok=True)
    poor_ini = work / "poor.ini"
    with_gains(lm.HERE / "machine.ini", poor_ini, POOR)
    agent("generate", "--axes", "X,Y", "--dialect", "linuxcnc", "--seed", 1, "--n-high", 30, "-o", work / "ident")
    with lm.Machine(axes="XY", ini=poor_ini) as m:
        ini = m.run_dir / "machine.ini"
        capture(m, [work / "ident/ident_low.ngc", work / "ident/ident_high.ngc"], work / "ident.mcap")
        agent("identify", work / "ident.mcap", "--no-diagnose", "--json", work / "result.json")
        (work / "running.ini").write_text(ini.read_text())  # the INI LinuxCNC runs (with the poor gains)
        agent("ballbar", "--machine", work / "result.json", "--ini", ini, "--radius", RADIUS, "--feed", FEED,
              "--lead-deg", LEAD, "--program-out", work / "ballbar.ngc")
        before = measure(m, work, "poor", work / "ballbar.ngc", ini, work / "result.json")
        tuned = agent("tune", "--machine", work / "result.json", "--ballbar", "--radius", RADIUS, "--feed", FEED,
                      "--lead-deg", LEAD, "--ini", ini, "--plant-integration", "euler", "--json", work / "tune.json")
        doc = json.loads((work / "tune.json").read_text())
        propose = [f"{a}.{k}={v!r}" for a, g in doc["gains"].items() for k, v in g["after"].items()]
        agent("tune", "--machine", work / "result.json", "--program", PART, "--ini", ini, "--plant-integration",
              "euler", *[x for p in propose for x in ("--propose", p)], "--json", work / "tune-part.json")
        part_doc = json.loads((work / "tune-part.json").read_text())
        tuned_ini = work / "tuned.ini"
        tuned_ini.write_text(ini.read_text())
        (work / "tune.diff").write_text("\n".join(doc["ini_diff"]) + "\n")
        subprocess.run(["patch", "--quiet", str(tuned_ini), str(work / "tune.diff")], check=True)
    with lm.Machine(axes="XY", ini=tuned_ini) as m:
        after = measure(m, work, "tuned", work / "ballbar.ngc", m.run_dir / "machine.ini", work / "result.json")

    print(f"LinuxCNC two-axis machine, poor gains {POOR}; ballbar R {RADIUS:g} mm at {FEED * 60:.0f} mm/min, "
          f"part {PART.name}\n")
    print(tuned.split("--- a/")[0].rstrip())
    print("\n".join(doc["ini_diff"]))
    print("\nplant recovered (true: X K/J 1000, B/J 2.5, Coulomb ±0.4 V; Y K/J 1250, B/J 3.125, Coulomb ±0.3 V):")
    for a, p in doc["plant"].items():
        print(f"  {a}: K/J {p['kj']:.1f}, B/J {p['bj']:.2f}, Coulomb {p['d_plus']:+.3f}/{p['d_minus']:+.3f} V")
    rows = [("ballbar circularity (larger of ccw, cw)", "circularity_um", doc),
            ("part max contour error", "contour_error_max_um", part_doc)]
    print(f"\n{'':40s} {'measured poor':>13s} {'tuned':>8s} {'drop':>6s} | {'predicted poor':>14s} {'tuned':>8s}"
          f" | tuned meas./pred.")
    ok = True
    for name, key, d in rows:
        mb, ma = before[key], after[key]
        pb, pa = d["predicted_before"][key], d["predicted_after"][key]
        drop, ratio = 1 - ma / mb, ma / pa
        ok &= drop >= 0.30 and abs(ratio - 1) <= 0.10
        print(f"{name:40s} {mb:11.2f}µm {ma:6.2f}µm {drop * 100:5.1f}% | {pb:12.2f}µm {pa:6.2f}µm | {ratio:.3f}")
    print(f"  ballbar per direction, measured: poor {before['runs']}, tuned {after['runs']}")
    print(f"\nno following-error trip (every program ran to its end); drop >= 30 % and tuned within 10 % of the "
          f"prediction: {ok}   (recordings in {work})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""One of LinuxCNC's own sample programs predicted as the three-axis LinuxCNC runs it (issue 41).

The sample is /usr/share/linuxcnc/ncfiles/gmoccapy_2_tools_with_cutter_radius_compensation.ngc,
as shipped: what a CAM post or a shop writes — a header of modal codes (G17 G21 G54 G61 G40
G49 G80 G90), two tool changes (T3 M6, T1 M6) with tool length offsets (G43 from the tool
table), cutter radius compensation (G41), helical feed-in and feed-out arcs (G3 with Z),
a full circle at 2000 and one at 1000 mm/min, Z moves, spindle, coolant, M1 and a message.
It moves Z, so it runs on the fixture machine with X, Y and Z (`machine.py start --axes
XYZ`: Z has X's plant and gains); it is in exact stop (G61), which the planner models as
LinuxCNC plans it, and it needs no remap or subroutine file.

The machine is identified from its own capture (agent capture over linuxcnc://, the
identification programs on X, Y and Z, `agent identify --no-diagnose`: the machine is
clean), then the sample is run on LinuxCNC while captured and predicted stand-alone by
`agent predict SAMPLE --machine result.json --ini machine.ini --tool-table tool.tbl
--against RECORDING` (the fixture's tool table: T1 Ø3 mm 12 mm long, T3 Ø6 mm 30 mm long).
Targets: max contour error within 5 %, rms of the difference <= 10 % of the measured rms,
cycle time within 1 %.  One run; LinuxCNC runs in real time.

Run (where LinuxCNC is installed; about 2 minutes):  python benchmarks/bench_linuxcnc_sample.py
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

from bench_linuxcnc_contour import agent, capture, lm  # benchmarks/ is on sys.path

SAMPLE = Path("/usr/share/linuxcnc/ncfiles/gmoccapy_2_tools_with_cutter_radius_compensation.ngc")
PORT = "linuxcnc://?joints=0,1,2&axes=X,Y,Z"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, help="keep the recordings and JSONs here (default: a new temporary directory)")
    a = ap.parse_args()
    why = lm.missing() or (None if SAMPLE.is_file() else f"{SAMPLE} is missing (LinuxCNC's sample programs)")
    if why:
        print(why)
        return 1
    work = a.work or Path(tempfile.mkdtemp(prefix="bench-linuxcnc-sample-"))
    work.mkdir(parents=True, exist_ok=True)
    agent("generate", "--axes", "X,Y,Z", "--dialect", "linuxcnc", "--seed", 1, "--n-high", 30, "-o", work / "ident")
    with lm.Machine(axes="XYZ") as m:
        capture(m, [work / "ident/ident_low.ngc", work / "ident/ident_high.ngc"], work / "ident.mcap", PORT)
        agent("identify", work / "ident.mcap", "--no-diagnose", "--json", work / "result.json")
        ini, tools = work / "machine.ini", work / "tool.tbl"
        shutil.copy(m.run_dir / "machine.ini", ini)
        shutil.copy(m.run_dir / "tool.tbl", tools)
        capture(m, [SAMPLE], work / "sample.mcap", PORT)
    out = agent("predict", SAMPLE, "--machine", work / "result.json", "--ini", ini, "--tool-table", tools,
                "--against", work / "sample.mcap", "--json", work / "p.json")
    c = json.loads((work / "p.json").read_text())["comparisons"][0]
    s = c["standalone"]
    mm, pm = c["measured_max_abs_mm"] * 1e3, s["predicted_max_abs_mm"] * 1e3
    cm, cp = c["measured_cycle_time_s"], c["predicted_cycle_time_s"]
    print(f"{SAMPLE.name} on the X, Y, Z LinuxCNC (identified from {work / 'ident.mcap'})")
    print("\n".join("  " + ln for ln in out.splitlines() if "planner" in ln or "limits" in ln))
    print(f"\nmax |contour error|: measured {mm:.2f} µm, stand-alone predicted {pm:.2f} µm ({(pm / mm - 1) * 100:+.1f} %)")
    print(f"rms of the difference: {s['rms_difference_ratio'] * 100:.1f} % of the measured rms "
          f"(driven by the recorded command: {c['rms_difference_ratio'] * 100:.1f} %)")
    print(f"cycle time: measured {cm:.3f} s, predicted {cp:.3f} s ({(cp / cm - 1) * 100:+.2f} %)")
    ok = abs(pm / mm - 1) <= 0.05 and s["rms_difference_ratio"] <= 0.10 and abs(cp / cm - 1) <= 0.01
    print(f"\nwithin max 5 %, rms 10 %, cycle 1 %: {ok}   (recordings in {work})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

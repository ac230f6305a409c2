"""The diagnosis on a labelled drive zoo (default ../shared/data/drive-zoo-dev: 21 recording pairs from an independent simulator).

A DEVELOPMENT figure: these recordings are what the diagnosis was examined on (issue 13);
the figures that measure how it generalises come from benchmarks/bench_independent.py's
report seeds.  Per case: the verdict, the truth, the main parameter against the label,
the base and augmented held-out fits, and the wall time of ``ident.identify``.

    python benchmarks/bench_drive_zoo.py [--jobs 2] [--zoo DIR] [--cases case_001,case_004] [--config JSON]
        [--jsonl FILE]

``--zoo ../shared/data/drive-zoo-dev2`` runs the second development set (28 cases);
``--jsonl`` writes one row per case with every candidate's parameters and score.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ZOO = ROOT.parent / "shared" / "data" / "drive-zoo-dev"
sys.path.insert(0, str(ROOT))
from benchmarks.diagnosis_config_arg import CONFIG_HELP  # noqa: E402

MAIN_PARAM = {"backlash": "gap_mm", "resonance": "freq_hz", "time_delay": "delay_s", "cyclic_error": "period_mm"}


def run_case(case: dict, config: str = "{}", zoo: str = str(ZOO)) -> dict:
    import ident
    from benchmarks.diagnosis_config_arg import diagnosis_config

    root = Path(zoo)
    t0 = time.perf_counter()
    res = ident.identify(ident.load(root / case["recording"]), validate=ident.load(root / case["validation"]),
                         diagnosis_config=diagnosis_config(config))
    r = res.axes["X"]
    d = r.diagnosis
    verdict = d.verdict if isinstance(d.verdict, str) else "+".join(d.verdict)
    out = {"case": case["case"], "truth": case["effect"], "verdict": verdict, "wall_s": time.perf_counter() - t0,
           "fit_before": d.fit_before_pct, "fit_after": d.fit_after_pct,
           "validation_fit": r.fit_validation.tracking_error_fit_pct if r.fit_validation else float("nan"),
           "candidates": [c.to_dict() for c in d.candidates]}
    key = MAIN_PARAM.get(case["effect"])
    if key and case.get("parameters", {}).get(key):
        fitted = next((c.parameters.get(key) for c in d.candidates if c.effect == case["effect"] and c.accepted), None)
        if fitted is not None:
            out["param_error_pct"] = 100.0 * (fitted / case["parameters"][key] - 1.0)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--cases", default="")
    ap.add_argument("--config", default="{}", help=CONFIG_HELP)
    ap.add_argument("--zoo", default=str(ZOO), help="folder with labels.json and the cases (default: %(default)s)")
    ap.add_argument("--jsonl", default=None, help="write one JSON row per case (candidates included) to this file")
    args = ap.parse_args()
    zoo = Path(args.zoo)
    if not (zoo / "labels.json").exists():
        sys.exit(f"error: {zoo / 'labels.json'} not found")
    cases = json.loads((zoo / "labels.json").read_text())["cases"]
    if args.cases:
        wanted = set(args.cases.split(","))
        cases = [c for c in cases if c["case"] in wanted]
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(run_case, cases, [args.config] * len(cases), [str(zoo)] * len(cases)))
    if args.jsonl:
        with open(args.jsonl, "w") as fh:
            for r in rows:
                fh.write(json.dumps(r) + "\n")
    hits = 0
    false_alarms = 0
    for r in rows:
        ok = r["verdict"] == r["truth"]
        hits += ok
        false_alarms += r["truth"] == "none" and r["verdict"] != "none"
        perr = f"  param {r['param_error_pct']:+.0f} %" if "param_error_pct" in r else ""
        print(f"{r['case']}  {r['truth']:13s} -> {r['verdict']:13s} {'ok ' if ok else 'MISS'}  "
              f"held-out fit {r['fit_before']:6.2f} -> {r['fit_after']:6.2f} %  {r['wall_s']:5.1f} s{perr}")
    walls = sorted(r["wall_s"] for r in rows)
    print(f"named right {hits}/{len(rows)}, false alarms on clean cases {false_alarms}/"
          f"{sum(r['truth'] == 'none' for r in rows)}, identify+diagnose wall median {walls[len(walls) // 2]:.1f} s, "
          f"max {walls[-1]:.1f} s")


if __name__ == "__main__":
    main()

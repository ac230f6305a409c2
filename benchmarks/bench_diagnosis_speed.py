"""Identify + diagnose time with an effect present: a ~23 s recording validated on a ~13 s one (issue 39 item 6).

Cases: the effect cases of ``../shared/data/drive-zoo-dev2`` (an independent simulator's
drives, 22.8 s identification and 13.3 s validation recordings at 1 kHz), by default one of
each class.  Per case ``ident.identify(rec, validate=val)`` in-process after one warm-up
(numba's on-disk cache loaded, imports done): wall time, CPU time of the process
(``time.process_time``: steadier than wall time on a loaded machine; the diagnosis runs
two worker threads, so CPU can exceed wall) and where the CPU goes — identification stages
(wall, from ``AxisResult.timings``) and, inside the diagnosis, the CPU of each stage's
threads: base re-fits, the base's controller variants, the equivalent-disturbance
analysis, each effect's search, the pairs' searches, the reference re-fits and the
re-estimation with a variance per segment.  The stages are timed by wrapping the
diagnosis's functions for the run (``time.thread_time`` in the thread that does the work);
nothing else is changed.  ``--json OUT`` writes the verdicts, the accepted parameters and
the diagnosis JSON of every case (to compare results before and after a change).

    python benchmarks/bench_diagnosis_speed.py [--cases case_000,case_001] [--data DIR] [--json OUT]
        [--config JSON] [--compare JSON]

``--config``: tunables changed for the run (as bench_drive_zoo.py's); ``--compare``: every
case is run a second time, right after, with these tunables instead, and the ratio of the
medians (compare / config) printed: the two measured in one run, under the same load.

``--data``: another labelled set of the same layout (``labels.json``), e.g. drive-zoo-dev.
"""

from __future__ import annotations

import argparse
import functools
import json
import statistics
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ZOO = ROOT.parent / "shared" / "data" / "drive-zoo-dev2"
sys.path.insert(0, str(ROOT))
from benchmarks.diagnosis_config_arg import CONFIG_HELP  # noqa: E402

#: One effect case of each class (the first of each in labels.json).
DEFAULT_CASES = ("case_000", "case_001", "case_002", "case_003", "case_004", "case_006")


class StageClock:
    """CPU seconds per diagnosis stage, summed over the threads that do the work."""

    def __init__(self) -> None:
        self.cpu: dict[str, float] = defaultdict(float)
        self._lock = threading.Lock()
        self._local = threading.local()
        self._undo: list = []

    def wrap(self, module, name: str, label) -> None:
        """Time every call of ``module.name`` under ``label`` (a string or a function of the call's arguments)."""
        fn = getattr(module, name)

        @functools.wraps(fn)
        def timed(*args, **kwargs):
            if getattr(self._local, "inside", False):  # nested in a timed stage: counted there
                return fn(*args, **kwargs)
            self._local.inside = True
            t0 = time.thread_time()
            try:
                return fn(*args, **kwargs)
            finally:
                self._local.inside = False
                with self._lock:
                    self.cpu[label if isinstance(label, str) else label(*args, **kwargs)] += time.thread_time() - t0

        setattr(module, name, timed)
        self._undo.append((module, name, fn))

    def restore(self) -> None:
        for module, name, fn in reversed(self._undo):
            setattr(module, name, fn)
        self._undo.clear()


def _search_label(base, effect, *args, **kwargs) -> str:
    return f"pair +{effect}" if base.effects else f"search {effect}"


def instrument() -> StageClock:
    import importlib

    candidates = importlib.import_module("ident.diagnosis.candidates")
    diagnose = importlib.import_module("ident.diagnosis.diagnose")  # the module, not the function
    clock = StageClock()
    clock.wrap(diagnose, "refit_base", "base re-fits")
    clock.wrap(candidates, "sampled_base", "base controller variants")
    clock.wrap(diagnose, "_disturbance", "disturbance analysis")
    clock.wrap(diagnose, "localise", "localisation")
    clock.wrap(diagnose, "search", _search_label)
    clock.wrap(diagnose, "fit_spec", "reference and final re-fits")
    clock.wrap(diagnose, "segment_variance_fit", "re-estimation")
    least_squares = importlib.import_module("ident.least_squares")
    if hasattr(least_squares, "_help"):  # Jacobian columns taken by helper threads, whatever stage they serve
        clock.wrap(least_squares, "_help", "Jacobian helper threads (any stage)")
    return clock


def run_case(case: dict, data: Path = ZOO, config: str = "{}") -> dict:
    import ident
    from benchmarks.diagnosis_config_arg import diagnosis_config
    from ident.model import BASE_KEYS

    rec = ident.load(data / case["recording"])
    val = ident.load(data / case["validation"])
    clock = instrument()
    try:
        c0, t0 = time.process_time(), time.perf_counter()
        res = ident.identify(rec, validate=val, diagnosis_config=diagnosis_config(config))
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    finally:
        clock.restore()
    r = res.axes["X"]
    d = r.diagnosis
    verdict = d.verdict if isinstance(d.verdict, str) else "+".join(d.verdict)
    return {"case": case["case"], "truth": case["effect"], "verdict": verdict, "wall_s": wall, "cpu_s": cpu,
            "identify_wall_s": {k: v for k, v in r.timings.items() if k != "diagnosis"},
            "diagnosis_wall_s": r.timings.get("diagnosis", float("nan")),
            "diagnosis_cpu_s": dict(clock.cpu),
            "accepted": {c.effect: c.parameters for c in d.candidates if c.accepted},
            "model": {k: float(getattr(r.model, k)) for k in BASE_KEYS},
            "diagnosis": d.to_dict()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(DEFAULT_CASES))
    ap.add_argument("--data", default=str(ZOO), help="a labelled set of recordings (default drive-zoo-dev2)")
    ap.add_argument("--json", default="", help="write every case's verdict, parameters and diagnosis here")
    ap.add_argument("--config", default="{}", help=CONFIG_HELP)
    ap.add_argument("--compare", default="", help="run every case again with these tunables (JSON) and print the ratio")
    args = ap.parse_args()
    data = Path(args.data)
    if not (data / "labels.json").exists():
        sys.exit(f"error: {data / 'labels.json'} not found")
    import ident

    wanted = args.cases.split(",")
    cases = {c["case"]: c for c in json.loads((data / "labels.json").read_text())["cases"]}
    missing = [w for w in wanted if w not in cases]
    if missing:
        sys.exit(f"error: no case {missing[0]} in {data / 'labels.json'}")
    first = cases[wanted[0]]
    # warm-up, untimed: imports and numba's cached machine code, for the diagnosis too
    ident.identify(ident.load(data / first["recording"]), validate=ident.load(data / first["validation"]))
    rows, other = [], []

    def show(row: dict) -> None:
        idf = ", ".join(f"{k} {v:.2f}" for k, v in row["identify_wall_s"].items())
        print(f"{row['case']}  {row['truth']:13s} -> {row['verdict']:24s} wall {row['wall_s']:5.2f} s  "
              f"cpu {row['cpu_s']:5.2f} s  (identify, wall: {idf}; diagnosis wall {row['diagnosis_wall_s']:.2f})")
        stages = sorted(row["diagnosis_cpu_s"].items(), key=lambda kv: -kv[1])
        print("    diagnosis cpu: " + ", ".join(f"{k} {v:.2f}" for k, v in stages)
              + f"; sum {sum(row['diagnosis_cpu_s'].values()):.2f} s", flush=True)

    for w in wanted:
        rows.append(run_case(cases[w], data, args.config))
        show(rows[-1])
        if args.compare:
            other.append(run_case(cases[w], data, args.compare))
            print(f"  with {args.compare}:")
            show(other[-1])
    print(f"median over {len(rows)} effect cases: wall {statistics.median(r['wall_s'] for r in rows):.2f} s, "
          f"cpu {statistics.median(r['cpu_s'] for r in rows):.2f} s "
          f"(max wall {max(r['wall_s'] for r in rows):.2f} s)")
    if other:
        med = {k: [statistics.median(r[k] for r in rs) for rs in (rows, other)] for k in ("wall_s", "cpu_s")}
        print(f"with {args.compare}: median wall {med['wall_s'][1]:.2f} s, cpu {med['cpu_s'][1]:.2f} s; ratio "
              f"wall {med['wall_s'][1] / med['wall_s'][0]:.2f}, cpu {med['cpu_s'][1] / med['cpu_s'][0]:.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=float))


if __name__ == "__main__":
    main()

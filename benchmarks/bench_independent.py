#!/usr/bin/env python
"""The diagnosis on an independent feed-drive simulator (benchmarks/independent_bench).

The simulator is written from the physics, not from ``virtual_cnc`` or ``ident.diagnosis``
(see benchmarks/independent_bench/__init__.py): rigid or two-mass plant, a gap with contact
stiffness, asymmetric Stribeck friction with Karnopp stick, cogging, P-PI / PID drives at
1 kHz with feed-forward, integral without anti-windup and a force limit, dead time,
quantised/noisy encoder or scale, pitch error.  Each case is one class of SPEC §7 (six
effects and ``none``) on a random drive; ``benchmarks/independent_bench/cases.py`` documents
the ranges.

Seed split, fixed before any tuning: the ranges in cases.py were chosen on TUNING_SEEDS
(``--tuning``); the figures are reported on REPORT_SEEDS (the default).  Case ``i`` of a
seed set has class ``CLASSES[i % 7]``; its ``j = i // 7``-th member of that class is
semi-closed for even ``j`` and full-closed for odd ``j``, P-PI for ``j % 4 < 2`` and PID
otherwise, so every class has both closures and both controller kinds.

Calibration: a case is kept only when the plain model still fits it -- the held-out
tracking-error fit of ``ident.identify(rec, validate=val, diagnose=False)`` lies in
FIT_WINDOW (60-95 %) for an effect, >= 60 % for ``none``.  Otherwise the case is drawn
again from the next sub-seed (``draw_case(cls, seed, sub + 1)``), at most MAX_TRIES times;
everything is deterministic from the case seed.  A case that never lands in the window is
reported as NOT CALIBRATED and left out of the scores (P-PI drives, whose velocity loop on
the motor damps a two-mass mode and whose integrator runs away past a force limit, are
where that happens: resonance and saturation).

History of the protocol (cases.py notes the ranges): the first report run (16 draws)
calibrated no saturation case and no full-closed P-PI resonance case; the saturation limit
(now relative to the sustained force of the fastest moves) and the full-closed resonance
tuning cap were revised on the tuning seeds, MAX_TRIES raised to 40, and the report seeds
run again.  Later the time_delay class's P-PI tuning rule was found to leave the
drives unstable (in a limit cycle at the force limit half the time: not a dead time) and
replaced by a 30° phase margin (version 2, cases.py); report figures from before that are
on version 1.  MAX_TRIES then went from 40 to 100: two report cases (s5033 saturation,
s5059 time delay) had not calibrated in 40 draws, so the report set had 68 cases, not the
70 the issue asks for; they land in the window at draws 42 and 65.  The calibration runs
no diagnosis, and a case calibrated within 40 draws is the same case (the first sub-seed
in the window), so no figure moves except by the two cases added.

Per case: truth, verdict, main parameter vs truth, base fit (identification),
held-out fit before/after the diagnosis, wall time of ``ident.identify``.  Then accuracy
overall and per class, false positives on ``none``, the share of main parameters within
±25 % on the hits, the median diagnosis time.

``--perturb EPS`` scales the recorded positions by 1 + EPS before the diagnosis (the cached
CSVs keep the unperturbed ones): the verdicts that change under EPS = 1e-12 (0.1 nm at
100 mm) are the bench's rounding noise, the band a change of the code at the last digit
moves the figures in (once measured: 7 of 69 report-seed verdicts).  ``--via-csv`` diagnoses
the recordings as a user's files carry them instead: written as SPEC §4 CSV and read back
(the command then differs by up to about 5e-10 mm, the writer's ten significant digits).

    python benchmarks/bench_independent.py [--tuning] [--jobs 1] [--cases s5003,s5010]
        [--classes backlash,none] [--cache DIR] [--jsonl FILE] [--summarize FILE]
        [--perturb EPS] [--via-csv]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.independent_bench.cases import CLASSES, case_recordings, draw_case  # noqa: E402
from benchmarks.diagnosis_config_arg import CONFIG_HELP  # noqa: E402

#: fixed before any tuning of the ranges: tune on the first, report on the second
TUNING_SEEDS = range(1000, 1070)
REPORT_SEEDS = range(5000, 5070)
FIT_WINDOW = (60.0, 95.0)
MAX_TRIES = 100
MAIN_PARAM = {"backlash": "gap_mm", "resonance": "freq_hz", "time_delay": "delay_s", "cyclic_error": "period_mm"}


def case_spec(seed: int, seeds: range) -> dict:
    """Class, closure and controller kind of case ``seed`` of the seed set ``seeds``."""
    i = seed - seeds.start
    j = i // len(CLASSES)
    return {"seed": seed, "cls": CLASSES[i % len(CLASSES)], "closure": "semi" if j % 2 == 0 else "full",
            "kind": "ppi" if j % 4 < 2 else "pid"}


def in_window(cls: str, fit: float) -> bool:
    lo, hi = FIT_WINDOW
    return fit == fit and (fit >= lo if cls == "none" else lo <= fit <= hi)


def base_fit(rec, val) -> float:
    import ident

    r = ident.identify(rec, validate=val, diagnose=False).axes["X"]
    return float(r.fit_validation.tracking_error_fit_pct)


def calibrate(spec: dict, max_tries: int = MAX_TRIES):
    """The first sub-seed whose case the plain model fits within the window.

    Returns ``(case, rec, val, base_fit_pct, tries)``; ``case`` is None when no sub-seed of
    ``max_tries`` qualified (``base_fit_pct`` then lists the fits seen).
    """
    fits = []
    for sub in range(max_tries):
        case = draw_case(spec["cls"], spec["seed"], sub, spec["closure"], spec["kind"])
        rec, val = case_recordings(case)
        try:
            fit = base_fit(rec, val)
        except Exception as exc:  # an unidentifiable (e.g. unstable) drive: redraw
            fit = float("nan")
            print(f"  s{spec['seed']}.{sub}: identify failed ({type(exc).__name__}: {exc})", file=sys.stderr)
        fits.append(round(fit, 1))
        if in_window(spec["cls"], fit):
            return case, rec, val, fit, sub + 1
    return None, None, None, fits, max_tries


def run_case(spec: dict, cache: str | None = None, config: str = "{}", perturb: float = 0.0,
             via_csv: bool = False) -> dict:
    import ident
    from benchmarks.diagnosis_config_arg import diagnosis_config

    t_cal = time.perf_counter()
    case, rec, val, fit0, tries = calibrate(spec)
    out = {"case": f"s{spec['seed']}", "truth": spec["cls"], "closure": spec["closure"], "kind": spec["kind"],
           "tries": tries, "calibrate_s": time.perf_counter() - t_cal}
    if case is None:
        out["uncalibrated"] = fit0
        return out
    out["case"] = case.name
    out["truth_parameters"] = {k: v for k, v in case.truth.items()}
    out["base_fit_validation"] = fit0
    if cache:
        from core.writer import write_recording_csv

        d = Path(cache)
        d.mkdir(parents=True, exist_ok=True)
        write_recording_csv(rec, d / f"{case.name}_identification.csv")
        write_recording_csv(val, d / f"{case.name}_validation.csv")
        (d / f"{case.name}.json").write_text(json.dumps({k: out[k] for k in ("case", "truth", "closure", "kind",
                                                                               "truth_parameters")}, indent=1))
    if perturb:  # rounding-level change of the recorded positions (the bench's noise band)
        for tr in list(rec.axes.values()) + list(val.axes.values()):
            tr.actual[:] = tr.actual * (1.0 + perturb)
        out["perturb"] = perturb
    if via_csv:  # the recordings as a user's CSV files carry them
        import tempfile

        from core.writer import write_recording_csv

        with tempfile.TemporaryDirectory() as tmp:
            rec = ident.load(write_recording_csv(rec, Path(tmp) / "identification.csv"))
            val = ident.load(write_recording_csv(val, Path(tmp) / "validation.csv"))
        out["via_csv"] = True
    t0 = time.perf_counter()
    res = ident.identify(rec, validate=val, diagnosis_config=diagnosis_config(config))
    out["wall_s"] = time.perf_counter() - t0
    r = res.axes["X"]
    d = r.diagnosis
    out["verdict"] = d.verdict if isinstance(d.verdict, str) else "+".join(d.verdict)
    out["diagnosis_s"] = d.elapsed_s
    out["fit_identification"] = r.fit_identification.tracking_error_fit_pct
    out["fit_before"], out["fit_after"] = d.fit_before_pct, d.fit_after_pct
    out["candidates"] = [c.to_dict() for c in d.candidates]  # every candidate's parameters and score (--jsonl)
    key = MAIN_PARAM.get(spec["cls"])
    if key and key in case.truth:
        fitted = next((c.parameters.get(key) for c in d.candidates if c.effect == spec["cls"] and c.accepted), None)
        out["param_key"] = key
        out["param_truth"] = case.truth[key]
        if fitted is not None:
            out["param_fit"] = float(fitted)
            out["param_error_pct"] = 100.0 * (float(fitted) / case.truth[key] - 1.0)
    return out


def closed_loop_reference(r: dict) -> None:
    """For a resonance row: add the closed-loop mode frequency (what a recording shows) as a second truth.

    The drawn ``freq_hz`` is the plant's free two-mass mode; the loop moves the mode seen in a
    recording (towards ``sqrt(k / m_t)`` when the velocity loop holds the motor), see
    independent_bench/linear.py.  Recomputed from the case name (deterministic).
    """
    if r.get("truth") != "resonance" or "verdict" not in r or "param_truth_closed_loop" in r:
        return
    from benchmarks.independent_bench.linear import closed_loop_mode

    seed, sub = (int(v) for v in r["case"][1:].split("."))
    case = draw_case("resonance", seed, sub, r["closure"], r["kind"])
    f_cl, z_cl = closed_loop_mode(case.drive)
    r["param_truth_closed_loop"] = f_cl
    r["damping_closed_loop"] = z_cl
    if "param_fit" in r:
        r["param_error_closed_loop_pct"] = 100.0 * (r["param_fit"] / f_cl - 1.0)


def format_row(r: dict) -> str:
    head = f"{r['case']:9s} {r['truth']:12s} {r['closure']:4s} {r['kind']:3s}"
    if "uncalibrated" in r:
        return f"{head} NOT CALIBRATED after {r['tries']} draws (held-out base fits {r['uncalibrated']})"
    ok = r["verdict"] == r["truth"]
    par = ""
    if "param_key" in r:
        par = f"  {r['param_key']} truth {r['param_truth']:.4g}"
        par += f" fit {r['param_fit']:.4g} ({r['param_error_pct']:+.0f} %)" if "param_fit" in r else " fit -"
        if "param_truth_closed_loop" in r:
            par += f"; closed-loop mode {r['param_truth_closed_loop']:.4g} Hz (zeta {r['damping_closed_loop']:.2f})"
            if "param_error_closed_loop_pct" in r:
                par += f" ({r['param_error_closed_loop_pct']:+.0f} %)"
    return (f"{head} -> {r['verdict']:22s} {'ok  ' if ok else 'MISS'} base fit id {r['fit_identification']:5.1f} % "
            f"held-out {r['base_fit_validation']:5.1f} %; diagnosis held-out {r['fit_before']:6.2f} -> "
            f"{r['fit_after']:6.2f} %  draw {r['tries']:2d}  {r['wall_s']:5.1f} s{par}")


def summarize(rows: list[dict]) -> None:
    for r in rows:
        closed_loop_reference(r)
    done = [r for r in rows if "verdict" in r]
    uncal = [r for r in rows if "uncalibrated" in r]
    print(f"\n{len(rows)} cases run, {len(done)} calibrated and diagnosed, {len(uncal)} not calibrated")
    if not done:
        return
    hits = [r for r in done if r["verdict"] == r["truth"]]
    named = [r for r in done if r["truth"] in r["verdict"].split("+")]
    print(f"accuracy {len(hits)}/{len(done)} = {100.0 * len(hits) / len(done):.0f} % (verdict exactly the truth); "
          f"truth named alone or in a list {len(named)}/{len(done)}")
    for cls in CLASSES:
        rs = [r for r in done if r["truth"] == cls]
        if not rs:
            continue
        h = sum(r["verdict"] == cls for r in rs)
        in_list = sum(cls in r["verdict"].split("+") for r in rs)
        closures = f"semi {sum(r['closure'] == 'semi' for r in rs)}/full {sum(r['closure'] == 'full' for r in rs)}, " \
                   f"ppi {sum(r['kind'] == 'ppi' for r in rs)}/pid {sum(r['kind'] == 'pid' for r in rs)}"
        verdicts = {}
        for r in rs:
            verdicts[r["verdict"]] = verdicts.get(r["verdict"], 0) + 1
        print(f"  {cls:12s} {h:2d}/{len(rs):2d} (in list {in_list:2d})  [{closures}]  "
              f"verdicts {dict(sorted(verdicts.items(), key=lambda kv: -kv[1]))}")
    none = [r for r in done if r["truth"] == "none"]
    fp = [r for r in none if r["verdict"] != "none"]
    said_none = [r for r in done if r["truth"] != "none" and r["verdict"] == "none"]
    print(f"false positives on none {len(fp)}/{len(none)}; effects called none {len(said_none)}/"
          f"{len(done) - len(none)}")
    par = [r for r in hits if "param_key" in r]
    within = [r for r in par if "param_error_pct" in r and abs(r["param_error_pct"]) <= 25.0]
    if par:
        print(f"main parameter within ±25 % on the hits: {len(within)}/{len(par)}")
        for key in sorted({r["param_key"] for r in par}):
            errs = [f"{r['param_error_pct']:+.0f}" for r in par if r["param_key"] == key and "param_error_pct" in r]
            print(f"  {key:10s} errors % {', '.join(errs)}")
        res = [r for r in par if "param_error_closed_loop_pct" in r]
        if res:
            ok = sum(abs(r["param_error_closed_loop_pct"]) <= 25.0 for r in res)
            errs = ", ".join(f"{r['param_error_closed_loop_pct']:+.0f}" for r in res)
            print(f"  freq_hz against the closed-loop mode instead of the plant's free mode: within ±25 % "
                  f"{ok}/{len(res)}, errors % {errs}")
    diag = sorted(r["diagnosis_s"] for r in done)
    wall = sorted(r["wall_s"] for r in done)
    before = statistics.median(r["fit_before"] for r in done)
    after = statistics.median(r["fit_after"] for r in done)
    print(f"diagnosis time median {statistics.median(diag):.1f} s (max {diag[-1]:.1f} s); identify+diagnose wall "
          f"median {statistics.median(wall):.1f} s; held-out fit median {before:.1f} -> {after:.1f} %")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tuning", action="store_true", help="run the tuning seeds instead of the report seeds")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--cases", default="", help="comma-separated case names, e.g. s5003,s5010")
    ap.add_argument("--classes", default="", help="comma-separated classes")
    ap.add_argument("--cache", default=None, help="directory to store the generated recordings (CSV)")
    ap.add_argument("--jsonl", default=None, help="append one JSON row per finished case to this file")
    ap.add_argument("--config", default="{}", help=CONFIG_HELP)
    ap.add_argument("--summarize", default=None, help="only print the summary of a --jsonl file")
    ap.add_argument("--perturb", type=float, default=0.0,
                    help="scale the recorded positions by 1 + this before the diagnosis (noise band)")
    ap.add_argument("--via-csv", action="store_true",
                    help="diagnose the recordings written to CSV and read back, as a user's files carry them")
    args = ap.parse_args()
    if args.summarize:
        rows = [json.loads(line) for line in Path(args.summarize).read_text().splitlines() if line.strip()]
        rows.sort(key=lambda r: r["case"])
        for r in rows:
            closed_loop_reference(r)
            print(format_row(r))
        summarize(rows)
        return
    seeds = TUNING_SEEDS if args.tuning else REPORT_SEEDS
    specs = [case_spec(s, seeds) for s in seeds]
    if args.classes:
        wanted = set(args.classes.split(","))
        specs = [s for s in specs if s["cls"] in wanted]
    if args.cases:
        wanted = {c.split(".")[0] for c in args.cases.split(",")}
        specs = [s for s in specs if f"s{s['seed']}" in wanted]
    print(f"{'tuning' if args.tuning else 'report'} seeds, {len(specs)} cases, jobs {args.jobs}", flush=True)
    rows = []
    with ProcessPoolExecutor(args.jobs) as pool:
        futures = [pool.submit(run_case, s, args.cache, args.config, args.perturb, args.via_csv) for s in specs]
        for fut in as_completed(futures):
            r = fut.result()
            closed_loop_reference(r)
            rows.append(r)
            print(format_row(r), flush=True)
            if args.jsonl:
                with open(args.jsonl, "a") as fh:
                    fh.write(json.dumps(r) + "\n")
    rows.sort(key=lambda r: r["case"])
    summarize(rows)


if __name__ == "__main__":
    main()

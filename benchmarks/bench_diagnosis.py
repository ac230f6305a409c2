#!/usr/bin/env python
"""Benchmark of the mismatch diagnosis (issue 5, item 6) on the virtual CNC.

A battery of cases, ``--cases-per-class`` (default 10) for each of the seven classes of
SPEC §7 (six effects and ``none``), with program seeds the tests do not use (10 000 +),
a random controller preset (fadal-ppi / fadal-pid / fadal-smc) and a random magnitude in
a realistic range per effect.  Each case: identification and validation recordings from
``virtual_cnc.machine_run.simulate`` of ``gcode_gen.excitation`` programs, the base
model identified as ``agent identify`` does (eq. 3.11, exact solver, output-error
refinement), then :func:`ident.diagnosis.diagnose` scored on the validation recording
(``--cv`` for two-fold cross-validation instead).

Prints the confusion matrix, accuracy, false-positive rate on ``none``, the error of each
estimated effect parameter against truth (share within ±25 %), the median held-out fit
before/after, the time per case, and the time of one diagnosis of a ~25 s recording.

    python benchmarks/bench_diagnosis.py [--cases-per-class N] [--cv] [--no-long] [--seed S]
        [--classes backlash,time_delay] [--jobs 2] [--cache DIR]
"""

from __future__ import annotations

import argparse
import os
import json
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

# one BLAS thread per process, as agent/cli.py does (the fits are many small solves)
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

from make_concealed_recordings import Case, base_fit_pct, identify_base, make_case  # noqa: E402

from virtual_cnc.presets import load_machine  # noqa: E402
from ident.diagnosis import EFFECTS, diagnose  # noqa: E402
from benchmarks.diagnosis_config_arg import CONFIG_HELP, diagnosis_config  # noqa: E402

CLASSES = list(EFFECTS) + ["none"]
#: fadal-smc (full feed-forward) is left out: its clean base-model fit is only ~75 %, so the
#: residual there is model structure, not a concealed effect (see docs/diagnosis.md).
PRESETS = ["fadal-ppi", "fadal-pid"]
#: A case is "concealed" only while the base model still fits at least this well (issue 5), on
#: the identification and the validation recording.
MIN_BASE_FIT = 60.0


def draw_effect(cls: str, rng: np.random.Generator, shrink: float = 1.0) -> str | None:
    """A random ``--effect`` text of class ``cls`` in a realistic range (× ``shrink`` ≤ 1)."""
    lu = lambda a, b: shrink * float(np.exp(rng.uniform(np.log(a), np.log(b))))  # noqa: E731
    if cls == "none":
        return None
    if cls == "backlash":
        return f"backlash={lu(0.03, 0.1):.4f}"
    if cls == "stribeck":
        return (f"stribeck=static_to_coulomb_ratio:{rng.uniform(2.5, 5.0):.2f},"
                f"stribeck_velocity_mm_s:{lu(0.5, 3.0):.3f}")
    if cls == "resonance":
        return f"resonance=freq_hz:{rng.uniform(80, 150):.1f},damping:{rng.uniform(0.01, 0.04):.3f}"
    if cls == "time_delay":
        if rng.random() < 0.5:
            return f"time_delay=delay_s:{lu(0.0007, 0.0015):.5f},at:actuation"
        return f"time_delay=delay_s:{lu(0.002, 0.006):.5f},at:capture"
    if cls == "cyclic_error":
        return f"cyclic_error=period_mm:{rng.uniform(2.0, 8.0):.3f},amplitude:{lu(150, 600):.1f}"
    if cls == "saturation":
        return f"saturation={rng.uniform(2.05, 2.35) / shrink ** 0.3:.3f}"
    raise ValueError(cls)


def truth_value(cls: str, truth: dict, machine: str) -> dict[str, float]:
    """Truth in the units the diagnosis reports (saturation limit V → mm/s² via K/J)."""
    if cls == "backlash":
        return {"gap_mm": truth["gap_mm"]}
    if cls == "time_delay":
        return {"delay_s": truth["delay_s"]}
    if cls == "cyclic_error":
        return {"period_mm": truth["period_mm"]}
    if cls == "resonance":
        return {"freq_hz": truth["freq_hz"]}
    if cls == "stribeck":
        return {"static_to_coulomb_ratio": truth["static_to_coulomb_ratio"]}
    if cls == "saturation":  # the amplifier's limit_v [V] (older cases: "limit") → the model's limit [mm/s²]
        kj = load_machine(machine).axes["X"].plant.K_over_J
        return {"limit": truth.get("limit_v", truth.get("limit")) * kj}
    return {}


def prepare_case(cls: str, i: int, seed0: int, cache: Path | None):
    """The case ``i`` of class ``cls``: recordings, truth and identified base model.

    Every case draws from its own generator (``seed0``, class, index), so one class can be
    run alone and a second battery (another ``--seed``) is independent of the first.
    ``cache``: a folder where prepared cases are kept between runs (``.npz``).
    """
    from ident.model import DriveModel

    ci = CLASSES.index(cls)
    seed = seed0 + 100 * ci + i
    path = cache / f"{seed0}_{cls}_{i}.npz" if cache else None
    if path is not None and path.exists():
        z = np.load(path, allow_pickle=False)
        meta = json.loads(str(z["meta"]))
        case = Case(meta["name"], meta["effect"], meta["effect_text"], meta["machine"], meta["seed"],
                    meta["Ts"], z["x_r"], z["x"], z["segment"], z["val_x_r"], z["val_x"], z["val_segment"],
                    meta["truth"])
        return case, DriveModel.from_theta(z["theta"]), meta["base_fit"], meta["t_prep"]
    rng = np.random.default_rng([seed0, ci, i])
    machine = PRESETS[int(rng.integers(len(PRESETS)))]
    t0 = time.perf_counter()
    shrink = 1.0
    for _attempt in range(4):
        # conceal: shrink the magnitude until the base model still fits >= 60 %
        text = draw_effect(cls, rng, shrink)
        case = make_case(f"{cls}{i}", text, seed=seed, machine=machine)
        model = identify_base(case.x_r, case.x, case.Ts, case.segment)
        base_fit = base_fit_pct(model, case.x_r, case.x, case.Ts, case.segment)
        # the validation run too: a magnitude that makes the loop ring or limit-cycle on the
        # other program is not concealed (a lightly damped mode near the bandwidth can)
        val_fit = base_fit_pct(model, case.val_x_r, case.val_x, case.Ts, case.val_segment)
        if min(base_fit, val_fit) >= MIN_BASE_FIT or cls == "none":
            break
        shrink *= 0.6
    t_prep = time.perf_counter() - t0
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {"name": case.name, "effect": case.effect, "effect_text": case.effect_text, "machine": machine,
                "seed": seed, "Ts": case.Ts, "truth": case.truth, "base_fit": base_fit, "t_prep": t_prep}
        np.savez(path, meta=json.dumps(meta), theta=model.theta, x_r=case.x_r, x=case.x, segment=case.segment,
                 val_x_r=case.val_x_r, val_x=case.val_x, val_segment=case.val_segment)
    return case, model, base_fit, t_prep


def run_case(cls: str, i: int, seed0: int, use_cv: bool, cache: Path | None, config: str = "{}") -> dict:
    """Prepare, diagnose and score one case; the row printed and tabulated."""
    case, model, base_fit, t_prep = prepare_case(cls, i, seed0, cache)
    machine, text = case.machine, case.effect_text
    t1 = time.perf_counter()
    val = None if use_cv else (case.val_x_r, case.val_x, case.val_segment)
    d = diagnose(case.x_r, case.x, case.Ts, model, segment=case.segment, validation=val,
                 config=diagnosis_config(config))
    t2 = time.perf_counter()
    verdict = d.verdict if isinstance(d.verdict, list) else [d.verdict]
    est = {}
    if cls in verdict:
        cand = [c for c in d.candidates if c.effect == cls and c.accepted]
        if cand:
            est = cand[0].parameters
    errs = {}
    for k, v in truth_value(cls, case.truth, machine).items():
        if k in est and v:
            errs[k] = (est[k] - v) / v
    named = [c for c in d.candidates if c.accepted and c.effect == verdict[0]]
    said = ""
    if named:
        def words(v) -> str:
            if isinstance(v, float):
                return f"{v:.4g}"
            if isinstance(v, list):
                return "[" + ",".join(words(w) for w in v) + "]"
            return str(v)

        said = " ".join(f"{k}={words(v)}" for k, v in named[0].parameters.items()
                        if k not in ("amplitude_unit", "limit_unit"))
    ok = "ok " if verdict[0] == cls else "MISS"
    err_txt = " ".join(f"{k}{100 * e:+.0f}%" for k, e in errs.items())
    line = (f"{ok} {cls:12s} {i:2d} {machine:9s} {text or '-':60s} → {'+'.join(verdict):24s} base {base_fit:5.1f} % "
            f"held-out {d.fit_before_pct:6.2f} → {d.fit_after_pct:6.2f} %  {t2 - t1:5.1f} s {err_txt}  [{said}]")
    return {"cls": cls, "machine": machine, "effect": text, "verdict": verdict, "base_fit": base_fit,
            "before": d.fit_before_pct, "after": d.fit_after_pct, "t_diag": t2 - t1, "t_prep": t_prep,
            "errs": errs, "n": case.x_r.size, "line": line}


def run(cases_per_class: int, use_cv: bool, seed0: int = 10_000, classes: list[str] | None = None,
        jobs: int = 1, cache: Path | None = None, config: str = "{}") -> dict:
    todo = [(cls, i) for cls in (classes or CLASSES) for i in range(cases_per_class)]
    rows = []
    if jobs <= 1:
        for cls, i in todo:
            rows.append(run_case(cls, i, seed0, use_cv, cache, config))
            print(rows[-1]["line"], flush=True)
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futs = [pool.submit(run_case, cls, i, seed0, use_cv, cache, config) for cls, i in todo]
            for f in futs:
                rows.append(f.result())
                print(rows[-1]["line"], flush=True)
    return {"rows": rows}


def report(rows: list[dict]) -> None:
    print("\nConfusion matrix (rows: truth, columns: verdict; a list verdict counts its first effect)")
    cols = CLASSES
    print(" " * 13 + " ".join(f"{c[:8]:>8s}" for c in cols))
    correct = 0
    for t in CLASSES:
        counts = [sum(1 for r in rows if r["cls"] == t and r["verdict"][0] == c) for c in cols]
        print(f"{t:12s} " + " ".join(f"{n:8d}" for n in counts))
        correct += counts[cols.index(t)]
    n = len(rows)
    print(f"\naccuracy: {correct}/{n} = {100 * correct / max(n, 1):.1f} %")
    none_rows = [r for r in rows if r["cls"] == "none"]
    fp = sum(1 for r in none_rows if r["verdict"][0] != "none")
    print(f"false positives on none: {fp}/{len(none_rows)}")
    multi = sum(1 for r in rows if len(r["verdict"]) > 1)
    print(f"verdicts naming two effects: {multi}")
    print("\nparameter error vs truth (cases where the effect was named):")
    keys = sorted({k for r in rows for k in r["errs"]})
    for k in keys:
        es = [r["errs"][k] for r in rows if k in r["errs"]]
        within = sum(1 for e in es if abs(e) <= 0.25)
        print(f"  {k:24s} n={len(es):2d}  median |err| {100 * statistics.median(abs(e) for e in es):5.1f} %  "
              f"within ±25 %: {within}/{len(es)}")
    print("\nheld-out tracking-error fit (median):")
    for t in CLASSES:
        rr = [r for r in rows if r["cls"] == t]
        if rr:
            print(f"  {t:12s} base-model fit {statistics.median(r['base_fit'] for r in rr):6.2f} %   held-out "
                  f"{statistics.median(r['before'] for r in rr):6.2f} → {statistics.median(r['after'] for r in rr):6.2f} %")
    td = [r["t_diag"] for r in rows]
    print(f"\ntime per case: diagnosis median {statistics.median(td):.1f} s (max {max(td):.1f} s) on "
          f"{statistics.median(r['n'] for r in rows) / 1000:.1f} s recordings; recording + identification "
          f"median {statistics.median(r['t_prep'] for r in rows):.1f} s")


def long_timing(use_cv: bool) -> None:
    """Diagnosis time of one ~25 s recording (thesis-sized programs), with an effect."""
    case = make_case("long", "backlash=0.05", seed=20_000, machine="fadal-ppi", n_low=200, n_high=200,
                     range_mm=10.0)
    t_id = time.perf_counter()
    model = identify_base(case.x_r, case.x, case.Ts, case.segment)
    val = None if use_cv else (case.val_x_r, case.val_x, case.val_segment)
    t0 = time.perf_counter()
    d = diagnose(case.x_r, case.x, case.Ts, model, segment=case.segment, validation=val)
    dt = time.perf_counter() - t0
    print(f"\n25 s-class recording: {case.x_r.size * case.Ts:.1f} s of data, identification {t0 - t_id:.1f} s, diagnosis {dt:.1f} s "
          f"(target ≤ 30 s incl. identification), verdict {d.verdict}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases-per-class", type=int, default=10)
    ap.add_argument("--cv", action="store_true", help="score by cross-validation, not the validation recording")
    ap.add_argument("--no-long", action="store_true", help="skip the 25 s timing case")
    ap.add_argument("--seed", type=int, default=10_000)
    ap.add_argument("--config", default="{}", help=CONFIG_HELP)
    ap.add_argument("--classes", default="", help="comma-separated classes to run (default: all seven)")
    ap.add_argument("--jobs", type=int, default=1, help="cases diagnosed in parallel (processes)")
    ap.add_argument("--cache", type=Path, default=None, help="folder keeping prepared cases between runs (keyed by seed, class and index only: empty it when the way cases are drawn or concealed changes)")
    args = ap.parse_args(argv)
    classes = [c.strip() for c in args.classes.split(",") if c.strip()] or None
    for c in classes or []:
        if c not in CLASSES:
            ap.error(f"unknown class {c!r} (one of {', '.join(CLASSES)})")
    res = run(args.cases_per_class, args.cv, args.seed, classes, args.jobs, args.cache, args.config)
    report(res["rows"])
    if not args.no_long:
        long_timing(args.cv)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

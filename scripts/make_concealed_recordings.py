#!/usr/bin/env python
"""Recordings from the virtual CNC with one concealed effect each — the proof of issue 5, item 5.

Each case runs the identification programs (``gcode_gen.excitation``: a low-speed and a
high-speed set) on the virtual CNC (``virtual_cnc.machine_run.simulate``) with one
effect of SPEC §7 added (or none), then a *validation* recording: the same kind of program
with a different seed.  Magnitudes are chosen so the base model of eq. 3.3 identified from
the recording still fits (tracking-error fit ≥ 60 %) and nothing shows by eye in the
position traces; the script checks the fit and prints it.

Written to ``fixtures/diagnosis/`` (small cases, ~4 s each) as CSV, SPEC §4 format
(``t_s,commanded_mm,actual_mm`` plus a ``segment`` column), one ``<case>.csv`` and
``<case>_validation.csv`` per case, and ``cases.json`` with the truth.

    python scripts/make_concealed_recordings.py [--out fixtures/diagnosis] [--seed 100] [--cases time_delay,...]

``--cases`` regenerates only the named cases (each keeps its own program seed, so the
others' files and their entries in ``cases.json`` stay as they are).

The functions are reused by ``benchmarks/bench_diagnosis.py``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from virtual_cnc.machine_run import simulate as run_programs  # noqa: E402
from gcode_gen.dialects import file_name, write  # noqa: E402
from gcode_gen.excitation import identification_programs  # noqa: E402

#: One fixture case per effect (and two clean ones): the --effect text and the truth.
FIXTURE_CASES: dict[str, str | None] = {
    "clean_ppi": None,
    "clean_pid": None,
    "backlash": "backlash=0.05",
    "stribeck": "stribeck=static_to_coulomb_ratio:4.0,stribeck_velocity_mm_s:2.0",
    "resonance": "resonance=freq_hz:100,damping:0.02",
    # 1.5 samples: one sample of dead time is the lag of sampling itself (docs/diagnosis.md),
    # and from about 1.95 ms this loop (phase margin ≈ 44° at 400 rad/s after the hold and
    # the backward-difference velocity) is unstable: it oscillates at its actuator limit
    "time_delay": "time_delay=0.0015",
    "cyclic_error": "cyclic_error=period_mm:4.0,amplitude:300",
    "saturation": "saturation=2.2",
}
FIXTURE_MACHINE = {"clean_pid": "fadal-pid"}


@dataclass
class Case:
    """A recording with its validation recording and the truth (arrays in mm, Ts in s)."""

    name: str
    effect: str  # an effect of SPEC §7 or "none"
    effect_text: str | None
    machine: str
    seed: int
    Ts: float
    x_r: np.ndarray
    x: np.ndarray
    segment: np.ndarray
    val_x_r: np.ndarray
    val_x: np.ndarray
    val_segment: np.ndarray
    truth: dict = field(default_factory=dict)


def _programs(seed: int, n_low: int, n_high: int, range_mm: float, workdir: Path) -> list[Path]:
    low, high = identification_programs(axes=("X",), n_low=n_low, n_high=n_high, range_mm=range_mm, seed=seed)
    paths = []
    for tp in (low, high):
        p = workdir / f"s{seed}_{file_name(tp, 'iso')}"
        p.write_text(write(tp, "iso"))
        paths.append(p)
    return paths


def record(seed: int, machine: str, effect_text: str | None, *, n_low: int, n_high: int, range_mm: float,
           noise_seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(x_r, x, segment, Ts) of axis X for the identification programs of ``seed``."""
    with tempfile.TemporaryDirectory() as d:
        progs = _programs(seed, n_low, n_high, range_mm, Path(d))
        rec = run_programs(progs, machine=machine, effects=[effect_text] if effect_text else [], seed=noise_seed)
    tr = rec.axes["X"]
    return tr.commanded.copy(), tr.actual.copy(), rec.segment.copy(), float(rec.sample_period)


def truth_of(effect_text: str | None) -> tuple[str, dict]:
    """Effect name and its parameters from the ``--effect`` text (defaults filled in)."""
    if not effect_text:
        return "none", {}
    from dataclasses import asdict

    from virtual_cnc.effects import parse_effect

    eff = parse_effect(effect_text)
    params = {k: v for k, v in asdict(eff).items() if k != "axis"}
    return eff.name, params


def make_case(name: str, effect_text: str | None, *, seed: int, machine: str = "fadal-ppi", n_low: int = 80,
              n_high: int = 28, range_mm: float = 5.0) -> Case:
    """A case: identification recording (program seed ``seed``) and validation (seed + 5000)."""
    x_r, x, seg, Ts = record(seed, machine, effect_text, n_low=n_low, n_high=n_high, range_mm=range_mm,
                             noise_seed=seed)
    vx_r, vx, vseg, _ = record(seed + 5000, machine, effect_text, n_low=n_low, n_high=n_high,
                               range_mm=range_mm, noise_seed=seed + 1)
    effect, params = truth_of(effect_text)
    return Case(name, effect, effect_text, machine, seed, Ts, x_r, x, seg, vx_r, vx, vseg, params)


def identify_base(x_r: np.ndarray, x: np.ndarray, Ts: float, segment: np.ndarray):
    """The base model of eq. 3.3 as ``agent identify`` would fit it: eq. 3.11 + exact solver + refinement.

    Uses no preview shift so the model answers the command as recorded.
    """
    from ident.model import Bounds
    from ident.refine import refine
    from ident.regression import build_regression
    from ident.solvers.exact import solve_exact

    reg = build_regression(x_r, x, Ts, segment, shift=0)
    bounds = Bounds()
    sol = solve_exact(reg.Phi, reg.Y, bounds, sample_period=Ts)
    model = sol.model
    res = refine(model, x_r, x, Ts, segment=segment, bounds=bounds, regression=reg)
    return res.model


def base_fit_pct(model, x_r: np.ndarray, x: np.ndarray, Ts: float, segment: np.ndarray) -> float:
    """Free-run tracking-error fit % (SPEC §5) of ``model`` with the project's simulator."""
    from ident.metrics import tracking_error_fit_pct
    from ident.simulation import simulate

    x_hat = simulate(model, x_r, Ts, segment=segment, x0=x)
    return tracking_error_fit_pct(x_r - x, x_r - x_hat)


def write_csv(path: Path, Ts: float, x_r: np.ndarray, x: np.ndarray, segment: np.ndarray) -> None:
    """SPEC §4 CSV (single axis) with an extra ``segment`` column."""
    t = np.arange(x_r.size) * Ts
    data = np.column_stack([t, x_r, x, segment])
    np.savetxt(path, data, delimiter=",", header="t_s,commanded_mm,actual_mm,segment", comments="",
               fmt=["%.6f", "%.7f", "%.7f", "%d"])


def read_csv(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(x_r, x, segment, Ts) from a CSV written by :func:`write_csv`."""
    d = np.loadtxt(path, delimiter=",", skiprows=1)
    Ts = float(np.median(np.diff(d[:, 0])))
    return d[:, 1].copy(), d[:, 2].copy(), d[:, 3].astype(np.int32), round(Ts, 9)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "fixtures" / "diagnosis")
    ap.add_argument("--seed", type=int, default=100, help="program seed of the first case")
    ap.add_argument("--cases", default="", help="comma-separated case names to regenerate (default: all)")
    args = ap.parse_args(argv)
    only = [c for c in args.cases.split(",") if c]
    unknown = sorted(set(only) - set(FIXTURE_CASES))
    if unknown:
        ap.error(f"no fixture case {', '.join(unknown)} (cases: {', '.join(FIXTURE_CASES)})")
    args.out.mkdir(parents=True, exist_ok=True)
    index_path = args.out / "cases.json"
    index = json.loads(index_path.read_text()) if only and index_path.exists() else {}
    for i, (name, text) in enumerate(FIXTURE_CASES.items()):
        if only and name not in only:
            continue
        machine = FIXTURE_MACHINE.get(name, "fadal-ppi")
        case = make_case(name, text, seed=args.seed + i, machine=machine)
        write_csv(args.out / f"{name}.csv", case.Ts, case.x_r, case.x, case.segment)
        write_csv(args.out / f"{name}_validation.csv", case.Ts, case.val_x_r, case.val_x, case.val_segment)
        model = identify_base(case.x_r, case.x, case.Ts, case.segment)
        fit = base_fit_pct(model, case.x_r, case.x, case.Ts, case.segment)
        index[name] = {"effect": case.effect, "effect_text": text, "machine": machine, "seed": case.seed,
                       "truth": case.truth, "duration_s": case.x_r.size * case.Ts,
                       "base_model_fit_pct": round(fit, 2), "base_model": model.to_dict()["model"]
                       if "model" in model.to_dict() else model.to_dict()}
        print(f"{name:14s} {case.x_r.size * case.Ts:5.1f} s  base-model fit {fit:6.1f} %  {text or ''}")
    index = {n: index[n] for n in FIXTURE_CASES if n in index}  # the table's order
    index_path.write_text(json.dumps(index, indent=1, default=float) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

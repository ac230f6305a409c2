"""Is a lightly damped mode's fit at the damping bound ripple of the free-run cost, or the data?

For each resonance case of a labelled zoo: the diagnosis's resonance search on the
identification recording (base re-fitted in free run, as ``diagnose`` does), then the
profile of the cost over the damping ζ: at each ζ of ``--damping`` the search's model is
re-fitted with ζ held, started at the labelled frequency and at the fitted one, by
multiple shooting (:meth:`~ident.diagnosis.spec.Chunk.shots`, windows of ``--window``
seconds from the recorded state), and its weighted cost printed both over those windows
and in free run over the whole recording, relative to the search's own fit.  If the free
run's ripple hid a lightly damped valley, the windows' cost would be lower at small ζ
than at the bound.  A DEVELOPMENT figure (the zoo the diagnosis is tuned on).

    python benchmarks/bench_shooting_profile.py [--zoo ../shared/data/drive-zoo-dev2]
        [--cases case_000,case_005] [--window 0.3] [--damping 0.02,0.05,0.1,0.15]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks._zoo_search import zoo_cases  # noqa: E402


def profile(zoo: Path, case: dict, window: float, dampings: list[float]) -> list[str]:
    from benchmarks._zoo_search import zoo_search
    from ident.diagnosis.augmented import EP_INDEX
    from ident.diagnosis.candidates import fit_spec
    from ident.diagnosis.config import DEFAULT
    from ident.diagnosis.spec import sse

    cfg = dataclasses.replace(DEFAULT, shooting_window_s=window)
    fit, _base, full, _held = zoo_search(zoo, case, "resonance", cfg)
    shots = full.shots(window, cfg.shooting_lead_s)
    c_shot, c_free = sse(fit, shots), sse(fit, full)
    i_f, i_z, i_mu = EP_INDEX["freq_hz"], EP_INDEX["damping"], EP_INDEX["motor_fraction"]
    truth = case.get("parameters", {}).get("freq_hz", float("nan"))
    lines = [f"{case['case']}  truth {truth:.1f} Hz   search: {fit.ep[i_f]:.1f} Hz  ζ {fit.ep[i_z]:.3f}  "
             f"μ {fit.ep[i_mu]:.2f}  variant {int(fit.modes[3])}   cost: windows {c_shot:.4g}, free run {c_free:.4g}"]
    for z in dampings:
        for f0, what in ((truth, "truth"), (float(fit.ep[i_f]), "fitted")):
            s0 = fit.copy()
            s0.ep[i_f], s0.ep[i_z], s0.box = f0, z, {}
            s1 = fit_spec(s0, shots, max_iter=cfg.shooting_iter, fd_step=cfg.fd_step_rough, polish=False,
                          search=True, bounds={"damping": (0.999 * z, 1.001 * z)}, cfg=cfg)
            lines.append(f"    ζ {z:.3f} from the {what:6s} frequency -> {s1.ep[i_f]:6.1f} Hz:  windows "
                         f"{sse(s1, shots) / c_shot:6.3f}  free run {sse(s1, full) / c_free:6.3f}  (× the search's)")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--zoo", default=str(ROOT.parent / "shared" / "data" / "drive-zoo-dev2"))
    ap.add_argument("--cases", default="", help="comma-separated; default every resonance case")
    ap.add_argument("--window", type=float, default=0.3)
    ap.add_argument("--damping", default="0.02,0.05,0.1,0.15")
    args = ap.parse_args()
    zoo = Path(args.zoo)
    cases = zoo_cases(zoo, "resonance", args.cases)
    for c in cases:
        print("\n".join(profile(zoo, c, args.window, [float(v) for v in args.damping.split(",")])), flush=True)


if __name__ == "__main__":
    main()

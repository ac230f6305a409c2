"""Does a clip of the drive's output hold a saturation case, and at which slope of the limit?

For each saturation case of a labelled zoo: the base model re-fitted in free run on the
identification recording (as ``diagnose`` does), then the profile of the cost over the
limit's slope c (``limit_slope``, 1/s: ``u`` clipped to ``±limit − c·ẋ``): at each c of
``--slopes`` and for both integral variants (frozen while clipped, or winding up), the
limit started at the 99th percentile of the base's drive output ``|u + c·ẋ|`` and fitted
jointly with the base, c held.  Printed: the limit reached, and the training and held-out
(validation recording) costs relative to the base's.  c = 0 is the clip the diagnosis had
before the slope: if no c > 0 did better, the miss would lie elsewhere.  A DEVELOPMENT
figure (the zoo the diagnosis is tuned on).

    python benchmarks/bench_saturation_profile.py [--zoo ../shared/data/drive-zoo-dev2]
        [--cases case_014,case_025] [--slopes 0,1,2,3,4,6]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks._zoo_search import zoo_cases  # noqa: E402


def profile(zoo: Path, case: dict, slopes: list[float]) -> list[str]:
    from benchmarks._zoo_search import zoo_base
    from ident.diagnosis.augmented import EP_INDEX, simulate_augmented
    from ident.diagnosis.candidates import fit_spec
    from ident.diagnosis.config import DEFAULT as cfg
    from ident.diagnosis.spec import sse

    base, _other, full, test = zoo_base(zoo, case, cfg)
    Ts = full.Ts
    u = np.empty(full.n)
    simulate_augmented(full.x_r, full.x, Ts, base.theta, flags=base.flags(), ep=base.ep, modes=base.modes,
                       starts=full.starts, derivs=full.derivs, u_out=u, warm=full.warm)
    ok = np.isfinite(u)
    train0, test0 = sse(base, full), sse(base, test)
    lines = [f"{case['case']}  base |u| 99th percentile {np.percentile(np.abs(u[ok]), 99):.0f} mm/s², "
             f"top speed {np.max(np.abs(full.derivs[0])):.0f} mm/s"]
    for c in slopes:
        limit = float(np.percentile(np.abs(u[ok] + c * full.derivs[0][ok]), 99.0))
        row = []
        for windup in (False, True):
            s0 = base.with_effect("saturation", {"limit": limit, "limit_slope": c}, int(windup))
            s1 = fit_spec(s0, full, max_iter=20, fd_step=cfg.fd_step_rough, cfg=cfg,
                          bounds={"limit_slope": (c, c)})
            row.append(f"{'winding up' if windup else 'frozen':10s} limit {s1.ep[EP_INDEX['limit']]:6.0f}  "
                       f"train {sse(s1, full) / train0:6.3f}  held-out {sse(s1, test) / test0:6.3f}")
        lines.append(f"    c {c:4.1f} /s:  " + "   |   ".join(row))
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--zoo", default=str(ROOT.parent / "shared" / "data" / "drive-zoo-dev2"))
    ap.add_argument("--cases", default="", help="comma-separated; default every saturation case")
    ap.add_argument("--slopes", default="0,1,2,3,4,6")
    args = ap.parse_args()
    zoo = Path(args.zoo)
    cases = zoo_cases(zoo, "saturation", args.cases)
    try:
        slopes = [float(v) for v in args.slopes.split(",")]
    except ValueError:
        sys.exit(f"error: --slopes must be comma-separated numbers, got {args.slopes!r}")
    for c in cases:
        print("\n".join(profile(zoo, c, slopes)), flush=True)


if __name__ == "__main__":
    main()

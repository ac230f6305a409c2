"""Where does the training cost put a backlash gap: at the labelled gap, or short of it?

For each backlash case of a labelled zoo: the diagnosis's backlash search on the
identification recording (base re-fitted in free run, as ``diagnose`` does, every variant
of :class:`~ident.diagnosis.effects.Backlash` started), then the profile of the weighted
free-run cost (eq. 3.6) over the gap: for every variant (0 massless table, 1 two-mass
full-closed, 2 two-mass semi-closed) and every gap of ``--ratios`` × the label, the model
re-fitted with the gap held (``--iter`` iterations, everything else free: θ of eq. 3.3,
the motor share, and in variant 1 the position term's motor share ψ; with
``--hold-psi`` ψ stays where the search left it), started from the
search's model (its variant, or switched to the other one).  Printed per point: the cost relative to the search's, and the residual rms over the
slow part of the recording (before the command first exceeds ``--slow`` mm/s: the
low-speed set of tiny moves) and over the rest.  If the fit stopped short of a minimum at
the label (a bound, ripple, a weighting that favours the slow part), the profile shows it
there; if every variant's profile rises towards the label in both parts, the model —
its structure, or a parameter it holds (``--hold-psi``) — puts the gap elsewhere.  A DEVELOPMENT figure (the zoos the
diagnosis is tuned on).

    python benchmarks/bench_gap_profile.py [--zoo ../shared/data/drive-zoo-dev2]
        [--cases case_001] [--ratios 0.5,0.7,0.85,1,1.2] [--variants 0,1,2] [--hold-psi]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks._zoo_search import zoo_cases  # noqa: E402


def profile(zoo: Path, case: dict, ratios: list[float], variants: list[int], iters: int, slow: float,
            hold_psi: bool) -> list[str]:
    from benchmarks._zoo_search import zoo_search
    from ident.diagnosis.augmented import EP_INDEX, MODE_SLOTS
    from ident.diagnosis.candidates import fit_spec
    from ident.diagnosis.config import DEFAULT as cfg
    from ident.diagnosis.spec import simulate_spec, sse

    fit, base, full, _held = zoo_search(zoo, case, "backlash", cfg)
    x, Ts = full.x, full.Ts
    slot, i_g = MODE_SLOTS["backlash"], EP_INDEX["gap_mm"]
    i_mu, i_psi = EP_INDEX["motor_fraction"], EP_INDEX["position_motor_share"]
    c_fit = sse(fit, full)
    fast = np.flatnonzero(np.abs(full.derivs[0]) > slow)
    cut = int(fast[0]) if fast.size else x.size  # the slow part: before the command first runs fast

    def rms_um(r: np.ndarray) -> str:
        return f"{1e3 * np.sqrt(np.mean(r[:cut] ** 2)):5.2f} / {1e3 * np.sqrt(np.mean(r[cut:] ** 2)):5.2f}"

    truth = case["parameters"]["gap_mm"]
    lines = [f"{case['case']}  gap truth {1e3 * truth:.1f} µm   search: {1e3 * fit.ep[i_g]:.1f} µm "
             f"({fit.ep[i_g] / truth - 1:+.0%}), variant {int(fit.modes[slot])}, motor share "
             f"{fit.ep[i_mu]:.2f}, ψ {fit.ep[i_psi]:.2f}; base cost × {sse(base, full) / c_fit:.2f}; "
             f"residual rms µm slow / fast {rms_um(simulate_spec(fit, full) - x)} (slow part {cut * Ts:.1f} s)"]
    for mode in variants:
        costs = []
        for r in ratios:
            s0 = fit.copy()
            if int(fit.modes[slot]) != mode:
                s0.modes[slot] = mode
                if mode == 2:
                    s0.ep[i_psi] = 0.0
                if mode and not int(fit.modes[slot]):
                    s0.ep[i_mu] = 0.5
            g = r * truth
            s0.ep[i_g] = g
            if hold_psi:  # a parameter named in ranges is held by the fit
                s0.ranges["position_motor_share"] = (s0.ep[i_psi], s0.ep[i_psi])
            s1 = fit_spec(s0, full, max_iter=iters, bounds={"gap_mm": (0.999 * g, 1.001 * g)}, cfg=cfg)
            c = sse(s1, full)
            costs.append(c)
            lines.append(f"    variant {mode}  gap {r:4.2f} × truth: cost {c / c_fit:7.3f} × the search's   "
                         f"motor share {s1.ep[i_mu]:.2f}  ψ {s1.ep[i_psi]:.2f}   d0 {s1.theta[6]:8.1f} d1 {s1.theta[7]:8.1f} mm/s²   "
                         f"rms µm slow / fast {rms_um(simulate_spec(s1, full) - x)}")
        lines.append(f"    variant {mode}: lowest cost at {ratios[int(np.argmin(costs))]:.2f} × the truth")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--zoo", default=str(ROOT.parent / "shared" / "data" / "drive-zoo-dev2"))
    ap.add_argument("--cases", default="", help="comma-separated; default every backlash case")
    ap.add_argument("--ratios", default="0.5,0.7,0.85,1,1.2", help="gaps held, × the labelled gap")
    ap.add_argument("--variants", default="0,1,2", help="backlash variants profiled")
    ap.add_argument("--iter", type=int, default=15, help="iterations of each held-gap fit")
    ap.add_argument("--slow", type=float, default=10.0, help="mm/s: the command speed that ends the slow part")
    ap.add_argument("--hold-psi", action="store_true", help="hold ψ where the search left it")
    args = ap.parse_args()
    zoo = Path(args.zoo)
    cases = zoo_cases(zoo, "backlash", args.cases)
    ratios = [float(v) for v in args.ratios.split(",")]
    variants = [int(v) for v in args.variants.split(",")]
    for c in cases:
        print("\n".join(profile(zoo, c, ratios, variants, args.iter, args.slow, args.hold_psi)), flush=True)


if __name__ == "__main__":
    main()

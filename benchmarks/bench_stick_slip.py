"""Does a Stribeck curve fail on held-out data by its level, or by the phase of its stick-slip?

For each Stribeck case of a labelled zoo: the diagnosis's base model and Stribeck search on
the identification recording (base re-fitted in free run, as ``diagnose`` does), then on the
validation recording

* the share of the held-out residual the curve removes in free run and restarted at rest
  (:func:`ident.diagnosis.spec.rest_residual`: restarted at the recorded position after
  every dwell of the command where the axis rests, the force friction holds profiled), and
  on the identification recording in free run;
* where the held-out residual energy lies, base and Stribeck (command at rest, below
  2 mm/s, 2–10 mm/s, above 10 mm/s), as a share of the base's;
* the same two held-out shares with the breakaway ratio moved by ±0.3 % and ±1 %, the
  rest of the model held: a spread far larger than the change of the model is the phase of
  marginal breakaways (one missed breakaway leaves the axis stuck at another place until
  the next move), not the curve's level.

A DEVELOPMENT figure (the zoo the diagnosis is tuned on).

    python benchmarks/bench_stick_slip.py [--zoo ../shared/data/drive-zoo-dev2] [--cases case_006,case_007]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks._zoo_search import zoo_cases  # noqa: E402


def profile(zoo: Path, case: dict) -> list[str]:
    from benchmarks._zoo_search import zoo_search
    from ident.diagnosis.augmented import EP_INDEX
    from ident.diagnosis.config import DEFAULT as cfg
    from ident.diagnosis.spec import ModelSpec, rest_residual, simulate_spec

    fit, base, full, held = zoo_search(zoo, case, "stribeck", cfg)
    rests = held.rests(cfg.rest_restart_s)

    def free(s: ModelSpec, ch) -> np.ndarray:
        return (simulate_spec(s, ch) - ch.x)[ch.score]

    def at_rest(s: ModelSpec) -> np.ndarray:
        return rest_residual(s, rests, cfg.rest_force_grid, cfg.rest_force_span) if rests is not None else free(s, held)

    def gain(r1: np.ndarray, r0: np.ndarray) -> float:
        return 1.0 - float(np.linalg.norm(r1) / np.linalg.norm(r0))

    f0, a0 = free(base, held), at_rest(base)
    f1, a1 = free(fit, held), at_rest(fit)
    i_r, i_v = EP_INDEX["static_to_coulomb_ratio"], EP_INDEX["stribeck_velocity_mm_s"]
    n_rest = 0 if rests is None else int(np.count_nonzero(rests.warm[0]))
    lines = [f"{case['case']}  Stribeck fit: ratio {fit.ep[i_r]:.3f}, v_s {fit.ep[i_v]:.3g} mm/s;  removes "
             f"{100 * gain(free(fit, full), free(base, full)):+.1f} % of the training residual, of the held-out "
             f"{100 * gain(f1, f0):+.1f} % in free run, {100 * gain(a1, a0):+.1f} % restarted at rest "
             f"({n_rest} restarts)"]
    v_r = np.abs(held.derivs[0][held.score])
    e0 = float(f0 @ f0)
    share = []
    for lo, hi, what in ((0.0, 0.0, "command at rest"), (1e-9, 2.0, "< 2 mm/s"), (2.0, 10.0, "2-10 mm/s"),
                         (10.0, np.inf, "> 10 mm/s")):
        m = (v_r == 0.0) if hi == 0.0 else (v_r >= lo) & (v_r < hi)
        share.append(f"{what} {100 * f0[m] @ f0[m] / e0:.0f} → {100 * f1[m] @ f1[m] / e0:.0f} %")
    lines.append("    held-out residual energy (share of the base's), base → Stribeck: " + ", ".join(share))
    moved = []
    for f in (0.99, 0.997, 1.003, 1.01):
        s = fit.copy()
        s.ep = s.ep.copy()
        s.ep[i_r] *= f
        moved.append(f"×{f:g}: {100 * gain(free(s, held), f0):+.1f} / {100 * gain(at_rest(s), a0):+.1f}")
    lines.append("    ratio moved, held-out gain % free run / restarted at rest:  " + ",  ".join(moved))
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--zoo", default=str(ROOT.parent / "shared" / "data" / "drive-zoo-dev2"))
    ap.add_argument("--cases", default="", help="comma-separated; default every Stribeck case")
    args = ap.parse_args()
    zoo = Path(args.zoo)
    cases = zoo_cases(zoo, "stribeck", args.cases)
    for c in cases:
        print("\n".join(profile(zoo, c)), flush=True)


if __name__ == "__main__":
    main()

"""How often the 95 % intervals of ident/uncertainty.py cover a known truth, and how their
widths compare with the spread of the estimates over noise realisations.

The drive is the thesis's PID drive (Table 3.4, X, "Actual"), run by the model's own exact
discretisation (``ident.simulation.simulate``) on the command of the default identification
programs (seed 7, through the virtual CNC's interpolator), so the truth is in the model
class and only the noise is random: 0.5 µm AR(1) noise with correlation 0.9 per sample
(integrated time 19 samples, like a closed loop's residual), then white (correlation 0);
20 realisations each (seeds 300 … 319; the method was designed on other seeds and another
program, never these).  Each is identified as a user would
(``ident.identify``, exact + refinement, preview shift searched); the preview shifts it
chose are printed: the intervals hold for the chosen shift.

    python benchmarks/bench_interval_coverage.py

Prints, per noise and parameter: coverage (of 20), the spread of the estimates divided by the mean
standard error (1 = the intervals are as wide as they should be), the first-order standard
error computed with the known noise covariance divided by the mean standard error (1 = the
estimator does what linear theory can), and the mean half-width.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter

import gcode_gen
import ident
import virtual_cnc
from core.recording import Recording
from ident.model import DriveModel
from ident.simulation import FreeRun, simulate
from ident.uncertainty import PARAMETER_NAMES, SEARCH_NAMES, output_error_jacobian

PID_X = DriveModel(a1=192.65, a2=44356.23, a3=316830.21, b0=0.0, b1=190.10, b2=44356.23, d0=441.0, d1=-302.0)


def _ar1(n: int, rho: float, sigma: float, rng: np.random.Generator) -> np.ndarray:
    e = rng.standard_normal(n) * sigma * math.sqrt(1 - rho * rho)
    out = np.empty(n)
    out[0] = rng.standard_normal() * sigma
    for k in range(1, n):
        out[k] = rho * out[k - 1] + e[k]
    return out


def _linear_theory_se(xr, x, cmd_rec, rho: float, sigma: float) -> np.ndarray:
    """Standard errors of a1 … d1 from first-order theory with the *known* noise covariance:
    (JᵀJ)⁻¹ JᵀΣJ (JᵀJ)⁻¹, Σ of the AR(1) noise (JᵀΣJ through the filter's adjoint), J at the truth."""
    fr = FreeRun(xr, cmd_rec.sample_period, segment=cmd_rec.segment, x0=x)
    J, _ = output_error_jacobian(fr, PID_X, x)
    AtJ = lfilter([1.0], [1.0, -rho], J[::-1], axis=0)[::-1]
    Ainv = np.linalg.inv(J.T @ J)
    cov = Ainv @ (AtJ.T @ AtJ * sigma ** 2 * (1 - rho ** 2)) @ Ainv
    return np.sqrt(np.diag(cov))


def _coverage(xr, x, cmd_rec, rho: float, truth: dict[str, float]) -> None:
    names = PARAMETER_NAMES + SEARCH_NAMES
    theory = dict(zip(PARAMETER_NAMES, _linear_theory_se(xr, x, cmd_rec, rho, 0.5e-3)))
    est, se, cover, half = ({k: [] for k in names} for _ in range(4))
    shifts: dict[int, int] = {}
    for seed in range(300, 320):
        noise = _ar1(x.size, rho, 0.5e-3, np.random.default_rng(seed))
        rec = Recording.from_arrays(cmd_rec.t, {"X": xr}, {"X": x + noise}, segment=cmd_rec.segment)
        r = ident.identify(rec, diagnose=False).axes["X"]
        shifts[r.shift] = shifts.get(r.shift, 0) + 1
        for k in names:
            iv = r.uncertainty.parameters[k]
            est[k].append(iv.value)
            se[k].append(iv.se)
            cover[k].append(iv.lo <= truth[k] <= iv.hi)
            half[k].append((iv.hi - iv.lo) / 2)
    print(f"\n0.5 µm AR(1) noise, correlation {rho} per sample; preview shifts chosen: "
          + ", ".join(f"{s:+d} ({n}x)" for s, n in sorted(shifts.items())) + "\n")
    print("| quantity | true | covered (of 20) | spread / mean se | linear-theory se / mean se "
          "| mean 95 % half-width |")
    print("|---|---|---|---|---|---|")
    for k in names:
        ratio = np.std(est[k], ddof=1) / np.mean(se[k])
        th = f"{theory[k] / np.mean(se[k]):.2f}" if k in theory else "–"
        print(f"| {k} | {truth[k]:.4g} | {sum(cover[k])} | {ratio:.2f} | {th} | {np.mean(half[k]):.3g} |")
    total = sum(sum(c) for c in cover.values())
    print(f"\nall: {total} of {20 * len(names)} intervals cover the truth ({100 * total / (20 * len(names)):.1f} %)")


def main() -> None:
    cmd_rec = virtual_cnc.simulate(gcode_gen.generate(["X"], seed=11), "fadal-pid", seed=11)
    xr = cmd_rec.axes["X"].commanded
    x = simulate(PID_X, xr, cmd_rec.sample_period, segment=cmd_rec.segment)
    wn, zeta, p = PID_X.search_variables()
    truth = {**{k: getattr(PID_X, k) for k in PARAMETER_NAMES},
             "wn_hz": wn / (2 * math.pi), "zeta": zeta, "p_hz": p / (2 * math.pi)}
    for rho in (0.9, 0.0):
        _coverage(xr, x, cmd_rec, rho, truth)


if __name__ == "__main__":
    main()

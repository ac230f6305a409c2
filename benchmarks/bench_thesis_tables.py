"""The thesis's simulation tables reproduced: Tables 3.3 (P-PI), 3.4 (PID), 3.5 (SMC) and 4.1 (PID, LM vs GA).

For each of the thesis's virtual Fadal drives (presets fadal-ppi, fadal-pid, fadal-smc,
whose eq. 3.4/3.5 parameters are the tables' "Actual" columns, tests/test_sim_presets.py)
the whole product runs as a user runs it: identification programs (``gcode_gen.generate``,
one axis at a time as Table 3.2's code, seed 1) → the virtual CNC (``virtual_cnc.simulate``, 1 ms servo, DAC,
encoder noise) → ``ident.identify`` (exact solver + output-error refinement; for Table 4.1
also the genetic algorithm, 4000 × 500, seed 0).  Printed per parameter, search variable,
pole and zero: the true value (eq. 3.4/3.5), the thesis's estimate (typed from the tables)
and ours with its 95 % interval and mark (``ident/uncertainty.py``); then the error of the
tracking frequency response, max |H_id − H_true| / |H_true| over 0.5 Hz … f_Nyquist/2 (ours
with the preview shift it was identified with, exp(jω·shift·T_s))
(and over 0.5 … 30 Hz, the band the thesis judged its FRFs on), for the thesis's estimate
and ours.  "True" is the continuous eq. 3.3 model of the drive; the virtual drive itself is
a sampled-data loop, which no eq. 3.3 model matches exactly.

    python benchmarks/bench_thesis_tables.py            # markdown tables on stdout

Figures in docs/identification.md ("The thesis's tables reproduced") come from this script.
"""

from __future__ import annotations

import math
import time

import numpy as np

import gcode_gen
import ident
import virtual_cnc
from ident.model import BASE_KEYS, DriveModel
from virtual_cnc.drive import closed_loop_parameters
from virtual_cnc.presets import load_machine

KEYS = BASE_KEYS

#: The thesis's "Estimated" columns: model parameters (a1 … d1).
THESIS = {
    ("Table 3.3", "fadal-ppi", "X"): (2648.46, 776813.58, 21349028.29, 1.08, -415.03, 65194.67, 7210, -5277),
    ("Table 3.3", "fadal-ppi", "Y"): (3061.86, 878064.60, 24070716.71, 1.19, -472.93, 75718.61, 7523, -7160),
    ("Table 3.4", "fadal-pid", "X"): (214.13, 60040.19, 685295.65, -0.35, 203.86, 60043.78, 620, -280),
    ("Table 3.4", "fadal-pid", "Y"): (123.02, 40099.88, 146558.19, -0.08, 123.16, 40089.20, 478, -428),
    ("Table 3.5", "fadal-smc", "X"): (566.95, 370137.94, 15346572.85, 0.85, 574.83, 370142.25, 2367, -1858),
    ("Table 3.5", "fadal-smc", "Y"): (449.09, 484496.30, 22962987.98, 0.87, 455.36, 484500.13, 2023, -2016),
    ("Table 4.1 GA", "fadal-pid", "X"): (214.41, 60072.73, 703594.29, -0.34, 203.74, 60076.41, 627, -277),
}
#: Table 4.1's search variables (ω_n Hz, ζ, p Hz): LM = Table 3.4 X's estimate, and GA.
THESIS_SEARCH = {("Table 3.4", "fadal-pid", "X"): (38.21, 0.42, 1.89), ("Table 4.1 GA", "fadal-pid", "X"): (38.20, 0.42, 1.94)}


def _g(v: float) -> str:
    return "–" if v is None or not math.isfinite(v) else f"{v:.4g}"


def _frf_error(model: DriveModel, true: DriveModel, f_hi: float, shift_s: float = 0.0,
               relative: bool = True) -> float:
    """Max tracking-FRF error over 0.5 … f_hi Hz, relative to |H_true| (or absolute: the
    tracking DC gain is 1, so that is relative to the command).  The model with its preview
    shift (the command it is driven with is advanced by ``shift_s`` s: a factor exp(jω shift_s))."""
    f = np.geomspace(0.5, f_hi, 400)
    h, _ = model.freqresp(f)
    h = h * np.exp(2j * np.pi * f * shift_s)
    h0, _ = true.freqresp(f)
    return float(np.max(np.abs(h - h0) / (np.abs(h0) if relative else 1.0)))


def _roots_text(roots) -> list[str]:
    return [f"{f:.4g} Hz, ζ {d:.2f}" for f, d in roots]


def _table(title: str, true: DriveModel, thesis: DriveModel | None, r, thesis_search=None) -> list[str]:
    u = r.uncertainty
    lines = [f"#### {title}", "", "| quantity | true | thesis | ours | ours 95 % interval | mark |",
             "|---|---|---|---|---|---|"]
    wn, zeta, p = true.search_variables()
    true_sv = (wn / (2 * math.pi), zeta, p / (2 * math.pi))
    if thesis_search is None and thesis is not None:
        w2, z2, p2 = thesis.search_variables()
        thesis_search = (w2 / (2 * math.pi), z2, p2 / (2 * math.pi))
    for i, k in enumerate(KEYS):
        iv = u.parameters[k]
        lines.append(f"| {k} | {_g(getattr(true, k))} | {_g(getattr(thesis, k)) if thesis else '–'} | {_g(iv.value)} "
                     f"| [{_g(iv.lo)}, {_g(iv.hi)}] | {iv.mark()} |")
    for i, k in enumerate(("wn_hz", "zeta", "p_hz")):
        iv = u.parameters[k]
        lines.append(f"| {k} | {_g(true_sv[i])} | {_g(thesis_search[i]) if thesis_search else '–'} | {_g(iv.value)} "
                     f"| [{_g(iv.lo)}, {_g(iv.hi)}] | {iv.mark()} |")
    for kind, ours, tr, th in (("pole", u.poles, true.poles(), thesis.poles() if thesis else []),
                               ("zero", u.zeros, true.zeros(), thesis.zeros() if thesis else [])):
        n = max(len(ours), len(tr), len(th))
        tr_t, th_t = _roots_text(tr), _roots_text(th)
        for i in range(n):
            o = ours[i] if i < len(ours) else None
            lo, hi = o.freq_hz_interval95 if o else (math.nan, math.nan)
            lines.append(f"| {kind} {i + 1} | {tr_t[i] if i < len(tr_t) else '–'} | {th_t[i] if i < len(th_t) else '–'} "
                         f"| {f'{o.freq_hz:.4g} Hz, ζ {o.damping:.2f}' if o else '–'} "
                         f"| {f'[{_g(lo)}, {_g(hi)}] Hz' if o else ''} | {o.mark() if o else ''} |")
    f_hi = 0.25 / r.sample_period
    shift_s = r.shift * r.sample_period
    ours_err = (_frf_error(r.model, true, f_hi, shift_s), _frf_error(r.model, true, 30.0, shift_s))
    ours_abs = _frf_error(r.model, true, f_hi, shift_s, relative=False)
    lines += ["", f"Tracking FRF error, max |H − H_true|/|H_true|: ours {ours_err[0] * 100:.1f} % over 0.5–{f_hi:.0f} Hz, "
              f"{ours_err[1] * 100:.1f} % over 0.5–30 Hz"
              + (f"; thesis {_frf_error(thesis, true, f_hi) * 100:.1f} % / {_frf_error(thesis, true, 30.0) * 100:.1f} %"
                 if thesis else "")
              + f".  Max |H − H_true| over 0.5–{f_hi:.0f} Hz: ours {ours_abs:.3f}"
              + (f", thesis {_frf_error(thesis, true, f_hi, relative=False):.3f}" if thesis else "")
              + f".  Fit {r.fit_identification.tracking_error_fit_pct:.2f} %, preview shift {r.shift}, "
              f"{'equivalent model' if u.is_equivalent else 'no equivalence mark'}.", ""]
    if u.is_equivalent:
        lines += ["Why: " + "; ".join(u.why) + ".", ""]
    return lines


def main() -> None:
    t0 = time.perf_counter()
    out: list[str] = []
    for table, preset in (("Table 3.3", "fadal-ppi"), ("Table 3.4", "fadal-pid"), ("Table 3.5", "fadal-smc")):
        machine = load_machine(preset)
        for axis in ("X", "Y"):  # each axis on its own program, as Table 3.2's single-axis code
            rec = virtual_cnc.simulate(gcode_gen.generate([axis], seed=1), preset, seed=1)
            res = ident.identify(rec, axes=[axis], diagnose=False)
            true = DriveModel(**{k: closed_loop_parameters(machine.axes[axis])[k] for k in KEYS})
            thesis = DriveModel(*THESIS[(table, preset, axis)])
            out += _table(f"{table}, {preset}, axis {axis}", true, thesis, res.axes[axis],
                          THESIS_SEARCH.get((table, preset, axis)))
            if preset == "fadal-pid" and axis == "X":
                ga = ident.identify(rec, axes=["X"], solver="ga", diagnose=False, seed=0)
                out += _table("Table 4.1, fadal-pid, axis X, genetic algorithm (thesis column: GA)", true,
                              DriveModel(*THESIS[("Table 4.1 GA", preset, "X")]), ga.axes["X"],
                              THESIS_SEARCH[("Table 4.1 GA", preset, "X")])
    print("\n".join(out))
    print(f"(run time {time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()

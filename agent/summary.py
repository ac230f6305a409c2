"""The terminal summary of an identification: the answer first (ident.headline), then the details.

Figures are named as in the report and the JSON: the one "held-out fit" (SPEC §5 on the
validation recording), the "fit on the identification recording" (not held out), the
diagnosis's "reference fit".
"""

from __future__ import annotations

import math

import typer

from ident.headline import HELD_OUT, axis_headline, comparison_words, saved_model_words, term_notes
from ident.model import BASE_KEYS
from ident.results import AxisResult, IdentifyResult


def _fmt(v: float) -> str:
    return "n/a" if v is None or not math.isfinite(v) else f"{v:.6g}"


def _print_intervals(r: AxisResult) -> None:
    """95 % intervals with their 'at bound' / 'not determined' marks, and the equivalent-model verdict."""
    u = r.uncertainty
    if u is None:
        return
    typer.echo("  95 % intervals (output-error fit, correlated residual accounted for):")
    for name, value, interval, mark in u.rows():
        typer.echo(f"    {name:8s} {value:>24s}  {interval}" + (f"  {mark}" if mark else ""))
    typer.echo("  " + u.equivalent_text())


def print_summary(result: IdentifyResult) -> None:
    echo = typer.echo
    echo(f"recording {result.source}" + (f", validated on {result.validation_source}" if result.validation_source else ""))
    against = result.metadata.get("against")
    for name, r in result.axes.items():
        h = axis_headline(r, result.validation_source)
        echo(f"\naxis {name}")
        echo(f"  identified:      {h.identified}")
        echo(f"  predicts:        {h.held_out}")
        cmp = comparison_words(r, against)
        if cmp:
            echo(f"  compared:        {cmp}")
        echo(f"  missing physics: {h.missing}")
        echo(f"  what to do:      {h.action}")
        m = r.model
        if r.prior_source:
            echo(f"  details: {saved_model_words(r)}, preview shift {r.shift} sample(s), checked on this "
                 "recording; not re-identified")
        else:
            echo(f"  details: solver {r.constrained.solver}" + (" + output-error refinement" if r.refined else "")
                 + f", preview shift {r.shift} sample(s)")
        echo("  model (eq. 3.3): " + ", ".join(f"{k}={_fmt(getattr(m, k))}" for k in BASE_KEYS))
        echo("  poles:  " + "; ".join(f"{f:.2f} Hz ζ={d:.2f}" for f, d in m.poles()))
        echo("  zeros:  " + ("; ".join(f"{f:.2f} Hz ζ={d:.2f}" for f, d in m.zeros()) or "none"))
        if r.runs_refit:  # the diagnosis's re-fit, what --machine runs
            vm = r.virtual_model
            echo(f"  virtual machine: eq. 3.3 re-fitted on a {vm.controller.replace('_', ' ')} control law"
                 + (f" with {', '.join(e.replace('_', ' ') for e in vm.effects)}" if vm.effects else "") + ": "
                 + ", ".join(f"{k}={_fmt(getattr(vm.model, k))}" for k in BASE_KEYS))
        if r.prior_source:
            pass  # the constraints of a fit made elsewhere are in that file's JSON
        elif r.constrained.solver == "ls":
            outside = r.bounds.check(m, r.sample_period)
            echo("  constraints: none applied (solver ls, unconstrained)"
                 + (f"; outside the bounds: {', '.join(outside)} (poles up to "
                    f"{r.bounds.f_max_hz_for(r.sample_period):g} Hz allowed)" if outside else ""))
        else:
            echo("  active constraints: " + (", ".join(r.active_constraints) or "none"))
        _print_intervals(r)
        for note in term_notes(r):
            echo(f"  note: {note}")
        fi = r.fit_identification
        if r.prior_source and r.prior_on_its_own_data:
            echo(f"  tracking-error fit of that model on this recording, which it was identified on (not held "
                 f"out): {fi.tracking_error_fit_pct:.2f} % (prediction error rms {fi.tracking_error_rms_mm * 1e3:.2f} µm)")
        elif r.prior_source:
            echo(f"  {HELD_OUT} of that model on this recording: {fi.tracking_error_fit_pct:.2f} % "
                 f"(prediction error rms {fi.tracking_error_rms_mm * 1e3:.2f} µm)")
        else:
            echo(f"  tracking-error fit on the identification recording (not held out): {fi.tracking_error_fit_pct:.2f} % "
                 f"(prediction error rms {fi.tracking_error_rms_mm * 1e3:.2f} µm); equation-error model before "
                 f"refinement {r.fit_constrained.tracking_error_fit_pct:.2f} %")
            echo(f"  unconstrained LS: {r.unconstrained_note}")
        if r.diagnosis is not None:
            echo("  diagnosis: " + r.diagnosis.summary)
        echo("  time: " + ", ".join(f"{k} {v:.2f} s" for k, v in r.timings.items()))
    if result.contour is not None:
        c = result.contour.to_dict()
        echo(f"\ncontour error ({c['source']} recording, axes {'/'.join(c['axes'])}): measured max "
             f"{c['measured']['max_abs_mm'] * 1e3:.2f} µm, predicted max {c['predicted']['max_abs_mm'] * 1e3:.2f} µm, "
             f"prediction error rms {c['prediction_error']['rms_mm'] * 1e3:.2f} µm")
    from ident.kernel import compiled_in_this_process

    echo(f"\ntotal {result.elapsed_s:.2f} s" + (" (most of it compiling the simulator, once after an install: the "
                                                "next runs load it from numba's cache)"
                                                if compiled_in_this_process() else ""))

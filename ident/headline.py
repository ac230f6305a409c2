"""The answer first: per axis, what was identified, how well it predicts held-out data, what
physics is missing and what to do — the opening of the terminal summary and the HTML report.

One held-out figure, named the same everywhere: the **held-out fit**, SPEC §5's tracking-error
fit % = 100·(1 − ‖e − ê‖/‖e − mean(e)‖) of the identified model in free run on the validation
recording (JSON ``axes.X.fit.validation.tracking_error_fit_pct``).  A second figure appears only
under a name that says what differs: the **held-out fit with the diagnosed physics** (the
model the virtual machine runs once the diagnosis accepted an effect; JSON
``diagnosis.fit_after_pct``), the **fit on the identification recording** (not held out), and
the diagnosis's **reference fit** (eq. 3.3 re-fitted by the diagnosis in free run, what each
candidate effect is weighed against; JSON ``diagnosis.fit_before_pct``).

The words for terms an engineer would otherwise look up (preview shift, a zero in the right
half-plane, a pole at a bound) are here too, so summary and report say the same.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core.effects import EFFECTS as REGISTRY
from ident.metrics import FitResult
from ident.results import AxisResult, AxisTraces, IdentifyResult

__all__ = ["AxisHeadline", "axis_headline", "result_headlines", "comparison_words", "term_notes", "HELD_OUT", "THESIS",
           "tracking_bandwidth_hz", "supported_band_hz", "COHERENT"]

#: the name of the one held-out figure
HELD_OUT = "held-out fit"

#: the method the model comes from
THESIS = ("W. Wong, “Rapid Identification of Virtual CNC Drives”, MASc thesis, University of Waterloo, "
          "2007 (supervisor K. Erkorkmaz; journal version: K. Erkorkmaz and W. Wong, Int. J. Machine Tools "
          "and Manufacture 47, 1381–1392, 2007)")

# what the machine's owner can do about each effect the diagnosis names
_ACTIONS = {
    "backlash": "lost motion at reversals: inspect the screw nut, bearings and coupling, or set the controller's "
                "backlash compensation to the gap",
    "stribeck": "breakaway friction at low speed: check lubrication and guideway preload; a friction "
                "feed-forward compensates it",
    "resonance": "a structural mode: keep servo gains and jerk away from its frequency, or add a notch filter",
    "time_delay": "a dead time: if it is the capture's, nothing on the machine needs fixing; if the drive's, "
                  "check the controller's interpolation and position-loop delays",
    "cyclic_error": "an error that repeats with position: typically screw lead or encoder error; a pitch-error "
                    "compensation table removes it",
    "saturation": "the drive reaches its current or torque limit: lower feed or acceleration, or check the "
                  "drive's limits",
    "external_force": "a load at particular times: look for a collision, cable drag or clamping at those times",
}


@dataclass(frozen=True)
class AxisHeadline:
    """The answer for one axis, each field one sentence.

    ``held_out_fit_pct`` is the one held-out figure (None without a validation recording).
    """

    axis: str
    identified: str
    held_out: str
    missing: str
    action: str
    held_out_fit_pct: float | None


def tracking_bandwidth_hz(r: AxisResult) -> float | None:
    """Frequency where |G_track| first falls 3 dB below its low-frequency gain, Hz (None below Nyquist)."""
    f = np.logspace(-2, math.log10(0.5 / r.sample_period), 2000)
    mag = np.abs(r.model.freqresp(f)[0])
    below = np.flatnonzero(mag < mag[0] / math.sqrt(2.0))
    return float(f[below[0]]) if below.size else None


#: coherence γ² above which the recording is taken to support an estimate of the response
COHERENT = 0.9


def supported_band_hz(r: AxisResult) -> float | None:
    """Highest frequency up to which the recording supports the tracking response: the H1 estimate's
    coherence (ident.frf_estimate) stays ≥ :data:`COHERENT` from its lowest frequency up to here, Hz."""
    from ident.frf_estimate import h1_estimate

    if r.traces is None:
        return None
    est = h1_estimate(r.traces.commanded, r.traces.actual, 1.0 / r.sample_period, segment=r.traces.segment)
    if est is None or est.coherence[0] < COHERENT:
        return None
    low = np.flatnonzero(est.coherence < COHERENT)
    return float(est.f[low[0] - 1] if low.size else est.f[-1])


def _um(mm: float) -> str:
    """A length in µm, or in mm from 1 mm up."""
    return f"{mm:.3g} mm" if abs(mm) >= 1.0 else f"{mm * 1e3:.3g} µm"


def _accepted(r: AxisResult) -> dict[str, dict]:
    d = r.diagnosis
    aug = getattr(d, "augmented_model", None) or {}
    out = dict(aug.get("effects") or {})
    for c in getattr(d, "candidates", []) or []:  # the external force is not in the augmented model
        if c.accepted and c.effect not in out:
            out[c.effect] = c.parameters
    carried = _carried(r)  # a saved model's own effects are not missing
    return {e: p for e, p in out.items() if e not in carried}


def _carried(r: AxisResult) -> dict[str, dict]:
    """The effects of the saved model given with ``--model`` (none for a model identified here)."""
    return dict(r.prior.effects) if r.prior is not None else {}


def saved_model_words(r: AxisResult) -> str:
    """The saved model ``--model`` gave, as its virtual machine runs it, with the effects it carries."""
    carried = "; ".join(_effect_words(e, p) for e, p in _carried(r).items())
    return (f"the model saved in {r.prior_source} as its virtual machine runs it"
            + (f" (with {carried})" if carried else ""))


def _held_out_words(fit: FitResult, traces: AxisTraces | None, where: str) -> str:
    """The held-out fit on a recording (``where``), its prediction error and the recorded tracking error."""
    e_rms = ""
    if traces is not None:
        e = traces.commanded - traces.actual
        e_rms = f" of a recorded tracking error of {_um(float(np.sqrt(np.mean(e ** 2))))} rms"
    return (f"{HELD_OUT} {fit.tracking_error_fit_pct:.2f} %{where} (prediction error "
            f"{_um(fit.tracking_error_rms_mm)} rms{e_rms})")


def _effect_words(effect: str, p: dict, unresolved: dict | None = None) -> str:
    from ident.diagnosis import EFFECT_MODELS

    if effect == "backlash":  # in µm: a machinist's unit for lost motion
        return f"backlash, gap {p['gap_mm'] * 1e3:.3g} µm"
    if effect == "external_force":
        return "an external force at " + ", ".join(f"{a:.2f}–{b:.2f} s" for a, b in p.get("times", []))
    # a value the recording does not resolve (a damping on its fit's bound) is said to be so
    return EFFECT_MODELS[effect].words(p, None, unresolved) if effect in EFFECT_MODELS else effect.replace("_", " ")


def _friction_words(r: AxisResult) -> str:
    """eq. 3.3's friction terms d0 / d1, called Coulomb friction only where they can be: a term
    that pushes the axis along its motion, or one the data do not determine, is said to be so."""
    m = r.model
    told = f"{m.d0:.3g} / {m.d1:.3g} mm/s² for positive / negative speed"
    if m.d0 < 0 or m.d1 > 0:
        return f"friction terms {told}, which push the axis along its motion: not Coulomb friction"
    loose = [k for k in ("d0", "d1") if r.uncertainty is not None and k in r.uncertainty.undetermined]
    if loose:
        return f"Coulomb friction {told}, {' and '.join(loose)} not determined by the data"
    return f"Coulomb friction {told}"


def axis_headline(r: AxisResult, validation_source: str | None = None) -> AxisHeadline:
    """The answer for axis ``r``: identified what, held-out fit, missing physics, what to do."""
    bw = tracking_bandwidth_hz(r)
    ident = (f"the closed-loop drive model of eq. 3.3 (tracking and disturbance transfer functions, "
             f"{_friction_words(r)}): tracking bandwidth "
             + (f"{bw:.3g} Hz (−3 dB)" if bw else
                f"above the Nyquist frequency ({0.5 / r.sample_period:.3g} Hz): the tracking gain stays within 3 dB "
                f"of its low-frequency gain up to there"))
    if r.uncertainty is not None and r.uncertainty.is_equivalent:
        ident += ("; an equivalent model: it reproduces the tracking response the recording excites, not the "
                  "drive's physical gains (which parameters the data do not determine: see the parameter table)")
    if r.prior_source:  # --model: a saved model checked on this recording, not re-identified
        ident = f"nothing new: {saved_model_words(r)}, checked on this recording — " + ident
    if r.shift:
        ident += f", {_shift_words(r)}"
    band = supported_band_hz(r)
    if band is not None:
        ident += (f"; the recording carries information on the response up to {band:.3g} Hz (coherence ≥ "
                  f"{COHERENT} of the estimate from the data): above that the data do not check the model")
    d = r.diagnosis
    accepted = _accepted(r) if d is not None else {}
    fv, fi = r.fit_validation, r.fit_identification
    if fv is not None:
        where = f" on {validation_source}" if validation_source else " on the validation recording"
        held = _held_out_words(fv, r.validation_traces, where)
        fig = fv.tracking_error_fit_pct
    elif r.prior_source and not r.prior_on_its_own_data:  # identified on other data: these are held out
        held = _held_out_words(fi, r.traces, f" on this recording, which the model of {r.prior_source} was not "
                               f"identified on")
        fig = fi.tracking_error_fit_pct
    elif r.prior_source:
        held = (f"the model of {r.prior_source} was identified on this recording: its fit here, which is not held "
                f"out, is {fi.tracking_error_fit_pct:.2f} % (prediction error {_um(fi.tracking_error_rms_mm)} rms); "
                f"pass another recording to check it")
        fig = None
    else:
        held = (f"no held-out recording (pass --validate): the fit on the identification recording, which is not "
                f"held out, is {fi.tracking_error_fit_pct:.2f} % (prediction error {_um(fi.tracking_error_rms_mm)} rms)")
        fig = None
    if accepted and d is not None and math.isfinite(d.fit_after_pct):
        scheme = (d.augmented_model or {}).get("held_out", "")
        name = HELD_OUT if scheme == "validation recording" else "cross-validated fit"
        held += (f"; with the diagnosed physics added (what the virtual machine runs) the {name} is "
                 f"{d.fit_after_pct:.2f} %")
    elif r.refit_predicts_better:
        controller = (d.augmented_model or {}).get("controller", "continuous").replace("_", " ")
        held += (f"; the diagnosis's re-fit of eq. 3.3 on a {controller} control law predicts it better, "
                 f"{d.fit_after_pct:.2f} %: the virtual machine runs that")
    if d is None:
        missing = "not looked for (the diagnosis was switched off)"
    elif not accepted:
        missing = _nothing_missing(r)
    else:
        unresolved = {c.effect: c.unresolved for c in getattr(d, "candidates", []) or []
                      if c.accepted and getattr(c, "unresolved", None)}
        missing = "; ".join(_effect_words(e, p, unresolved.get(e)) for e, p in accepted.items())
    action = _action(r, accepted, fig)
    return AxisHeadline(r.axis, ident, held, missing, action, fig)


def _nothing_missing(r: AxisResult) -> str:
    """The missing physics when the diagnosis accepted no effect: it tried all but a saved model's own."""
    carried = _carried(r)
    tried = ", ".join(e.words for name, e in REGISTRY.items() if name not in carried)
    head = (f"nothing beyond the {', '.join(REGISTRY[e].words for e in carried)} the model of {r.prior_source} "
            f"carries: no other effect" if carried else "nothing the data can show: no effect")
    return f"{head} the diagnosis knows ({tried}) improves the held-out prediction by more than chance"


def _action(r: AxisResult, accepted: dict, fig: float | None) -> str:
    steps = []
    if fig is None:
        steps.append("record a second run of another seed (agent generate --seed N) and identify with --validate "
                     "to see how well the model predicts data it was not fitted to")
    elif fig < 90.0 and not accepted:
        steps.append("the model misses much of the held-out data and no known effect explains it: check that both "
                     "recordings come from the same machine and settings, in mm and s, and read the diagnosis below")
    for e, p in accepted.items():
        if e == "backlash" and "gap_mm" in p:
            steps.append(f"{_ACTIONS[e]} ({p['gap_mm'] * 1e3:.3g} µm)")
        elif e == "time_delay" and p.get("where") == "capture":
            steps.append("the delay is the capture's, not the machine's: nothing to fix")
        elif e in _ACTIONS:
            steps.append(_ACTIONS[e])
    if accepted:
        steps.append("the virtual machine (agent simulate / predict / ballbar --machine RESULT.json) already "
                     "includes what was found")
    elif fig is not None and fig >= 90.0 and r.prior_source:
        steps.append(f"nothing to fix: the model of {r.prior_source} still holds; keep using it as the virtual "
                     f"machine (agent predict / simulate / ballbar --machine {r.prior_source})")
    elif fig is not None and fig >= 90.0:
        steps.append("nothing to fix: use the model as the virtual machine (agent predict / simulate / ballbar "
                     "--machine RESULT.json, the file --json wrote)")
    return "; ".join(steps)


def _shift_words(r: AxisResult) -> str:
    ms = abs(r.shift) * r.sample_period * 1e3
    n = abs(r.shift)
    samples = "sample" if n == 1 else "samples"
    if r.shift < 0:
        return (f"a dead time of {ms:.3g} ms (preview shift {r.shift} {samples}: the axis responds as if each command "
                f"arrived {n} {samples} later than recorded — a delay in the drive or the capture)")
    return (f"a preview of {ms:.3g} ms (preview shift +{r.shift} {samples}: the drive acts on each command "
            f"{n} {samples} before it is recorded, as a feed-forward with look-ahead does)")


def term_notes(r: AxisResult) -> list[str]:
    """Plain words for the terms of the model table that need them (empty when none applies)."""
    notes = []
    if r.shift:
        notes.append(_shift_words(r)[0].upper() + _shift_words(r)[1:] + ". The model is fitted and simulated with "
                     "this shift; the frequency-response plot includes it.")
    f_max = r.bounds.f_max_hz_for(r.sample_period)
    # eq. 3.8 bounds ω_n, so an over-damped pair can put one real pole beyond f_max: neither is determined
    at_bound = [f for f, _ in r.model.poles() if f_max and f > (1 - 1e-3) * f_max]
    if at_bound:
        where = "sits on" if at_bound[0] < (1 + 1e-3) * f_max else "lies beyond"
        notes.append(f"A pole at {at_bound[0]:.4g} Hz {where} the upper bound f_max = {f_max:.4g} Hz (the Nyquist "
                     f"frequency unless set): the recording does not determine it — it stands for “faster than the "
                     f"data can show”. The model is then an equivalent of the drive over the frequencies the "
                     f"commands contain, not its physical parameters (the thesis's P-PI drive, Table 3.3, showed "
                     f"the same).")
    rhp = [(f, z) for f, z in r.model.zeros() if z < 0]
    if rhp:
        f, z = rhp[0]
        kind = "a real zero" if abs(z + 1.0) < 1e-6 else "a pair of zeros"
        tail = (" It lies above the Nyquist frequency: it has no other effect the recording can show."
                if f > 0.5 / r.sample_period else "")
        notes.append(f"ζ {z:.2f} on the {f:.4g} Hz zero marks {kind} in the right half-plane (non-minimum phase): "
                     f"below {f:.4g} Hz it acts like a dead time of about {1e3 / (2 * math.pi * f):.2g} ms — the "
                     f"model's way of representing a small delay in the drive or the capture.{tail}")
    cancel = [(p, z) for p, zp in r.model.poles() for z, zz in r.model.zeros()
              if abs(p - z) < 0.02 * p and abs(zp - zz) < 0.05]
    if cancel:
        p, z = cancel[0]
        notes.append(f"The pole at {p:.3g} Hz and the zero at {z:.3g} Hz nearly cancel: together they add only a "
                     f"small component that settles at that rate (integral action, or friction the model spreads "
                     f"over time), and the data determine their frequency only weakly.")
    return notes


def result_headlines(result: IdentifyResult) -> list[AxisHeadline]:
    """:func:`axis_headline` of every axis of ``result``."""
    return [axis_headline(r, result.validation_source) for r in result.axes.values()]


def comparison_words(r: AxisResult, against_source: str | None = None) -> str | None:
    """What ``--against SIM`` compared, in words (None when the diagnosis compared with the model)."""
    loc = getattr(r.diagnosis, "mismatch", None) or {}
    if loc.get("compared_with") != "simulated recording":
        return None
    name = against_source or "the simulated recording"
    return (f"compared with {name} (--against): that simulated recording reproduces this recording's tracking "
            f"error with a fit of {loc.get('fit_pct', float('nan')):.2f} % (the same tracking-error fit with the simulated "
            f"recording in place of the model's free run); the diagnosis locates the mismatch on their difference")

"""A self-contained HTML report of an identification (figures embedded as PNG).

Figures follow the thesis: tracking and disturbance Bode plots (Figs 3.5, 3.8, 3.10),
commanded / actual / simulated position (Fig 3.4), measured vs simulated tracking error,
and, for a two-axis recording, predicted vs measured contour error (Figs 3.6, 3.7,
4.9, 4.10); then the diagnosis: where the residual concentrates and the fit before and
after the left-out physics is added.
"""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np

from ident.frf_estimate import h1_estimate
from ident.headline import COHERENT, HELD_OUT, THESIS, axis_headline, comparison_words, term_notes
from ident.html_page import page, png, pyplot, table, write_html
from ident.model import BASE_KEYS
from ident.results import AxisResult, AxisTraces, IdentifyResult

__all__ = ["write_report", "render_report"]

_MAX_POINTS = 6000


def _decimate(*arrays: np.ndarray) -> list[np.ndarray]:
    n = len(arrays[0])
    step = max(1, int(math.ceil(n / _MAX_POINTS)))
    return [a[::step] for a in arrays]


def _bode(r: AxisResult) -> str:
    """Tracking and disturbance responses of the final and the equation-error model, each with the
    preview shift it was fitted with (a delay e^(−jωτ) for a negative shift), and beside the
    tracking response the H1 estimate from the recording itself (ident.frf_estimate) with its
    coherence: where γ² is low the excitation carried no information and the model is unchecked."""
    plt = pyplot()
    nyq = 0.5 / r.sample_period
    f = np.logspace(-1, math.log10(nyq), 400)
    shift = np.exp(2j * np.pi * f * r.shift * r.sample_period)
    fig, ax = plt.subplots(3, 2, figsize=(11, 8), sharex=True, gridspec_kw={"height_ratios": [3, 3, 1.6]})
    est = None
    if r.traces is not None:
        tr = r.traces
        est = h1_estimate(tr.commanded, tr.actual, 1.0 / r.sample_period, segment=tr.segment)
    if est is not None:
        good = est.coherence >= COHERENT
        # the estimate's phase on the final model's branch (±360°), so a delay's long phase lag reads as one curve
        ref = np.degrees(np.unwrap(np.angle(r.model.freqresp(est.f)[0] * np.exp(
            2j * np.pi * est.f * r.shift * r.sample_period))))
        ph_est = np.degrees(np.angle(est.H))
        ph_est += 360.0 * np.round((ref - ph_est) / 360.0)
        for sel, color, label in ((good, "k", f"from the recording (H1, γ² ≥ {COHERENT})"),
                                  (~good, "0.7", f"from the recording, γ² < {COHERENT}: no information")):
            ax[0, 0].semilogx(est.f[sel], 20 * np.log10(np.abs(est.H[sel])), ".", ms=3, color=color, label=label)
            ax[1, 0].semilogx(est.f[sel], ph_est[sel], ".", ms=3, color=color)
        ax[2, 0].semilogx(est.f, est.coherence, color="k", lw=0.8)
        ax[2, 0].axhline(COHERENT, color="0.6", lw=0.6, ls=":")
        ax[2, 0].set_ylim(0, 1.05)
        ax[2, 0].set_ylabel("coherence γ²")
    shift_words = f", preview shift {r.shift} samples" if r.shift else ""
    models = [("final model" + shift_words, r.model, "C0", "-"),
              ("equation-error (constrained)" + shift_words, r.constrained.model, "C1", "--")]
    for label, m, color, ls in models:
        H, D = m.freqresp(f)
        H = H * shift
        ph = np.degrees(np.unwrap(np.angle(H)))
        ax[0, 0].semilogx(f, 20 * np.log10(np.abs(H)), color=color, ls=ls, label=label)
        ax[1, 0].semilogx(f, ph, color=color, ls=ls)
        ax[0, 1].semilogx(f, 20 * np.log10(np.abs(D) + 1e-300), color=color, ls=ls, label=label)
        ax[1, 1].semilogx(f, np.degrees(np.unwrap(np.angle(D))), color=color, ls=ls)
    ax[0, 0].set_title("tracking  G_track = x / x_r")
    ax[0, 1].set_title("disturbance  G_dist = x / d")
    ax[0, 0].set_ylabel("magnitude [dB]")
    ax[0, 1].set_ylabel("magnitude [dB re mm/(mm/s²)]")
    for a in ax[1]:
        a.set_ylabel("phase [deg]")
    ax[2, 0].set_xlabel("frequency [Hz]")
    ax[2, 1].axis("off")
    ax[1, 1].tick_params(labelbottom=True)  # its shared axis below is hidden
    ax[1, 1].set_xlabel("frequency [Hz]")
    ax[2, 1].text(0.0, 0.5, "The disturbance response cannot be estimated from commanded\nand actual "
                  "position alone: the friction force is not recorded.", fontsize=8, va="center",
                  transform=ax[2, 1].transAxes)
    if est is None:
        ax[2, 0].axis("off")
        ax[2, 0].text(0.0, 0.5, "no estimate from the recording: too short for one window", fontsize=8,
                      transform=ax[2, 0].transAxes)
    for a in ax[:2].flat:
        a.grid(True, which="both", alpha=0.3)
    ax[2, 0].grid(True, which="both", alpha=0.3)
    ax[0, 0].set_ylim(bottom=max(ax[0, 0].get_ylim()[0], -60))
    ax[0, 0].legend(fontsize=7, loc="lower left")
    fig.suptitle(f"axis {r.axis}: frequency responses")
    alt = (f"Frequency response of axis {r.axis}: tracking magnitude and phase of the final and the equation-error "
           f"model{shift_words}" + (", with the H1 estimate from the recording and its coherence" if est else "")
           + "; disturbance magnitude and phase of both models.")
    return png(fig, alt)


def _time_plots(tr: AxisTraces, title: str) -> str:
    plt = pyplot()
    e = tr.commanded - tr.actual
    e_hat = tr.commanded - tr.simulated
    t, xr, x, xs, e_d, eh_d = _decimate(tr.t, tr.commanded, tr.actual, tr.simulated, e, e_hat)
    fig, ax = plt.subplots(3, 1, figsize=(11, 8))
    ax[0].plot(t, xr, label="commanded", lw=0.8)
    ax[0].plot(t, x, label="actual (recorded)", lw=0.8)
    ax[0].plot(t, xs, "--", label="simulated (model)", lw=0.8)
    ax[0].set_ylabel("position [mm]")
    ax[0].legend(fontsize=8, loc="upper right")
    ax[1].plot(t, e_d * 1e3, label="measured e = x_r − x", lw=0.7)
    ax[1].plot(t, eh_d * 1e3, "--", label="simulated ê = x_r − x̂", lw=0.7)
    ax[1].set_ylabel("tracking error [µm]")
    ax[1].legend(fontsize=8, loc="upper right")
    # a zoom on the busiest second: the largest error change
    n = len(tr.t)
    w = min(n, int(round(1.0 / max(tr.t[1] - tr.t[0], 1e-9))) if n > 1 else n)
    if n > w > 0:
        k = int(np.argmax(np.convolve(np.abs(np.diff(e, prepend=e[0])), np.ones(w), "valid")))
    else:
        k = 0
    sl = slice(k, k + w)
    ax[2].plot(tr.t[sl], e[sl] * 1e3, label="measured", lw=0.9)
    ax[2].plot(tr.t[sl], e_hat[sl] * 1e3, "--", label="simulated", lw=0.9)
    ax[2].plot(tr.t[sl], (e[sl] - e_hat[sl]) * 1e3, ":", label="residual e − ê", lw=0.9)
    ax[2].set_ylabel("tracking error [µm]")
    ax[2].set_xlabel("time [s]")
    ax[2].set_title("zoom: the most active second", fontsize=9)
    ax[2].legend(fontsize=8, loc="upper right")
    for a in ax:
        a.grid(True, alpha=0.3)
    fig.suptitle(title)
    return png(fig, f"{title}: commanded, recorded and simulated position; measured and simulated tracking "
                    f"error; a one-second zoom with the residual e − ê.")


def _contour_plot(result: IdentifyResult) -> str:
    c = result.contour
    plt = pyplot()
    t, m, p = _decimate(c.t, c.measured, c.predicted)
    fig, ax = plt.subplots(1, 1, figsize=(11, 3.5))
    ax.plot(t, m * 1e3, label="measured", lw=0.8)
    ax.plot(t, p * 1e3, "--", label="predicted by the model", lw=0.8)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("contour error [µm]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(f"contour error, axes {'/'.join(c.axes)} ({c.source} recording)")
    return png(fig, f"Contour error of axes {'/'.join(c.axes)} against time on the {c.source} recording: "
                    f"measured and predicted by the model.")


def _diagnosis_plots(r: AxisResult) -> str:
    """Residual before / after the accepted effects; drawn only when an effect was accepted
    (otherwise both curves are the same model's)."""
    d = r.diagnosis
    traces = getattr(d, "traces", None) or {}
    accepted = [e for e in (d.augmented_model or {}).get("effects", {})]
    if not accepted:
        return ""
    names = " and ".join(e.replace("_", " ") for e in accepted)
    out = []
    plt = pyplot()
    t = traces.get("t")
    if t is not None and "residual_before" in traces:
        keys = [k for k in ("residual_before", "residual_after") if k in traces]
        arrays = _decimate(t, *[traces[k] for k in keys])
        labels = {"residual_before": "reference model (eq. 3.3 re-fitted)", "residual_after": f"with {names}"}
        fig, ax = plt.subplots(1, 1, figsize=(11, 3.5))
        for k, a in zip(keys, arrays[1:]):
            ax.plot(arrays[0], a * 1e3, lw=0.7, label=labels[k])
        ax.set_xlabel("time [s]")
        ax.set_ylabel("residual x̂ − x [µm]")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
        ax.set_title(f"axis {r.axis}: residual before / after {names} is added (identification recording)")
        out.append(png(fig, f"Residual of axis {r.axis} against time on the identification recording, before and "
                            f"after {names} is added to the model."))
    # the residual where the base model misses most, on the held-out (validation) recording when there is one
    pre = "validation_" if "validation_x_hat_after" in traces else ""
    keys = [pre + k for k in ("t", "x_r", "x", "x_hat_before", "x_hat_after")]
    if all(k in traces for k in keys):
        tt, xr, x, xb, xa = (np.asarray(traces[k]) for k in keys)
        # residuals e − ê = x̂ − x, µm: the tracking error itself is mm-sized and would hide them
        rb, ra = (xb - x) * 1e3, (xa - x) * 1e3
        n = len(tt)
        w = min(n, 300)
        gain = np.abs(rb) - np.abs(ra)
        k = int(np.argmax(np.convolve(gain, np.ones(w), "valid"))) if n > w else 0
        sl = slice(k, k + w)
        fig, ax = plt.subplots(1, 1, figsize=(11, 3.5))
        ax.plot(tt[sl], rb[sl], label="reference model (eq. 3.3 re-fitted)", lw=0.9)
        ax.plot(tt[sl], ra[sl], label=f"with {names}", lw=0.9)
        ax.axhline(0, color="k", lw=0.5)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("residual x̂ − x [µm]")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
        where = "validation recording" if pre else "identification recording"
        ax.set_title(f"axis {r.axis}: residual where {names} helps most ({where}, zoom)")
        out.append(png(fig, f"Zoom on the {w * r.sample_period:.2g} s of the {where} where {names} reduces the "
                            f"residual of axis {r.axis} most: residual before and after."))
    return "\n".join(out)


def _g(v: float) -> str:
    return "n/a" if v is None or not math.isfinite(v) else f"{v:.6g}"


def _fit_cell(v: float) -> str:
    """A fit %: a model whose free run diverged has a residual many times the signal
    (fits like −1e89 %), which says less than the word."""
    return "diverged" if v is not None and math.isfinite(v) and v < -1000.0 else _g(v)


def _param_text(v) -> str:
    """A candidate parameter: a number, a range of numbers ("lo–hi") or a word."""
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return _g(v)
    if isinstance(v, (list, tuple)) and v and all(isinstance(w, (int, float)) for w in v):
        return "–".join(dict.fromkeys(_g(w) for w in v))  # a range of one value prints once
    return str(v)


def _interval_section(r: AxisResult) -> str:
    """The search variables with their 95 % interval and mark, and whether the model is an equivalent one
    (the intervals of eq. 3.3's parameters, poles and zeros are in their own tables)."""
    u = r.uncertainty
    if u is None:
        return ""
    verdict = "equivalent" if u.is_equivalent else "physical"
    rows = [row for row in u.rows() if row[0] in u.parameters and row[0] not in _PARAM_MEANING]
    return ("<h3>Search variables (95 % intervals) and what the model is</h3>"
            + table(rows, header=("quantity", "value", "95 % interval", "mark"))
            + f"<p class='{verdict}'>{html.escape(u.equivalent_text())}</p>"
            + f"<p>Intervals from the output-error fit's Jacobian; the residual is correlated, so "
              f"{u.n_samples} samples count as about {u.effective_samples:.0f} independent ones "
              f"(blocks of {u.block_length} samples).</p>")


def _f(v, scale: float = 1.0, fmt: str = ".3g") -> str:
    return "n/a" if v is None or not isinstance(v, (int, float)) or not math.isfinite(v) else format(v * scale, fmt)


def _bins(rows: list[dict], lo: str, hi: str, unit: str, scale: float = 1.0) -> list[tuple]:
    """Localisation bins as table rows: range, share of time, share of residual energy, rms µm."""
    out = []
    for b in rows:
        top = b.get(hi)
        rng = f"{_f(b.get(lo), scale)} – {_f(top, scale)} {unit}" if top is not None else f"≥ {_f(b.get(lo), scale)} {unit}"
        out.append((rng, f"{100 * b.get('time_share', 0.0):.0f} %", f"{100 * b.get('energy_share', 0.0):.0f} %",
                    _f(b.get("rms_mm"), 1e3)))
    return out


def _localisation(loc: dict, title: str) -> str:
    """Where the residual concentrates, as tables in µm and s (the JSON holds the same in mm)."""
    parts = [f"<h4>{html.escape(title)}</h4>"]
    # the residual of the diagnosis's reference model, or of the --against recording (whose fit the headline gives)
    against = loc.get("compared_with") == "simulated recording"
    facts = [("residual of", "the simulated recording (--against)" if against
              else "the reference model (eq. 3.3 re-fitted by the diagnosis)"),
             ("residual rms", f"{_f(loc.get('rms_mm'), 1e3)} µm"),
             ("reversals", str(loc.get("reversals", "n/a"))),
             ("share of residual energy within 30 ms after a reversal",
              f"{100 * loc.get('after_reversal_30ms_share', 0.0):.0f} % (in {100 * loc.get('after_reversal_30ms_time_share', 0.0):.0f} % of the time)")]
    if "noise_floor_mm" in loc:
        facts.append(("measurement noise floor", f"{_f(loc['noise_floor_mm'], 1e3)} µm"))
    parts.append(table([(k, v) for k, v in facts if "n/a" not in v or k == "reversals"]))
    win = loc.get("worst_windows") or []
    if win:
        parts.append(table([(f"{w['t_start_s']:.3f} – {w['t_end_s']:.3f}", f"{100 * w['energy_share']:.0f} %",
                             _f(w.get("rms_mm"), 1e3)) for w in win],
                           ("worst windows, t (s)", "share of residual energy", "rms (µm)")))
    for key, lo, hi, unit, scale, name in (("by_speed", "from_mm_s", "to_mm_s", "mm/s", 1.0, "commanded speed"),
                                           ("by_time_since_reversal", "from_s", "to_s", "ms", 1e3, "time since a reversal"),
                                           ("by_acceleration", "from_mm_s2", "to_mm_s2", "mm/s²", 1.0, "commanded acceleration")):
        if loc.get(key):
            parts.append(table(_bins(loc[key], lo, hi, unit, scale),
                               (name, "share of time", "share of residual energy", "rms (µm)")))
    peaks = loc.get("spectrum_peaks") or []
    if peaks:
        parts.append(table([(f"{p['freq_hz']:.3g}", f"{100 * p['power_share']:.0f} %") for p in peaks[:5]],
                           ("residual spectrum peak (Hz)", "share of residual power")))
    return "\n".join(parts)


_PARAM_MEANING = {
    "a1": "denominator s² coefficient (1/s)", "a2": "denominator s coefficient (1/s²)",
    "a3": "integral action (1/s³)", "b0": "feed-forward of acceleration (–)",
    "b1": "feed-forward of velocity (1/s)", "b2": "position gain (1/s²)",
    "d0": "Coulomb friction, positive speed (mm/s², control-equivalent)",
    "d1": "Coulomb friction, negative speed (mm/s², control-equivalent)",
}


def _parameter_table(r: AxisResult) -> str:
    """eq. 3.3's parameters, one row each, with their 95 % interval and mark when the fit gave one."""
    m, u = r.model, r.uncertainty
    rows = []
    for k in BASE_KEYS:
        row = (k, _g(getattr(m, k)))
        if u is not None and k in u.parameters:
            iv = u.parameters[k]
            row += (f"[{_g(iv.lo)}, {_g(iv.hi)}]", iv.mark())
        rows.append(row + (_PARAM_MEANING[k],))
    header = ("parameter (eq. 3.3)", "value") + (("95 % interval", "mark") if u is not None else ()) + ("meaning",)
    return table(rows, header)


def _roots_table(r: AxisResult) -> str:
    """Poles and zeros with what each means for the machine, and their 95 % interval when there is one."""
    f_max = r.bounds.f_max_hz_for(r.sample_period)
    u = r.uncertainty
    rows = []
    for kind, roots, ivs in (("pole", r.model.poles(), u.poles if u else []),
                             ("zero", r.model.zeros(), u.zeros if u else [])):
        for i, (f, z) in enumerate(roots):
            note = ""
            if kind == "pole" and f_max and f > (1 - 1e-3) * f_max:
                note = "at or beyond the f_max bound: not determined by the data"
            elif z < 0:
                note = "right half-plane (non-minimum phase)"
            elif abs(z - 1.0) < 1e-9:
                note = "real"
            row = (kind, f"{f:.4g}", f"{z:.2f}")
            if u is not None:
                iv = ivs[i] if i < len(ivs) else None
                row += (("[{}, {}] Hz, ζ [{:.2f}, {:.2f}]".format(_g(iv.freq_hz_interval95[0]), _g(iv.freq_hz_interval95[1]),
                                                                  *iv.damping_interval95), iv.mark()) if iv else ("", ""))
            rows.append(row + (note,))
    header = ("", "frequency (Hz)", "damping ζ") + (("95 % interval", "mark") if u is not None else ()) + ("note",)
    return table(rows, header)


def _axis_section(r: AxisResult, result: IdentifyResult) -> str:
    parts = [f"<h2>Axis {html.escape(r.axis)}</h2>"]
    fit = r.fit_identification
    rows = []
    if r.fit_validation is not None:
        fv = r.fit_validation
        rows.append(("held-out fit (validation recording)",
                     f"{fv.tracking_error_fit_pct:.2f} % (prediction error rms {fv.tracking_error_rms_mm * 1e3:.2f} µm)"))
    rows += [(f"fit of the model of {r.prior_source} on this recording, which it was identified on (not held out)"
              if r.prior_on_its_own_data
              else f"{HELD_OUT} of the model of {r.prior_source} (this recording)" if r.prior_source
              else "fit on the identification recording (not held out)",
              f"{fit.tracking_error_fit_pct:.2f} % (prediction error rms {fit.tracking_error_rms_mm * 1e3:.2f} µm)"),
             ("equation-error model before refinement (identification recording)",
              f"{r.fit_constrained.tracking_error_fit_pct:.2f} %"),
             ("solver", r.constrained.solver + (" + output-error refinement" if r.refined else "")),
             ("active constraints", ", ".join(r.active_constraints) or "none"),
             ("preview shift", f"{r.shift} samples ({r.shift * r.sample_period * 1e3:+.3g} ms)"),
             ("time", ", ".join(f"{k} {v:.2f} s" for k, v in r.timings.items()))]
    parts.append(table(rows))
    parts.append("<p class='cite'>Every fit is the tracking-error fit % = 100·(1 − ‖e − ê‖/‖e − mean(e)‖) of "
                 "docs/identification.md, e = x_r − x recorded, ê from the model's free run on the command alone.</p>")
    parts.append(_parameter_table(r))
    parts.append(_roots_table(r))
    notes = term_notes(r)
    if notes:
        parts.append("<ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in notes) + "</ul>")
    parts.append(_interval_section(r))
    parts.append("<h3>What unconstrained least squares gives, and why the constraints matter</h3>")
    parts.append(f"<p>{html.escape(r.unconstrained_note)}</p>")
    parts.append(_bode(r))
    if r.traces is not None:
        parts.append(_time_plots(r.traces, f"axis {r.axis}: identification recording"))
    if r.validation_traces is not None:
        parts.append(_time_plots(r.validation_traces, f"axis {r.axis}: validation recording"))
    if r.diagnosis is not None:
        parts.append(_diagnosis_section(r, result))
    return "\n".join(parts)


def _diagnosis_section(r: AxisResult, result: IdentifyResult) -> str:
    d = r.diagnosis
    dd = d.to_dict()
    parts = ["<h3>Diagnosis</h3>"]
    cmp = comparison_words(r, result.metadata.get("against"))
    if cmp:
        parts.append(f"<p><b>{html.escape(cmp[0].upper() + cmp[1:])}.</b></p>")
    parts.append(f"<p>{html.escape(d.summary)}</p>")
    parts.append("<p class='cite'>The diagnosis weighs every effect against a <i>reference</i>: eq. 3.3 re-fitted "
                 "in free run (with the controller variant that fits best), scored on the held-out data "
                 f"({html.escape(str(dd.get('augmented_model', {}).get('held_out', 'held out')))}). Its "
                 "<i>reference fit</i> is the same metric for that model, so it can differ from the held-out fit "
                 "of the identified model above.</p>")
    cand_rows = []
    for c in dd.get("candidates", []):
        params = ", ".join(f"{k} = {_param_text(v)}" for k, v in c.get("parameters", {}).items())
        cand_rows.append((str(c.get("effect")).replace("_", " "), params, _fit_cell(c.get("fit_before_pct")),
                          _fit_cell(c.get("fit_after_pct")), "yes" if c.get("accepted") else "no"))
    if cand_rows:
        parts.append(table(cand_rows, ("effect", "parameters", "reference fit %", "with the effect %", "accepted")))
    parts.append("<details><summary>where the residual concentrates (localisation)</summary>"
                 + _localisation(dd.get("mismatch", {}), "identification recording")
                 + (_localisation(dd["mismatch_validation"], "validation recording")
                    if dd.get("mismatch_validation") else "") + "</details>")
    parts.append(_diagnosis_plots(r))
    return "\n".join(parts)


def _headline(result: IdentifyResult) -> str:
    """The answer first: per axis, identified what, held-out fit, missing physics, what to do."""
    out = []
    for r in result.axes.values():
        h = axis_headline(r, result.validation_source)
        items = [("Identified", h.identified), ("Predicts held-out data", h.held_out)]
        cmp = comparison_words(r, result.metadata.get("against"))
        if cmp:
            items.append(("Compared", cmp))
        items += [("Missing physics", h.missing), ("What to do", h.action)]
        body = "".join(f"<dt>{html.escape(k)}</dt><dd>{html.escape(v)}.</dd>" for k, v in items)
        out.append(f"<div class='headline'><h2>Axis {html.escape(r.axis)}</h2><dl>{body}</dl></div>")
    return "\n".join(out)


def render_report(result: IdentifyResult) -> str:
    """The report as one HTML string: the answer (headline) first, then the evidence."""
    rec_rows = [("recording", result.source), ("validation", result.validation_source or "none")]
    if result.metadata.get("against"):
        rec_rows.append(("compared with (--against)", str(result.metadata["against"])))
    rec_rows += [("controller", str(result.metadata.get("controller", "unknown"))),
                 ("transport", str(result.metadata.get("transport", "unknown"))),
                 ("programs", ", ".join(p.get("name", "?") for p in result.metadata.get("programs", []) or []
                                        if isinstance(p, dict)) or "unknown"),
                 ("total time", f"{result.elapsed_s:.2f} s")]
    head = ["<h1>rapid-ident: drive identification</h1>", _headline(result),
            f"<p class='cite'>Model and method: {html.escape(THESIS)}.</p>", table(rec_rows)]
    body = [_axis_section(r, result) for r in result.axes.values()]
    if result.contour is not None:
        c = result.contour.to_dict()
        body.append("<h2>Contour error</h2>")
        body.append(table([("measured max", f"{c['measured']['max_abs_mm'] * 1e3:.2f} µm"),
                            ("predicted max", f"{c['predicted']['max_abs_mm'] * 1e3:.2f} µm"),
                            ("prediction error rms", f"{c['prediction_error']['rms_mm'] * 1e3:.2f} µm")]))
        body.append(_contour_plot(result))
    return page("rapid-ident report", head + body)


def write_report(result: IdentifyResult, path: str | Path) -> Path:
    """Write the report to ``path`` (one self-contained .html file)."""
    return write_html(render_report(result), path)

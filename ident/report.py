"""A self-contained HTML report of an identification (figures embedded as PNG).

Figures follow the thesis: tracking and disturbance Bode plots (Figs 3.5, 3.8, 3.10),
commanded / actual / simulated position (Fig 3.4), measured vs simulated tracking error,
and, for a two-axis recording, predicted vs measured contour error (Figs 3.6, 3.7,
4.9, 4.10); then the diagnosis: where the residual concentrates and the fit before and
after the left-out physics is added.
"""

from __future__ import annotations

import html
import json
import math
from pathlib import Path

import numpy as np

from ident.html_page import page, png, pyplot, table, write_html
from ident.results import AxisResult, AxisTraces, IdentifyResult

__all__ = ["write_report", "render_report"]

_MAX_POINTS = 6000


def _decimate(*arrays: np.ndarray) -> list[np.ndarray]:
    n = len(arrays[0])
    step = max(1, int(math.ceil(n / _MAX_POINTS)))
    return [a[::step] for a in arrays]


def _bode(r: AxisResult) -> str:
    plt = pyplot()
    nyq = 0.5 / r.sample_period
    f = np.logspace(-1, math.log10(nyq), 400)
    fig, ax = plt.subplots(2, 2, figsize=(11, 6), sharex=True)
    models = [("final model", r.model, "C0", "-"), ("equation-error (constrained)", r.constrained.model, "C1", "--")]
    for label, m, color, ls in models:
        H, D = m.freqresp(f)
        ax[0, 0].semilogx(f, 20 * np.log10(np.abs(H)), color=color, ls=ls, label=label)
        ax[1, 0].semilogx(f, np.degrees(np.unwrap(np.angle(H))), color=color, ls=ls)
        ax[0, 1].semilogx(f, 20 * np.log10(np.abs(D) + 1e-300), color=color, ls=ls, label=label)
        ax[1, 1].semilogx(f, np.degrees(np.unwrap(np.angle(D))), color=color, ls=ls)
    ax[0, 0].set_title("tracking  G_track = x / x_r")
    ax[0, 1].set_title("disturbance  G_dist = x / d")
    ax[0, 0].set_ylabel("magnitude [dB]")
    ax[0, 1].set_ylabel("magnitude [dB re mm/(mm/s²)]")
    for a in ax[1]:
        a.set_xlabel("frequency [Hz]")
        a.set_ylabel("phase [deg]")
    for a in ax.flat:
        a.grid(True, which="both", alpha=0.3)
    ax[0, 0].legend(fontsize=8)
    fig.suptitle(f"axis {r.axis}: frequency responses")
    return png(fig)


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
    return png(fig)


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
    return png(fig)


def _diagnosis_plots(r: AxisResult) -> str:
    d = r.diagnosis
    traces = getattr(d, "traces", None) or {}
    out = []
    plt = pyplot()
    t = traces.get("t")
    if t is not None and "residual_before" in traces:
        keys = [k for k in ("residual_before", "residual_after") if k in traces]
        arrays = _decimate(t, *[traces[k] for k in keys])
        fig, ax = plt.subplots(1, 1, figsize=(11, 3.5))
        for k, a in zip(keys, arrays[1:]):
            ax.plot(arrays[0], a * 1e3, lw=0.7, label=k.replace("_", " "))
        ax.set_xlabel("time [s]")
        ax.set_ylabel("residual e − ê [µm]")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
        ax.set_title(f"axis {r.axis}: residual before / after the diagnosed physics is added")
        out.append(png(fig))
    # Before/after overlay of the tracking error where the base model misses most,
    # on the held-out (validation) recording when there is one.
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
        ax.plot(tt[sl], rb[sl], label="base model", lw=0.9)
        ax.plot(tt[sl], ra[sl], label="with the diagnosed physics", lw=0.9)
        ax.axhline(0, color="k", lw=0.5)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("residual e − ê [µm]")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
        where = "validation recording" if pre else "identification recording"
        ax.set_title(f"axis {r.axis}: residual where the added physics helps most ({where}, zoom)")
        out.append(png(fig))
    return "\n".join(out)


def _g(v: float) -> str:
    return "n/a" if v is None or not math.isfinite(v) else f"{v:.6g}"


def _fit_cell(v: float) -> str:
    """A held-out fit %: a model whose free run diverged has a residual many times the signal
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
    """Each parameter, pole and zero with its 95 % interval and 'at bound' / 'not determined' mark."""
    u = r.uncertainty
    if u is None:
        return ""
    verdict = "equivalent" if u.is_equivalent else "physical"
    return ("<h3>How well the data determine each parameter (95 % intervals)</h3>"
            + table(u.rows(), header=("quantity", "value", "95 % interval", "mark"))
            + f"<p class='{verdict}'>{html.escape(u.equivalent_text())}</p>"
            + f"<p>Intervals from the output-error fit's Jacobian; the residual is correlated, so "
              f"{u.n_samples} samples count as about {u.effective_samples:.0f} independent ones "
              f"(blocks of {u.block_length} samples).</p>")


def _axis_section(r: AxisResult) -> str:
    m = r.model
    parts = [f"<h2>Axis {html.escape(r.axis)}</h2>"]
    fit = r.fit_identification
    rows = [("solver", r.constrained.solver + (" + output-error refinement" if r.refined else "")),
            ("tracking-error fit, identification", f"{fit.tracking_error_fit_pct:.2f} % (prediction error rms {fit.tracking_error_rms_mm * 1e3:.2f} µm)")]
    if r.fit_validation is not None:
        fv = r.fit_validation
        rows.append(("tracking-error fit, validation", f"{fv.tracking_error_fit_pct:.2f} % (prediction error rms {fv.tracking_error_rms_mm * 1e3:.2f} µm)"))
    rows += [("equation-error model fit (before refinement)", f"{r.fit_constrained.tracking_error_fit_pct:.2f} %"),
             ("active constraints", ", ".join(r.active_constraints) or "none"),
             ("preview shift", f"{r.shift} samples"),
             ("model (eq. 3.3)", ", ".join(f"{k} = {_g(getattr(m, k))}" for k in ("a1", "a2", "a3", "b0", "b1", "b2", "d0", "d1"))),
             ("poles", "; ".join(f"{f:.2f} Hz, ζ {d:.2f}" for f, d in m.poles())),
             ("zeros", "; ".join(f"{f:.2f} Hz, ζ {d:.2f}" for f, d in m.zeros()) or "none"),
             ("time", ", ".join(f"{k} {v:.2f} s" for k, v in r.timings.items()))]
    parts.append(table(rows))
    parts.append(_interval_section(r))
    parts.append("<h3>What unconstrained least squares gives, and why the constraints matter</h3>")
    parts.append(f"<p>{html.escape(r.unconstrained_note)}</p>")
    parts.append(_bode(r))
    if r.traces is not None:
        parts.append(_time_plots(r.traces, f"axis {r.axis}: identification recording"))
    if r.validation_traces is not None:
        parts.append(_time_plots(r.validation_traces, f"axis {r.axis}: validation recording"))
    if r.diagnosis is not None:
        d = r.diagnosis
        parts.append("<h3>Diagnosis</h3>")
        parts.append(f"<p class='verdict'>{html.escape(d.summary)}</p>")
        dd = d.to_dict()
        cand_rows = []
        for c in dd.get("candidates", []):
            params = ", ".join(f"{k} = {_param_text(v)}" for k, v in c.get("parameters", {}).items())
            cand_rows.append(
                f"<tr><td>{html.escape(str(c.get('effect')))}</td><td>{html.escape(params)}</td>"
                f"<td>{_fit_cell(c.get('fit_before_pct'))}</td><td>{_fit_cell(c.get('fit_after_pct'))}</td>"
                f"<td>{'yes' if c.get('accepted') else 'no'}</td></tr>")
        if cand_rows:
            parts.append("<table><tr><th>effect</th><th>parameters</th><th>held-out fit before %</th>"
                         "<th>after %</th><th>accepted</th></tr>" + "".join(cand_rows) + "</table>")
        parts.append("<details><summary>where the residual concentrates (localisation)</summary><pre>"
                     + html.escape(json.dumps(dd.get("mismatch", {}), indent=1, default=str)[:20000]) + "</pre></details>")
        parts.append(_diagnosis_plots(r))
    return "\n".join(parts)


def render_report(result: IdentifyResult) -> str:
    """The report as one HTML string."""
    head = ["<h1>rapid-ident: drive identification</h1>",
            table([("recording", result.source), ("validation", result.validation_source or "none"),
                    ("controller", str(result.metadata.get("controller", "unknown"))),
                    ("transport", str(result.metadata.get("transport", "unknown"))),
                    ("programs", ", ".join(p.get("name", "?") for p in result.metadata.get("programs", []) or [] if isinstance(p, dict)) or "unknown"),
                    ("total time", f"{result.elapsed_s:.2f} s")])]
    body = [_axis_section(r) for r in result.axes.values()]
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

"""The HTML report of ``agent predict``: a part program on one or more virtual machines.

One column per machine (the thesis's use case: tune on the virtual machine, compare),
the figures a machinist asks for (max/rms contour error, where, at which feed), the
toolpath coloured by contour error, errors against time, the worst places by program
line, and, when a recording of the same motion is given, measured vs predicted.
"""

from __future__ import annotations

import html
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from ident.html_page import page, png, pyplot, table, write_html
from ident.model import BASE_KEYS
from ident.prediction import Comparison, PredictionSummary, line_number_words

__all__ = ["render_prediction_report", "write_prediction_report"]

_MAX_POINTS = 8000


def _um(v: float | None) -> str:
    return "n/a" if v is None or not math.isfinite(v) else f"{v * 1e3:.2f} µm"


def _step(n: int) -> int:
    return max(1, int(math.ceil(n / _MAX_POINTS)))


def _figures(summaries: Sequence[PredictionSummary]) -> str:
    header = ("figure",) + tuple(s.machine for s in summaries)
    rows = []
    if any(s.contour is not None for s in summaries):
        rows.append(("max contour error (feed moves)",) + tuple(_um(s.contour_max_mm) for s in summaries))
        rows.append(("rms contour error (feed moves)",) + tuple(_um(s.contour_rms_mm) for s in summaries))

        def where(s: PredictionSummary) -> str:
            if not s.worst:
                return "n/a"
            p = s.worst[0]
            pos = ", ".join(f"{a} {v:+.3f}" for a, v in p.position_mm.items())
            feed = f", feed {p.feed_mm_s:g} mm/s (path at {p.speed_mm_s:.3g} mm/s there)" if p.feed_mm_s else ""
            return f"{p.where}, t = {p.t_s:.3f} s, at {pos} mm{feed}"

        rows.append(("where the contour error is largest",) + tuple(where(s) for s in summaries))
    for axis in dict.fromkeys(a for s in summaries for a in s.tracking):
        rows.append((f"{axis} max tracking error (feed moves)",) + tuple(
            (f"{_um(s.tracking[axis].max_abs_mm)} at {s.tracking[axis].where}"
             if axis in s.tracking else "n/a") for s in summaries))
        rows.append((f"{axis} rms tracking error (feed moves)",) + tuple(
            _um(s.tracking[axis].rms_mm) if axis in s.tracking else "n/a" for s in summaries))
    return table(rows, header)


def _worst(s: PredictionSummary) -> str:
    rows = [(p.program, line_number_words(p.line, p.n), f"{p.t_s:.3f}",
             ", ".join(f"{a} {v:+.3f}" for a, v in p.position_mm.items()),
             "rapid" if p.feed_mm_s is None else f"{p.feed_mm_s:g}", f"{p.speed_mm_s:.3g}",
             f"{p.contour_error_mm * 1e3:.2f}")
            for p in s.worst]
    return table(rows, ("program", "line", "t (s)", "position (mm)", "feed (mm/s)", "path speed there (mm/s)",
                        "contour error (µm)"))


def _toolpath_plot(summaries: Sequence[PredictionSummary]) -> str:
    shown = [s for s in summaries if s.contour is not None and s.prediction is not None]
    if not shown:
        return ""
    plt = pyplot()
    fig, axs = plt.subplots(1, len(shown), figsize=(5.5 * len(shown), 5), squeeze=False)
    vmax = max(float(np.max(np.abs(s.contour[s.feed_move]), initial=0.0)) for s in shown) * 1e3 or 1.0
    for ax, s in zip(axs[0], shown):
        rec = s.prediction.recording
        a, b = s.axes[:2]
        k = np.flatnonzero(s.feed_move) if s.feed_move.any() else np.arange(rec.n_samples)
        k = k[::_step(k.size)]
        ax.plot(rec.axes[a].commanded, rec.axes[b].commanded, color="0.85", lw=0.8, zorder=0)
        sc = ax.scatter(rec.axes[a].commanded[k], rec.axes[b].commanded[k], c=np.abs(s.contour[k]) * 1e3,
                        s=4, cmap="viridis", vmin=0, vmax=vmax)
        # one label per program line, fanned out from its point so labels never sit on each other
        shown_lines = list({p.line: p for p in reversed(s.worst[:3])}.values())[::-1]
        for i, p in enumerate(shown_lines):
            ax.annotate(f"line {line_number_words(p.line, p.n)}", (p.position_mm[a], p.position_mm[b]),
                        xytext=(14, 14 - 16 * i),
                        textcoords="offset points", fontsize=8, color="C3",
                        bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.8),
                        arrowprops=dict(arrowstyle="-", color="C3", lw=0.6))
        ax.set_xlabel(f"{a} (mm)")
        ax.set_ylabel(f"{b} (mm)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(s.machine, fontsize=10)
    fig.colorbar(sc, ax=axs[0].tolist(), label="|contour error| (µm)")
    return png(fig, "Toolpath of " + "; ".join(s.machine for s in shown) + " in the plane of the first two axes, "
                    "coloured by the predicted |contour error|, with the worst program lines labelled.")


def _time_plot(summaries: Sequence[PredictionSummary]) -> str:
    shown = [s for s in summaries if s.prediction is not None]
    axes = list(dict.fromkeys(a for s in shown for a in s.axes))
    with_contour = any(s.contour is not None for s in shown)
    n = len(axes) + (1 if with_contour else 0)
    plt = pyplot()
    fig, axs = plt.subplots(n, 1, figsize=(11, 2.4 * n), sharex=True, squeeze=False)
    row = 0
    if with_contour:
        for i, s in enumerate(shown):
            if s.contour is not None:
                rec = s.prediction.recording
                k = slice(None, None, _step(rec.n_samples))
                _feed_and_other(axs[0, 0], rec.t[k], s.contour[k] * 1e3, s.feed_move[k], f"C{i}", s.machine)
        axs[0, 0].set_ylabel("contour error (µm)")
        axs[0, 0].legend(fontsize=8)
        row = 1
    for j, axis in enumerate(axes):
        for i, s in enumerate(shown):
            rec = s.prediction.recording
            if axis in rec.axes:
                k = slice(None, None, _step(rec.n_samples))
                _feed_and_other(axs[row + j, 0], rec.t[k], rec.axes[axis].tracking_error[k] * 1e3,
                                s.feed_move[k], f"C{i}")
        axs[row + j, 0].set_ylabel(f"{axis} tracking\nerror (µm)")
    axs[-1, 0].set_xlabel("time (s)")
    return png(fig, "Predicted " + ("contour error and " if with_contour else "") + "tracking error of axes "
                    + ", ".join(axes) + " against time, one colour per machine; in grey the rapids and dwells, "
                    "which the figures above do not count (they are taken over the feed moves, G1/G2/G3).")


def _feed_and_other(ax, t: np.ndarray, y: np.ndarray, feed: np.ndarray, color: str, label: str | None = None) -> None:
    """``y`` against ``t``: the feed-move samples in ``color``, the others (rapids, dwells) in grey."""
    ax.plot(t, y, color="0.75", lw=0.6)
    ax.plot(t, np.where(feed, y, np.nan), color=color, lw=0.8, label=label)


def _comparison(c: Comparison) -> str:
    d = c.to_dict()
    parts = [f"<h2>Measured vs predicted: {html.escape(c.source)}</h2>",
             "<p>The model is driven by the recording's own command, so the two stay in step.</p>",
             table([("measured max |contour error|", _um(d["measured_max_abs_mm"])),
                    ("predicted max |contour error|", _um(d["predicted_max_abs_mm"])),
                    ("predicted / measured max", f"{d['max_ratio']:.3f}"),
                    ("measured rms", _um(d["measured_rms_mm"])), ("predicted rms", _um(d["predicted_rms_mm"])),
                    ("rms of the difference / measured rms", f"{d['rms_difference_ratio'] * 100:.1f} %")])]
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(11, 3))
    k = slice(None, None, _step(c.t.size))
    ax.plot(c.t[k], np.where(c.mask, c.measured, np.nan)[k] * 1e3, color="k", lw=0.9, label="measured")
    ax.plot(c.t[k], np.where(c.mask, c.predicted, np.nan)[k] * 1e3, color="C3", lw=0.9, ls="--", label="predicted")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("contour error (µm)")
    ax.legend(fontsize=8)
    parts.append(png(fig, f"Contour error against time, measured on {c.source} and predicted by the model."))
    return "\n".join(parts)


def render_prediction_report(summaries: Sequence[PredictionSummary], comparisons: Sequence[Comparison] = (),
                             programs: Sequence[str] = ()) -> str:
    """The report as one HTML string."""
    parts = ["<h1>rapid-ident: predicted tracking and contour errors</h1>",
             table([("programs", ", ".join(programs) or "?"),
                    ("machines", "; ".join(s.machine for s in summaries)),
                    ("what this is", "the programs run on the identified drive models (eq. 3.3 and the effects the "
                                     "diagnosis accepted): a prediction, not a measurement")])]
    for s in summaries:
        for w in s.warnings:
            parts.append(f"<p class='warn'>{html.escape(s.machine)}: {html.escape(w)}</p>")
    parts += ["<h2>Figures</h2>", _figures(summaries)]
    parts.append(_toolpath_plot(summaries))
    parts.append(_time_plot(summaries))
    for s in summaries:
        if s.worst:
            parts += [f"<h3>Worst places on {html.escape(s.machine)}</h3>", _worst(s)]
    for c in comparisons:
        parts.append(_comparison(c))
    parts.append("<h2>Models</h2>")
    for s in summaries:
        if s.prediction is None:
            continue
        rows = []
        for axis, m in s.prediction.machine.axes.items():
            base = ", ".join(f"{k} = {getattr(m.model, k):.6g}" for k in BASE_KEYS)
            fx = "; ".join(f"{e}: " + ", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}"
                                              for k, v in p.items()) for e, p in m.effects.items())
            rows.append((axis, base + (f" — effects: {fx}" if fx else "")))
        parts += [f"<h3>{html.escape(s.machine)}</h3>", table(rows)]
    return page("rapid-ident prediction", parts)


def write_prediction_report(path: str | Path, summaries: Sequence[PredictionSummary],
                            comparisons: Sequence[Comparison] = (), programs: Sequence[str] = ()) -> Path:
    """Write the report to ``path`` (one self-contained .html file)."""
    return write_html(render_prediction_report(summaries, comparisons, programs), path)

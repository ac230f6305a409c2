"""The HTML report of ``agent ballbar``: polar plots, ISO 230-4 figures and their reading."""

from __future__ import annotations

import html
from pathlib import Path
from typing import Sequence

from ident.ballbar import plot_ballbar
from ident.html_page import page, png, table, write_html
from ident.synthetic_ballbar import SyntheticBallbar

__all__ = ["render_ballbar_report", "write_ballbar_report"]


def _figures(tests: Sequence[SyntheticBallbar]) -> str:
    def um(v):
        return "n/a" if v is None else f"{v:.2f} µm"

    rows = []
    for t in tests:
        r = t.result
        for f in r.runs:
            rows.append((t.machine, f.direction, f"{f.circularity_um:.2f} µm", um(r.hysteresis_um),
                         f"{r.servo_mismatch_ms:+.2f} ms (model {t.model_servo_mismatch_ms:+.2f})",
                         f"{r.scale_mismatch_ppm:+.1f} ppm",
                         "; ".join(f"{a.axis} {a.spike_um:.1f} / {a.step_um:+.1f}" for a in r.axis_reversals)))
        if t.measured is not None:
            m = t.measured
            for f in m.runs:
                rows.append((f"{t.machine}: recorded", f.direction, f"{f.circularity_um:.2f} µm", um(m.hysteresis_um),
                             f"{m.servo_mismatch_ms:+.2f} ms", f"{m.scale_mismatch_ppm:+.1f} ppm",
                             "; ".join(f"{a.axis} {a.spike_um:.1f} / {a.step_um:+.1f}" for a in m.axis_reversals)))
    return table(rows, ("machine", "direction", "circularity G", "hysteresis H", "servo mismatch",
                        "scale mismatch", "reversal spike / step (µm)"))


def _polar(t: SyntheticBallbar) -> str:
    fig = plot_ballbar(t.result, t.measured)
    ax = fig.axes[0]
    # the legend beside the plot, clear of the 270° reversal marks and labels
    ax.legend(loc="upper left", bbox_to_anchor=(1.05, 1.0), fontsize=8)
    runs = "predicted and recorded" if t.measured is not None else "predicted"
    return png(fig, f"Ballbar polar plot of {t.machine}: {runs} ccw and cw runs, radial deviation from the "
                    f"nominal {t.radius:g} mm circle, with the axis reversal points marked.")


def render_ballbar_report(tests: Sequence[SyntheticBallbar]) -> str:
    """The report as one HTML string."""
    t0 = tests[0]
    parts = ["<h1>rapid-ident: synthetic ballbar (ISO 230-4 circular test)</h1>",
             table([("radius", f"{t0.radius:g} mm"), ("feed", f"{t0.feed:g} mm/s ({t0.feed * 60:g} mm/min)"),
                    ("runs", "counter-clockwise and clockwise, one full circle each, started at 45°"),
                    ("what this is", "the test run on the identified drive models (a prediction); features are "
                                     "read from the predicted path, their causes from the model")]),
             "<h2>Figures</h2>", _figures(tests)]
    for t in tests:
        parts.append(f"<h2>{html.escape(t.machine)}</h2>")
        parts.append("<ul>" + "".join(f"<li>{html.escape(w)}</li>" for w in t.words()) + "</ul>")
        parts.append(_polar(t))
    return page("rapid-ident ballbar", parts)


def write_ballbar_report(path: str | Path, tests: Sequence[SyntheticBallbar]) -> Path:
    """Write the report to ``path`` (one self-contained .html file)."""
    return write_html(render_ballbar_report(tests), path)

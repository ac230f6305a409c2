"""Building blocks of the self-contained HTML reports (identify, predict, ballbar).

Figures are matplotlib (Agg backend, imported only when a figure is drawn) embedded as
base64 PNG, so a report is one file that opens with no network.
"""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path

from core.errors import InputError

__all__ = ["pyplot", "png", "table", "page", "write_html", "CSS"]

CSS = """body{font-family:system-ui,sans-serif;max-width:1150px;margin:auto;padding:1em;color:#222}
table{border-collapse:collapse;margin:.5em 0}th,td{border:1px solid #ccc;padding:3px 8px;text-align:left;font-size:14px}
th{background:#f3f3f3}img{max-width:100%;margin:.5em 0}.verdict{font-weight:600;background:#fff8e0;padding:.5em}
pre{font-size:12px;background:#f7f7f7;padding:.5em;overflow:auto}.warn{background:#fde8e8;padding:.5em}
.headline{background:#eef5ee;border-left:4px solid #3a7d44;padding:.4em 1em;margin:.5em 0}
.headline dt{font-weight:600;margin-top:.3em}.headline dd{margin-left:1em}.cite{font-size:13px;color:#555}"""


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as pyplot

    return pyplot


def png(fig, alt: str) -> str:
    """An ``<img>`` holding ``fig`` as an embedded PNG with ``alt`` (what the figure shows); closes the figure."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    pyplot().close(fig)
    return (f'<img alt="{html.escape(alt, quote=True)}" src="data:image/png;base64,'
            + base64.b64encode(buf.getvalue()).decode() + '">')


def table(rows: list[tuple[str, str]], header: tuple[str, ...] | None = None) -> str:
    """Two-column key/value rows, or a grid when ``header`` is given (rows of any width)."""
    if header is None:
        body = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(v)}</td></tr>" for k, v in rows)
        return f"<table>{body}</table>"
    head = "<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header) + "</tr>"
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table>{head}{body}</table>"


def page(title: str, parts: list[str]) -> str:
    """One HTML document."""
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{CSS}</style></head><body>" + "\n".join(parts) + "</body></html>")


def write_html(text: str, path: str | Path) -> Path:
    """Write a report; an unwritable path is a one-line InputError about ``report``."""
    path = Path(path)
    try:
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise InputError.about("report", f"{path}: cannot write ({exc.strerror})") from None
    return path

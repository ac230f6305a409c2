"""``agent capture``: record commanded/actual positions from a controller into MCAP."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional

import typer


def capture(
    port: str = typer.Option(..., "--port", help="controller URL, e.g. serial:///dev/ttyUSB0?format=binary"),
    output: Path = typer.Option(..., "--out", "-o", help="MCAP log to write"),
    axes: Optional[str] = typer.Option(None, "--axes", help="comma-separated axes to record (default: all)"),
    duration: Optional[float] = typer.Option(None, "--duration", help="stop after this much controller time, s"),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="no live progress line"),
) -> None:
    """Record a controller's commanded and actual positions until the program ends, --duration, or Ctrl-C.

    Example: agent capture --port serial:///dev/ttyUSB0?baud=921600 -o run.mcap
    """
    from agent.outputs import check_output
    from core.errors import TransportError
    from drivers.capture import capture as run_capture

    check_output(output, "-o")

    wanted = [a.strip() for a in axes.split(",") if a.strip()] if axes else None
    s = run_capture(port, output, axes=wanted, duration=duration, progress=not quiet)
    print(
        f"{s.path}: {s.received} samples ({s.duration_s:.3f} s of {','.join(s.axes)}), dropped {s.dropped}, "
        f"corrupt {s.corrupt}, reconnects {s.reconnects}; ended: {s.end}",
        file=sys.stderr,
    )
    if s.error:
        # the log is complete and readable; the failure is still an error for scripts
        raise TransportError(f"{s.error} (log {s.path} closed with {s.received} samples)")

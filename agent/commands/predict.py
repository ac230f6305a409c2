"""``agent predict``: run part programs on identified drives; tracking and contour errors, where."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer


def predict(
    programs: List[Path] = typer.Argument(..., help="G-code programs, run in order as separate segments."),
    machine: List[Path] = typer.Option([], "--machine", help="Result JSON of agent identify --json; repeat to compare machines."),
    set_: List[str] = typer.Option([], "--set", help="Override a parameter, AXIS.PARAM=VALUE (X.a1=120, "
                                                      "Y.backlash.gap_mm=0.01): a second machine to compare, repeatable."),
    against: List[Path] = typer.Option([], "--against", help="A recording of the same motion: measured vs predicted."),
    ini: Optional[Path] = typer.Option(None, "--ini", help="The controller's LinuxCNC INI: plan with its per-axis "
                                                            "MAX_VELOCITY/MAX_ACCELERATION as LinuxCNC does."),
    report: Optional[Path] = typer.Option(None, "--report", help="Write a self-contained HTML report here."),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write the figures as JSON here."),
    out: Optional[Path] = typer.Option(None, "-o", "--out", help="Write the prediction as a log (.mcap or .csv)."),
    tool_table: Optional[Path] = typer.Option(None, "--tool-table", help="LinuxCNC tool table for the programs' tool "
                                                                         "offsets (G43 H, G41/G42 D; docs/gcode-support.md)."),
) -> None:
    """Predict the tracking and contour errors of PROGRAMs on the identified machine(s).

    Example: agent predict part.ngc --machine result.json --set X.a1=150 --report predicted.html
    """
    from agent.outputs import check_output
    from agent.workflows.predict import load_machines, predict_files

    check_output(json_out, "--json", ".json")
    check_output(report, "--report", ".html")
    check_output(out, "--out", ".mcap", ".csv")
    from gcode_gen.commands import parse_program_files

    programs = parse_program_files(programs, tool_table)
    machines = load_machines(machine, set_, ini)
    summaries, comparisons = predict_files(programs, machines, against=against, json_out=json_out,
                                           report=report, out=out)
    for s in summaries:
        typer.echo(f"machine {s.machine}")
        typer.echo(f"  planner: {s.planner['words']}")
        if s.cycle_time_s is not None:
            typer.echo(f"  cycle time {s.cycle_time_s:.3f} s")
        for w in s.warnings:
            typer.echo(f"  warning: {w}")
        if s.contour_max_mm is not None:
            line = f"  contour error max {s.contour_max_mm * 1e3:.2f} µm, rms {s.contour_rms_mm * 1e3:.2f} µm"
            if s.worst:
                p = s.worst[0]
                feed = f", feed {p.feed_mm_s:g} mm/s (path at {p.speed_mm_s:.3g} mm/s there)" if p.feed_mm_s else ""
                line += f"; largest at {p.where}, t = {p.t_s:.3f} s{feed}"
            typer.echo(line)
        for a, e in s.tracking.items():
            typer.echo(f"  {a}: tracking error max {e.max_abs_mm * 1e3:.2f} µm at {e.where}, "
                       f"rms {e.rms_mm * 1e3:.2f} µm")
    for c in comparisons:
        d = c.to_dict()
        typer.echo(f"against {c.source}: contour error max measured {d['measured_max_abs_mm'] * 1e3:.2f} µm, "
                   f"predicted {d['predicted_max_abs_mm'] * 1e3:.2f} µm; rms of the difference "
                   f"{d['rms_difference_ratio'] * 100:.1f} % of the measured rms (model driven by the recorded command)")
        if c.standalone:
            a = c.standalone
            typer.echo(f"  stand-alone prediction (planned here): max {a['predicted_max_abs_mm'] * 1e3:.2f} µm "
                       f"({(a['max_ratio'] - 1) * 100:+.1f} %), rms of the difference "
                       f"{a['rms_difference_ratio'] * 100:.1f} % of the measured rms")
        if c.measured_cycle_s and c.predicted_cycle_s:
            typer.echo(f"  cycle time measured {c.measured_cycle_s:.3f} s, predicted {c.predicted_cycle_s:.3f} s "
                       f"({(c.predicted_cycle_s / c.measured_cycle_s - 1) * 100:+.2f} %)")
    for path in (out, json_out, report):
        if path is not None:
            typer.echo(f"wrote {path}")

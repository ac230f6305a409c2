"""``agent ballbar``: the ISO 230-4 circular test run on identified drives, read as a ballbar user reads it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import List, Optional

import typer

from core.errors import InputError


def ballbar(
    machine: List[Path] = typer.Option([], "--machine", help="Result JSON of agent identify --json; repeat to compare."),
    set_: List[str] = typer.Option([], "--set", help="Override a parameter, AXIS.PARAM=VALUE: a second machine to compare."),
    radius: float = typer.Option(100.0, "--radius", help="Ballbar length (circle radius), mm."),
    feed: float = typer.Option(1000.0 / 60.0, "--feed", help="Test feed, mm/s.", show_default="16.67 = 1000 mm/min"),
    axes: str = typer.Option("X,Y", "--axes", help="The plane: two axis letters (X,Z or XZ)."),
    centre: str = typer.Option("0,0", "--centre", help="Circle centre in the plane, mm."),
    center: Optional[str] = typer.Option(None, "--center", hidden=True),  # the other spelling, kept working
    against: List[Path] = typer.Option([], "--against", help="Recordings of the same test (the whole test, or ccw "
                                                            "and cw apart): overlay measured."),
    ini: Optional[Path] = typer.Option(None, "--ini", help="The controller's LinuxCNC INI: plan with its per-axis limits."),
    lead_deg: float = typer.Option(180.0, "--lead-deg", help="Feed-in and feed-out arcs either side of each 360° "
                                                           "data arc, degrees."),
    program_out: Optional[Path] = typer.Option(None, "--program-out", help="Write the test program (LinuxCNC "
                                                                          "dialect) here, to run it on the machine."),
    report: Optional[Path] = typer.Option(None, "--report", help="Write a self-contained HTML report here."),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write the figures as JSON here."),
) -> None:
    """Run the ballbar test on the identified machine(s) and print what the plot shows.

    Example: agent ballbar --machine result.json --radius 100 --feed 16.67 --report ballbar.html
    """
    from agent.outputs import check_output, write_json
    from agent.validation import parse_plane
    from agent.workflows.predict import load_machines
    from core.reader import load_recording
    from ident.synthetic_ballbar import run_ballbar

    check_output(json_out, "--json", ".json")
    check_output(report, "--report", ".html")
    centre = center or centre
    plane = parse_plane(axes)
    try:
        c = tuple(float(v) for v in centre.split(","))
    except ValueError:
        c = ()
    if len(c) != 2:
        raise InputError(f"--centre {centre!r}: two numbers, e.g. 0,0")
    recordings = [load_recording(p) for p in against]
    machines = load_machines(machine, set_, ini)
    if program_out is not None:
        from gcode_gen.dialects import write
        from ident.synthetic_ballbar import ballbar_program

        program_out.write_text(write(ballbar_program(radius, feed, c, plane, lead_deg), "linuxcnc"))
        typer.echo(f"wrote {program_out}")
    tests = [run_ballbar(m, radius=radius, feed=feed, axes=plane, centre=c, against=recordings if i == 0 else (),
                         lead_deg=lead_deg) for i, m in enumerate(machines)]
    for m, t in zip(machines, tests):
        typer.echo(f"machine {t.machine}: ballbar R {radius:g} mm at {feed:g} mm/s; {lead_deg:g}° feed-in/out arcs, "
                   f"ccw then cw in one run from rest with the loop at its equilibrium")
        typer.echo(f"  planner: {m.planner['words']}")
        for w in t.words():
            typer.echo(f"  {w}")
        if t.measured is not None:
            from ident.ballbar import words

            typer.echo("  recorded: " + "; ".join(words(t.measured)))
    if json_out is not None:
        write_json(json.dumps({"format": "rapid-ident-ballbar/1", "tests": [t.to_dict() for t in tests]},
                              indent=2, allow_nan=False), json_out)
        typer.echo(f"wrote {json_out}")
    if report is not None:
        from ident.ballbar_report import write_ballbar_report

        write_ballbar_report(report, tests)
        typer.echo(f"wrote {report}")

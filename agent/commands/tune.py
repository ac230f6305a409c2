"""``agent tune``: gains that minimise the predicted contour error or circularity within margins."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer


def tune(
    machine: Path = typer.Option(..., "--machine", help="Result JSON of agent identify --json (the identified drives)."),
    program: List[Path] = typer.Option([], "--program", help="Judge the tuning on this part program's max contour error."),
    ballbar: bool = typer.Option(False, "--ballbar", help="Judge it on the ballbar circularity (ccw + cw)."),
    controller: str = typer.Option("linuxcnc-pid", "--controller", help="linuxcnc-pid | p-pi | pid (the virtual CNC's PID)."),
    ini: Optional[Path] = typer.Option(None, "--ini", help="LinuxCNC INI: the current [JOINT_n] gains (read only)."),
    gain: List[str] = typer.Option([], "--gain", help="Current gain [AXIS.]NAME=VALUE (p-pi: Kp, Kd, Ki, Kv, Ka; "
                                                      "pid: Kp, Ki, Kd, Kv, Ka), repeatable."),
    propose: List[str] = typer.Option([], "--propose", help="Check these gains [AXIS.]NAME=VALUE instead of searching."),
    radius: float = typer.Option(100.0, "--radius", help="Ballbar radius, mm."),
    feed: float = typer.Option(1000.0 / 60.0, "--feed", help="Ballbar feed (the test feed), mm/s.",
                               show_default="16.67 = 1000 mm/min"),
    lead_deg: Optional[float] = typer.Option(None, "--lead-deg",
                                             help="Judge the ballbar as run: one program with feed-in/out arcs of "
                                                  "this many degrees (agent ballbar's, default there 180); without, "
                                                  "the two circles each from rest."),
    axes: Optional[str] = typer.Option(None, "--axes", help="Ballbar plane, two axis letters (default X,Y; X,Z or XZ)."),
    u_max: float = typer.Option(10.0, "--u-max", help="Output limit, V, for p-pi/pid (LinuxCNC: MAX_OUTPUT)."),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write gains, margins and predictions as JSON."),
    recording: Optional[Path] = typer.Option(None, "--recording",
                                             help="The recording the machine was identified from (agent identify "
                                                  "LOG): fit each plant to it through the controller's sampled loop "
                                                  "instead of to the identified model."),
    tool_table: Optional[Path] = typer.Option(None, "--tool-table", help="LinuxCNC tool table for the --program's "
                                                                         "tool offsets (G43 H, G41/G42 D)."),
    plant_integration: str = typer.Option("continuous", "--plant-integration",
                                          help="continuous (a real drive) | euler (the headless LinuxCNC test "
                                               "machine's HAL plant, one Euler step per servo period)."),
) -> None:
    """Propose controller gains (and compensation) from the identified drives; prints before/after and the INI diff.

    Never writes to a controller.  Example: agent tune --machine result.json --ballbar --ini machine.ini
    """
    from agent.outputs import check_output
    from agent.validation import parse_plane
    from agent.workflows.tune import tune_files
    from core.errors import InputError
    from ident.tuning import CONTROLLER_FORMS

    check_output(json_out, "--json", ".json")
    if controller not in CONTROLLER_FORMS:
        raise InputError(f"--controller {controller!r}: one of {', '.join(CONTROLLER_FORMS)}")
    if plant_integration not in ("continuous", "euler"):
        raise InputError(f"--plant-integration {plant_integration!r}: continuous or euler")
    from gcode_gen.commands import parse_program_files

    plane = list(parse_plane(axes)) if axes else None
    parsed = parse_program_files(program, tool_table)
    result, diff = tune_files(machine, controller=controller, ini=ini, gains=gain, propose=propose, programs=parsed,
                              ballbar=ballbar, radius=radius, feed=feed, axes=plane, u_max=u_max, json_out=json_out,
                              integration=plant_integration, lead_deg=lead_deg, recording=recording)
    what = {"circularity_um": "circularity", "contour_error_max_um": "max contour error",
            "tracking_error_max_um": "max tracking error"}[result.test]
    change = 100.0 * (result.predicted_after / result.predicted_before - 1.0) if result.predicted_before else 0.0
    typer.echo(f"predicted {what}: before {result.predicted_before:.2f} µm, after {result.predicted_after:.2f} µm "
               f"({change:+.0f} %)")
    for a, p in result.plants.items():
        how = (f"fitted to the recording (tracking-error fit {p.fit_pct:.1f} %)" if p.derivation == "recording"
               else "from the identified model")
        typer.echo(f"  {a} plant {how}: K/J {p.kj:.1f} mm/(V·s²), B/J {p.bj:.2f} 1/s, Coulomb {p.d_plus:+.3f}/{p.d_minus:+.3f} V"
                   + (f", gap {p.gap_mm * 1e3:.1f} µm" if p.gap_mm else ""))
    for a in result.before:
        mb, ma = result.margins_before[a][0], result.margins_after[a][0]
        typer.echo(f"  {a} margins: phase {mb.phase_margin_deg:.1f}° → {ma.phase_margin_deg:.1f}°, "
                   f"gain {mb.gain_margin_db:.1f} → {ma.gain_margin_db:.1f} dB; lag at the test feed "
                   f"{result.lag_ms[a] * 1e3:.2f} µs")
        b, n = result.before[a].to_dict(), result.after[a].to_dict()
        changed = [f"{k} {b[k]:.6g} → {n[k]:.6g}" for k in n if n[k] != b[k]]
        typer.echo(f"  {a} gains: " + (", ".join(changed) if changed else "unchanged"))
    for note in result.notes:
        typer.echo(f"  note: {note}")
    for line in diff:
        typer.echo(line)
    if json_out is not None:
        typer.echo(f"wrote {json_out}")

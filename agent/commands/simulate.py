"""``agent simulate``: run programs on the built-in virtual CNC and write a log."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from core.errors import InputError


def simulate(
    programs: List[Path] = typer.Argument(..., help="G-code programs, run in order as separate segments."),
    out: Path = typer.Option(..., "-o", "--out", help="Output log (.mcap), the same layout a capture writes."),
    machine: Optional[str] = typer.Option(
        None, "--machine", help="Machine preset name, TOML machine file, or the result JSON of agent identify "
                                "(the identified drives; default: fadal-ppi)."),
    effect: List[str] = typer.Option(
        [], "--effect", help="Add physics: NAME=VALUE or NAME=key:value,key:value (docs/spec.md §7, docs/machine-file.md), repeatable."),
    seed: int = typer.Option(0, "--seed", help="Seed of the encoder noise."),
    tool_table: Optional[Path] = typer.Option(None, "--tool-table", help="LinuxCNC tool table for the programs' tool "
                                                                         "offsets (G43 H, G41/G42 D; docs/gcode-support.md)."),
    csv: Optional[Path] = typer.Option(None, "--csv", help="Also write the CSV of docs/recording-format.md to this file."),
) -> None:
    """Run PROGRAMs on the virtual CNC and write a recording in exactly the format a capture writes.

    Example: agent simulate prog/ident_low.ngc prog/ident_high.ngc --machine fadal-pid -o run.mcap
    """
    from agent.outputs import check_output
    from agent.validation import check_seed
    from agent.workflows.predict import is_identified_machine
    from core.writer import write_recording_csv, write_recording_mcap

    if out.suffix.lower() != ".mcap":
        raise InputError(f"-o {out}: the log must be a .mcap file (use --csv for CSV)")
    check_seed(seed)
    check_output(out, "-o")
    check_output(csv, "--csv", ".csv")
    from gcode_gen.commands import parse_program_files

    programs = parse_program_files(programs, tool_table)
    if is_identified_machine(machine):
        from ident.virtual_machine import load_virtual_machine

        if effect:
            raise InputError("--effect adds physics to a built-in machine; an identified machine runs the effects "
                             "its diagnosis accepted (agent predict --set changes them)")
        prediction = load_virtual_machine(machine).run(programs)
        for w in prediction.warnings:
            typer.echo(f"warning: {w}", err=True)
        rec = prediction.recording
    else:
        from agent.validation import check_machine
        from virtual_cnc import simulate as run_programs

        check_machine(machine)

        rec = run_programs(programs, machine=machine, effects=effect, seed=seed)
    write_recording_mcap(rec, out)
    if csv is not None:
        write_recording_csv(rec, csv)
    _print_summary(rec, out, csv)


def _print_summary(rec, out: Path, csv: Optional[Path]) -> None:
    import numpy as np

    typer.echo(f"wrote {out}" + (f" and {csv}" if csv else ""))
    if rec.metadata.get("actual_is"):
        typer.echo(f"actual positions {rec.metadata['actual_is']}")
    typer.echo(f"machine {rec.metadata.get('machine')}, {rec.n_samples} samples at "
               f"{1.0 / rec.sample_period:.0f} Hz, {rec.duration:.2f} s, {len(rec.segments())} segment(s)")
    for name, tr in rec.axes.items():
        e = tr.tracking_error * 1e3
        v = np.gradient(tr.commanded, rec.sample_period)
        typer.echo(f"  {name}: travel {tr.commanded.min():+.3f} … {tr.commanded.max():+.3f} mm, "
                   f"peak feed {np.abs(v).max():.1f} mm/s, tracking error rms {np.sqrt(np.mean(e**2)):.2f} µm, "
                   f"max {np.abs(e).max():.2f} µm")
    from virtual_cnc import not_following

    for w in not_following(rec):
        typer.echo(f"warning: {w}", err=True)


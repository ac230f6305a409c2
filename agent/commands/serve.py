"""``agent serve``: a simulated controller serving the virtual CNC run of programs over a transport."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from drivers.endpoints.source import FaultPlan


def serve(
    programs: List[Path] = typer.Argument(None, help="G-code programs, run in order as separate segments."),
    transport: str = typer.Option(..., "--transport", "-t", help="serial | modbus | can"),
    recording: Optional[Path] = typer.Option(None, "--recording",
                                             help="serve an existing log (.mcap/.csv) instead of running programs"),
    machine: Optional[str] = typer.Option(None, "--machine", help="Machine preset name or TOML machine file (default: fadal-ppi)."),
    effect: List[str] = typer.Option([], "--effect", help="extra physics NAME=VALUE (repeatable)"),
    seed: int = typer.Option(0, "--seed", help="seed of the simulation noise and of the fault plan"),
    speed: float = typer.Option(1.0, "--speed", help="1 = real time, 2 = twice as fast"),
    drop_rate: float = typer.Option(0.0, "--drop-rate", help="fraction of sample ticks not sent (0..1)"),
    corrupt_rate: float = typer.Option(0.0, "--corrupt-rate", help="fraction of sample ticks sent damaged (0..1)"),
    disconnect_at: Optional[float] = typer.Option(None, "--disconnect-at",
                                                  help="break the connection once at this controller time, s"),
    fault_log: Optional[Path] = typer.Option(None, "--fault-log", help="write the injected faults here (JSON)"),
    linger: Optional[float] = typer.Option(None, "--linger",
                                           help="keep serving the end marker this long after the program, s"),
    opt: List[str] = typer.Option([], "--opt", help="transport option NAME=VALUE, e.g. format=ascii (repeatable)"),
    tool_table: Optional[Path] = typer.Option(None, "--tool-table", help="LinuxCNC tool table for the programs' tool "
                                                                         "offsets (G43 H, G41/G42 D; docs/gcode-support.md)."),
) -> None:
    """Serve commanded/actual positions of a virtual CNC run of PROGRAMS over serial, Modbus or CAN.

    Prints `port: <URL>` first; pass that URL to `agent capture --port`.

    Example: agent serve prog/ident_low.ngc prog/ident_high.ngc --transport serial
    """
    from agent.outputs import check_output
    from agent.validation import check_machine, check_seed
    from drivers.endpoints.base import parse_endpoint_options
    from drivers.endpoints.serve import build_recording, endpoint_class, serve as run_serve

    check_seed(seed)
    check_output(fault_log, "--fault-log", ".json")
    if recording is None:
        check_machine(machine)

    options = parse_endpoint_options(endpoint_class(transport), list(opt))
    if linger is not None:
        options["linger"] = linger
    from gcode_gen.commands import parse_program_files

    rec = build_recording(parse_program_files(programs or [], tool_table), machine, effect, seed, recording)
    if recording is None:  # a run of the virtual CNC: say so when the effects made its loop unstable
        from virtual_cnc import not_following

        for w in not_following(rec):
            typer.echo(f"warning: {w}", err=True)
    faults = FaultPlan(drop_rate=drop_rate, corrupt_rate=corrupt_rate, disconnect_at_s=disconnect_at, seed=seed)
    run_serve(transport, rec, speed=speed, faults=faults, options=options, fault_log=fault_log)

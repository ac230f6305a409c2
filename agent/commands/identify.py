"""``agent identify``: fit the thesis drive model per axis, check it, diagnose mismatch, report."""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path
from typing import List, Optional

import typer

from core.errors import InputError


def identify(
    log: Path = typer.Argument(..., help="Recording to identify from (.mcap or .csv)."),
    axis: List[str] = typer.Option([], "--axes", help="Axes to identify (comma list, repeatable); default all."),
    axis_alias: List[str] = typer.Option([], "--axis", hidden=True),  # the other spelling, kept working
    solver: str = typer.Option("exact", "--solver", help="exact (certified constrained optimum), ga (thesis §4.2) or ls (unconstrained); docs/identification.md."),
    validate: Optional[Path] = typer.Option(None, "--validate", help="Score the model on this other recording."),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write the JSON result (docs/spec.md §6) here."),
    report: Optional[Path] = typer.Option(None, "--report", help="Write a self-contained HTML report here."),
    against: Optional[Path] = typer.Option(None, "--against", help="Simulated log of the same program: compare virtual vs real machine."),
    model: Optional[Path] = typer.Option(None, "--model", help="Check the model an earlier --json saved (as its virtual machine runs it: own preview shift and effects) on LOG, held out, instead of identifying anew."),
    refine: bool = typer.Option(True, "--refine/--no-refine", help="Output-error refinement after the equation-error solve."),
    diagnose: bool = typer.Option(True, "--diagnose/--no-diagnose", help="Locate and explain model/recording mismatch."),
    p_min_hz: float = typer.Option(0.2, "--p-min-hz", help="Lower bound on the real pole p, Hz (eq. 3.8)."),
    wn_min_hz: float = typer.Option(0.2, "--wn-min-hz", help="Lower bound on the pole pair's natural frequency, Hz."),
    zeta_min: float = typer.Option(0.2, "--zeta-min", help="Lower bound on the pair's damping ratio."),
    zeta_max: float = typer.Option(2.0, "--zeta-max", help="Upper bound on the pair's damping ratio."),
    f_max_hz: Optional[float] = typer.Option(None, "--f-max-hz", help="Upper bound on pole frequencies, Hz (default Nyquist)."),
    units: str = typer.Option("auto", "--units", help="Units of the recorded positions: mm, m (converted), or auto "
                                                       "(metres in the log's metadata are converted; values that only "
                                                       "look like metres are refused)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the genetic algorithm and of the diagnosis cross-validation."),
    ga_population: int = typer.Option(4000, "--ga-population", help="GA population size (thesis: 4000)."),
    ga_generations: int = typer.Option(500, "--ga-generations", help="GA generations (thesis: 500)."),
) -> None:
    """Identify the closed-loop drive model of each axis in LOG and print the result.

    Example: agent identify run.mcap --validate other.mcap --json result.json --report report.html
    """
    from agent.outputs import check_output
    from agent.validation import check_seed
    from agent.summary import print_summary
    from agent.workflows.identify import identify_files
    from ident.model import Bounds

    check_seed(seed)
    if against is not None and not diagnose:
        raise InputError("--against compares the recording with a simulated one in the diagnosis; "
                         "it does nothing with --no-diagnose (drop one of them)")
    check_output(json_out, "--json", ".json")
    check_output(report, "--report", ".html")
    axes = [a for item in [*axis, *axis_alias] for a in item.split(",") if a.strip()]
    with _progress_line() as progress:
        result = identify_files(
            log, validate=validate, against=against, model=model, json_out=json_out, report=report,
            axes=axes or None, solver=solver, diagnose=diagnose, refine=refine, seed=seed,
            bounds=Bounds(p_min_hz=p_min_hz, wn_min_hz=wn_min_hz, zeta_min=zeta_min, zeta_max=zeta_max,
                          f_max_hz=f_max_hz),
            ga_population=ga_population, ga_generations=ga_generations, progress=progress, units=units.strip().lower(),
        )
    print_summary(result)
    for path in (json_out, report):
        if path is not None:
            typer.echo(f"wrote {path}")


@contextmanager
def _progress_line():
    """A transient status line on stderr while the diagnosis runs (only on a terminal)."""
    import sys

    if not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console

    with Console(stderr=True).status("identifying …") as status:
        yield lambda msg: status.update(f"diagnosis, {msg} …")

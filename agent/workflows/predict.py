"""``agent predict`` / ``agent simulate --machine result.json`` as workflows of files.

Load the virtual machines (result JSON + ``--set`` overrides), run the programs on each
(:meth:`ident.virtual_machine.VirtualMachine.run`), analyse (:func:`ident.prediction.analyse`),
compare with recordings (:func:`ident.prediction.compare`), write JSON / HTML / log.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Sequence

from agent.outputs import write_json
from core.errors import InputError
from core.reader import load_recording
from gcode_gen.commands import ProgramLike
from ident.prediction import Comparison, PredictionSummary, analyse, compare
from ident.virtual_machine import VirtualMachine, load_virtual_machine

__all__ = ["load_machines", "predict_files", "is_identified_machine"]


def is_identified_machine(machine: str | None) -> bool:
    """True when ``--machine`` names a result JSON rather than a preset or a TOML file."""
    return machine is not None and machine.lower().endswith(".json")


def load_machines(paths: Sequence[Path], overrides: Sequence[str] = (), ini: Path | None = None) -> list[VirtualMachine]:
    """One virtual machine per result JSON; ``overrides`` (AXIS.PARAM=VALUE) make one more machine
    from the first when a single JSON is given (the tuning comparison), else apply to each.
    ``ini``: a LinuxCNC INI whose per-axis limits every machine plans with."""
    if not paths:
        raise InputError.about("machine", "no machine given (a result JSON written by agent identify --json)")
    machines = [load_virtual_machine(p) for p in paths]
    if ini is not None:
        from gcode_gen.planner_limits import read_linuxcnc_ini

        limits = read_linuxcnc_ini(ini)
        machines = [m.with_planner_limits(limits) for m in machines]
    if overrides:
        if len(machines) == 1:
            machines.append(machines[0].with_overrides(overrides))
        else:
            machines = [m.with_overrides(overrides) for m in machines]
    return machines


def predict_files(programs: Sequence[ProgramLike], machines: Sequence[VirtualMachine], *,
                  against: Sequence[Path] = (), json_out: Path | None = None, report: Path | None = None,
                  out: Path | None = None) -> tuple[list[PredictionSummary], list[Comparison]]:
    """Run ``programs`` on every machine, compare with ``against`` recordings, write the outputs.

    ``out`` gets the first machine's prediction as a log (MCAP, or CSV by its suffix).
    """
    summaries = [analyse(m.run(programs)) for m in machines]
    comparisons = []
    for path in against:
        rec = load_recording(path)
        try:
            comparisons.append(compare(machines[0], rec, summaries[0].prediction.run, source=Path(path).name))
        except ValueError as exc:
            raise InputError.about("against", f"{path}: {exc}") from None
    names = [p["name"] for p in summaries[0].prediction.run.programs]
    if out is not None:
        from core.writer import write_recording_csv, write_recording_mcap

        rec = summaries[0].prediction.recording
        (write_recording_csv if Path(out).suffix.lower() == ".csv" else write_recording_mcap)(rec, out)
    if json_out is not None:
        doc = {"format": "rapid-ident-prediction/1", "programs": names,
               "machines": [s.to_dict() for s in summaries],
               "comparisons": [c.to_dict() for c in comparisons]}
        write_json(json.dumps(doc, indent=2, allow_nan=False), json_out)
    if report is not None:
        from ident.prediction_report import write_prediction_report

        write_prediction_report(report, summaries, comparisons, names)
    return summaries, comparisons

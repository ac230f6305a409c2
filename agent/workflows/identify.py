"""``agent identify`` as a workflow of files: load the recordings, :func:`ident.identify`, write the outputs."""

from __future__ import annotations

from pathlib import Path

from agent.outputs import write_json
from core.reader import load_recording
from ident.pipeline import identify as identify_recording
from ident.pipeline import load_fingerprints, load_models
from ident.results import IdentifyResult

__all__ = ["identify_files"]


def identify_files(path: Path, *, validate: Path | None = None, against: Path | None = None,
                   model: Path | None = None, json_out: Path | None = None, report: Path | None = None,
                   **options) -> IdentifyResult:
    """Identify the recording at ``path``; write ``json_out`` and ``report`` when given.

    ``options`` are :func:`ident.identify`'s keywords (axes, solver, diagnose, bounds ...).
    """
    result = identify_recording(
        load_recording(path),
        validate=load_recording(validate) if validate is not None else None,
        against=load_recording(against) if against is not None else None,
        prior=load_models(model) if model is not None else None,
        prior_source=Path(model).name if model is not None else None,
        prior_sha256=load_fingerprints(model) if model is not None else None,
        **options,
    )
    if against is not None:  # named in the summary, report and JSON ("recording.against")
        result.metadata["against"] = str(against)
    if json_out is not None:
        write_json(result.to_json(), json_out)
    if report is not None:
        result.report(report)
    return result

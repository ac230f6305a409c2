"""``--config``: the diagnosis benchmarks run with some tunables of
:class:`ident.diagnosis.config.DiagnosisConfig` changed, given as JSON, so a sweep needs
no edit of the library (e.g. ``--config '{"race_iter": [8, 8, 16]}'``)."""

from __future__ import annotations

import dataclasses
import json

CONFIG_HELP = ("JSON object of DiagnosisConfig fields to change for this run, "
               "e.g. '{\"race_iter\": [8, 8, 16]}' (default: the documented values)")


def diagnosis_config(text: str = "{}"):
    """The default :class:`DiagnosisConfig` with the fields of the JSON object ``text`` replaced."""
    from ident.diagnosis.config import DEFAULT

    changes = json.loads(text or "{}")
    fields = {f.name: f for f in dataclasses.fields(DEFAULT)}
    unknown = sorted(set(changes) - set(fields))
    if unknown:
        raise SystemExit(f"--config: no DiagnosisConfig field {', '.join(unknown)}")
    changes = {k: tuple(v) if isinstance(v, list) else v for k, v in changes.items()}
    return dataclasses.replace(DEFAULT, **changes)

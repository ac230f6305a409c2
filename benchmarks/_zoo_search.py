"""A zoo's labelled cases of one effect, and one effect's search on a case as ``diagnose`` runs it:
what the profile benchmarks start from."""

from __future__ import annotations

from pathlib import Path


def zoo_base(zoo: Path, case: dict, cfg):
    """(base, second base, chunk of the identification recording, chunk of the validation recording).

    The base model identified on ``case``'s recording and re-fitted in free run (both
    controller representations, as ``diagnose`` does: the best and the next best); both
    recordings in one frame, positions from the identification recording's first sample.
    """
    import ident
    from ident.diagnosis.augmented import segment_starts
    from ident.diagnosis.candidates import base_variants
    from ident.diagnosis.diagnose import _theta, fit_base
    from ident.diagnosis.spec import ModelSpec, make_chunk

    rec, val = ident.load(zoo / case["recording"]), ident.load(zoo / case["validation"])
    res = ident.identify(rec, diagnose=False)
    ax, vax = next(iter(rec.axes.values())), next(iter(val.axes.values()))
    ref = ax.actual[0]
    Ts = rec.sample_period
    full = make_chunk(ax.commanded - ref, ax.actual - ref, Ts, segment_starts(ax.commanded.size, rec.segment))
    held = make_chunk(vax.commanded - ref, vax.actual - ref, Ts, segment_starts(vax.commanded.size, val.segment))
    base = fit_base(ModelSpec(_theta(next(iter(res.axes.values())).model)), full, cfg=cfg)
    base, other = base_variants(base, full, cfg=cfg)[:2]
    return base, other, full, held


def zoo_search(zoo: Path, case: dict, effect: str, cfg):
    """(search's model, base, chunks of the identification and the validation recording) for
    ``effect`` on ``case``.

    The base of :func:`zoo_base`, the residual localised, and ``effect`` searched
    (:func:`ident.diagnosis.candidates.search`) with ``cfg`` from both bases.
    """
    from ident.diagnosis.candidates import search
    from ident.diagnosis.residuals import localise
    from ident.diagnosis.spec import simulate_spec

    base, other, full, held = zoo_base(zoo, case, cfg)
    loc = localise(simulate_spec(base, full) - full.x, full.x_r, full.x, *full.derivs, full.Ts, full.starts)
    return search(base, effect, full, loc, cfg, others=(other,)), base, full, held


def zoo_cases(zoo: Path, effect: str, names: str = "") -> list[dict]:
    """The labelled cases of ``effect`` in the zoo folder ``zoo`` (its labels.json), only those
    named in ``names`` (comma-separated) when given; exits with a one-line error when the
    folder holds no labels.json."""
    import json
    import sys

    if not (zoo / "labels.json").exists():
        sys.exit(f"error: {zoo / 'labels.json'} not found")
    cases = [c for c in json.loads((zoo / "labels.json").read_text())["cases"] if c["effect"] == effect]
    if names:
        wanted = set(names.split(","))
        cases = [c for c in cases if c["case"] in wanted]
    return cases

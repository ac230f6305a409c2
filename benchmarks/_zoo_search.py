"""One effect's search on a zoo case, as ``diagnose`` runs it: what the profile benchmarks start from."""

from __future__ import annotations

from pathlib import Path


def zoo_search(zoo: Path, case: dict, effect: str, cfg):
    """(search's model, base, chunk of the whole identification recording) for ``effect`` on ``case``.

    The base model identified, re-fitted in free run (both controller representations, as
    ``diagnose`` does), the residual localised, and ``effect`` searched
    (:func:`ident.diagnosis.candidates.search`) with ``cfg``; positions from the first sample.
    """
    import ident
    from ident.diagnosis.augmented import segment_starts
    from ident.diagnosis.candidates import base_variants, search
    from ident.diagnosis.diagnose import _theta, fit_base
    from ident.diagnosis.residuals import localise
    from ident.diagnosis.spec import ModelSpec, make_chunk, simulate_spec

    rec = ident.load(zoo / case["recording"])
    res = ident.identify(rec, diagnose=False)
    ax = next(iter(rec.axes.values()))
    x_r, x = ax.commanded - ax.actual[0], ax.actual - ax.actual[0]  # positions from the first sample
    Ts = rec.sample_period
    starts = segment_starts(x_r.size, rec.segment)
    full = make_chunk(x_r, x, Ts, starts)
    base = fit_base(ModelSpec(_theta(next(iter(res.axes.values())).model)), full, cfg=cfg)
    base, other = base_variants(base, full, cfg=cfg)[:2]
    loc = localise(simulate_spec(base, full) - x, x_r, x, *full.derivs, Ts, starts)
    return search(base, effect, full, loc, cfg, others=(other,)), base, full

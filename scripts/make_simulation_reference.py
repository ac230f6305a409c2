"""Saved free runs of :func:`ident.simulation.simulate` (fixtures/simulation/reference.npz).

The model of eq. 3.3 with and without Coulomb friction (stick, breakaway and reversals), one
and several segments, start from the command or the recorded position, an external load,
one to eight sub-steps, a stiff and the EMPS model.  tests/test_simulation_reference.py
checks ``simulate`` against it to 1e-9 of the tracking error's spread, so moving the
simulator onto another kernel cannot move the identified model's free run.  The saved runs
were made by the exact first-order-hold discretisation with the Karnopp stick rule
(:mod:`ident.simulation`); regenerate only when that model is meant to change:

    PYTHONPATH=. python scripts/make_simulation_reference.py
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ident.simulation import simulate

OUT = Path(__file__).resolve().parents[1] / "fixtures" / "simulation" / "reference.npz"
TS = 1e-3

#: (name, parameters a1 … d1 of eq. 3.3)
MODELS = {
    "linear": (300.0, 3e4, 1e6, 1.0, 300.0, 3e4, 0.0, 0.0),
    "coulomb": (300.0, 3e4, 1e6, 1.0, 300.0, 3e4, 40.0, -55.0),
    "stiff": (3000.0, 3e6, 1e9, 0.5, 3000.0, 3e6, 200.0, -150.0),
    "emps": (98.6153, 16469.5, 20542.5, 0.0523994, -39.8702, 16293.8, 238.013, -260.096),
}


def command(n: int = 1500) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Back-and-forth moves with dwells (x_r, mm), a lagging recorded position (mm), and two segment ids."""
    t = np.arange(n) * TS
    x_r = 4.0 * np.sin(2 * np.pi * 0.9 * t) ** 3 + 0.5 * np.clip(np.sin(2 * np.pi * 0.35 * t), -0.3, 0.3)
    x = x_r - 0.02 * np.cos(2 * np.pi * 0.9 * t)
    segment = (t >= 0.9).astype(int)
    return x_r, x, segment


def cases():
    """(key, model, keyword arguments of ``simulate``) of every saved run, in a fixed order."""
    x_r, x, segment = command()
    load = 30.0 * np.sin(2 * np.pi * 3.0 * np.arange(x_r.size) * TS)
    for name, p in MODELS.items():
        model = SimpleNamespace(**dict(zip(("a1", "a2", "a3", "b0", "b1", "b2", "d0", "d1"), p)))
        yield f"{name}_plain", model, {}
        yield f"{name}_segments_x0", model, {"segment": segment, "x0": x}
        yield f"{name}_scalar_x0_load", model, {"x0": float(x[0]) + 0.01, "disturbance": load}
        for m in (1, 3):
            yield f"{name}_substeps{m}", model, {"segment": segment, "substeps": m}


def runs():
    """(key, x̂, x_r) of every case."""
    x_r, _, _ = command()
    for key, model, kw in cases():
        yield key, simulate(model, x_r, TS, **kw), x_r


def main() -> None:
    arrays = {key: y for key, y, _ in runs()}
    OUT.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(OUT, **arrays)
    print(f"{OUT}: {len(arrays)} runs")


if __name__ == "__main__":
    main()

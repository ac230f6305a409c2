"""Saved outputs of the augmented simulator's kernel (fixtures/kernel/reference.npz).

Every effect in every variant of tests/test_diagnosis_lockstep.py, on the three controllers,
on a recording of two segments and on windows of it restarted mid-move: the recorded
position and the applied u at every 20th sample, and a SHA-256 of the full outputs.
tests/test_kernel_reference.py checks the kernel against it bit for bit, so a rewrite of the
kernel (e.g. a number type of its own for the complex-step sensitivities) cannot move the
real path.  Regenerate only when the model itself is meant to change:

    PYTHONPATH=. python scripts/make_kernel_reference.py
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from ident.diagnosis.augmented import simulate_augmented
from ident.diagnosis.spec import ModelSpec, sim_substeps
from tests.test_diagnosis_lockstep import THETA, VARIANTS, _chunk

OUT = Path(__file__).resolve().parents[1] / "fixtures" / "kernel" / "reference.npz"
#: Every how many samples the outputs are stored (the hash covers all of them).
STRIDE = 20


def reference_runs():
    """(key, y, u) of every case, in a fixed order."""
    for i, (effect, params, variant) in enumerate(VARIANTS):
        for controller in (0, 1, 2):
            spec = ModelSpec(THETA.copy()) if effect is None else ModelSpec(THETA.copy()).with_effect(
                effect, params, variant)
            spec.modes[4] = controller
            for c, chunk in enumerate(_chunk()):
                u = np.empty(chunk.n)
                y = simulate_augmented(chunk.x_r, chunk.x, chunk.Ts, spec.theta, flags=spec.flags(), ep=spec.ep,
                                       modes=spec.modes, starts=chunk.starts, derivs=chunk.derivs,
                                       nsub=sim_substeps(spec, chunk.Ts), u_out=u, warm=chunk.warm)
                yield f"v{i}_c{controller}_k{c}", y, u


def digest(y: np.ndarray, u: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(y).tobytes() + np.ascontiguousarray(u).tobytes()).hexdigest()


def main() -> None:
    arrays = {}
    for key, y, u in reference_runs():
        arrays[key + "_y"] = y[::STRIDE]
        arrays[key + "_u"] = u[::STRIDE]
        arrays[key + "_sha"] = np.array(digest(y, u))
    OUT.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(OUT, **arrays)
    print(f"{OUT}: {len(arrays) // 3} runs")


if __name__ == "__main__":
    main()

"""The augmented simulator's real (float64) path gives, bit for bit, the outputs saved from it
(fixtures/kernel/reference.npz, scripts/make_kernel_reference.py): every effect in every
variant, three controllers, cold and warm starts.  A rewrite of the kernel — one source for
the float64 run and the complex-step sensitivities — must not move a single bit of it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from scripts.make_kernel_reference import OUT, STRIDE, digest, reference_runs

REF = np.load(Path(OUT))


@pytest.mark.parametrize("key, y, u", list(reference_runs()), ids=lambda v: v if isinstance(v, str) else "")
def test_the_real_path_is_the_saved_free_run_bit_for_bit(key, y, u):
    np.testing.assert_array_equal(y[::STRIDE], REF[key + "_y"])
    np.testing.assert_array_equal(u[::STRIDE], REF[key + "_u"])
    assert digest(y, u) == str(REF[key + "_sha"])

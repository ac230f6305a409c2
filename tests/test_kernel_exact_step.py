"""The kernel steps a single mass on the continuous controller exactly: without friction the
free run does not depend on the number of sub-steps (the linear part of eq. 3.3 is
discretised exactly for a command linear between samples), while the two-mass variants,
on semi-implicit Euler, still do."""

from __future__ import annotations

import numpy as np

from ident.diagnosis.augmented import simulate_augmented
from ident.diagnosis.spec import ModelSpec
from tests.test_diagnosis_lockstep import THETA, _chunk


def _run(spec, chunk, nsub):
    return simulate_augmented(chunk.x_r, chunk.x, chunk.Ts, spec.theta, flags=spec.flags(), ep=spec.ep,
                              modes=spec.modes, starts=chunk.starts, derivs=chunk.derivs, nsub=nsub)


def test_without_friction_the_single_mass_free_run_is_the_same_on_one_or_sixteen_sub_steps():
    theta = THETA.copy()
    theta[6:] = 0.0
    chunk = _chunk()[0]
    spec = ModelSpec(theta)
    one, many = _run(spec, chunk, 1), _run(spec, chunk, 16)
    assert np.max(np.abs(one - many)) <= 1e-9 * np.ptp(chunk.x_r - many) + 1e-11 * np.abs(many).max()


def test_the_two_mass_variants_still_depend_on_their_sub_steps():
    theta = THETA.copy()
    theta[6:] = 0.0
    chunk = _chunk()[0]
    spec = ModelSpec(theta).with_effect("resonance", {"freq_hz": 40.0, "damping": 0.05, "motor_fraction": 0.7}, 1)
    coarse, fine = _run(spec, chunk, 4), _run(spec, chunk, 16)
    assert np.max(np.abs(coarse - fine)) > 1e-6 * np.ptp(chunk.x_r - fine)

"""Several parameter sets simulated in one pass (``simulate_augmented_many``, for the columns of a
finite-difference Jacobian) give each set's free run bit for bit as ``simulate_augmented`` does."""

from __future__ import annotations

import numpy as np
import pytest

from ident.diagnosis.augmented import simulate_augmented, simulate_augmented_many
from ident.diagnosis.spec import ModelSpec, make_chunk, sim_substeps

THETA = np.array([300.0, 3e4, 1e6, 1.0, 300.0, 3e4, 5.0, -5.0])
#: every effect in every variant the kernel knows (effect, parameters, variant)
VARIANTS = [
    (None, {}, None),
    ("backlash", {"gap_mm": 0.01}, 0),
    ("backlash", {"gap_mm": 0.01, "motor_fraction": 0.7, "position_motor_share": 0.3}, 1),
    ("backlash", {"gap_mm": 0.01, "motor_fraction": 0.7}, 2),
    ("resonance", {"freq_hz": 40.0, "damping": 0.05, "gain": 0.1}, 0),
    ("resonance", {"freq_hz": 40.0, "damping": 0.05, "motor_fraction": 0.7}, 1),
    ("resonance", {"freq_hz": 40.0, "damping": 0.05, "motor_fraction": 0.7}, 2),
    ("resonance", {"freq_hz": 40.0, "damping": 0.05, "motor_fraction": 0.7}, 3),
    ("stribeck", {"static_to_coulomb_ratio": 2.0, "stribeck_velocity_mm_s": 1.0}, None),
    ("time_delay", {"delay_s": 0.0023}, 0),
    ("time_delay", {"delay_s": 0.0023}, 1),
    ("cyclic_error", {"period_mm": 2.0, "amplitude_sin": 0.002, "amplitude_cos": 0.001}, 0),
    ("cyclic_error", {"period_mm": 2.0, "amplitude_sin": 200.0, "amplitude_cos": 100.0}, 1),
    ("saturation", {"limit": 3000.0}, 0),
    ("saturation", {"limit": 3000.0, "position_motor_share": 0.5}, 1),
]


def _chunk():
    """Two segments of back-and-forth moves with rests, and a window of them restarted mid-move."""
    Ts = 1e-3
    t = np.arange(3000) * Ts
    x_r = 5.0 * np.sin(2 * np.pi * 1.3 * t) ** 3 + 0.02 * t
    x = x_r - 0.01 * np.cos(2 * np.pi * 1.3 * t)  # a recorded position that lags
    starts = np.zeros(t.size, dtype=bool)
    starts[[0, 1700]] = True
    full = make_chunk(x_r, x, Ts, starts)
    return full, full.windows(1.2, 0.4, 0.1)


@pytest.mark.parametrize("effect, params, variant", VARIANTS)
@pytest.mark.parametrize("controller", [0, 1, 2])
def test_each_set_of_a_lockstep_pass_is_its_own_free_run_bit_for_bit(effect, params, variant, controller):
    rng = np.random.default_rng(7)
    spec = ModelSpec(THETA.copy()) if effect is None else ModelSpec(THETA.copy()).with_effect(effect, params, variant)
    spec.modes[4] = controller
    for chunk in _chunk():
        nsub = sim_substeps(spec, chunk.Ts)
        TH = spec.theta * (1.0 + 0.01 * rng.standard_normal((5, 8)))
        EP = spec.ep * (1.0 + 0.01 * rng.standard_normal((5, spec.ep.size)))
        EP[4, 6] = 2.0  # a delay beyond 1 s: no model to simulate, NaN as simulate_augmented gives
        Y = simulate_augmented_many(chunk.x_r, chunk.x, chunk.Ts, TH, EP, flags=spec.flags(), modes=spec.modes,
                                    starts=chunk.starts, derivs=chunk.derivs, nsub=nsub, warm=chunk.warm)
        for p in range(TH.shape[0]):
            y = simulate_augmented(chunk.x_r, chunk.x, chunk.Ts, TH[p], flags=spec.flags(), ep=EP[p],
                                   modes=spec.modes, starts=chunk.starts, derivs=chunk.derivs, nsub=nsub,
                                   warm=chunk.warm)
            np.testing.assert_array_equal(Y[p], y)
        assert np.all(np.isfinite(Y[:4])) and np.all(np.isnan(Y[4]))

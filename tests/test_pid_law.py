"""The position-loop law (core/pid_law.py), one copy run by both the virtual CNC's servo and
the tuner's sampled loop: its anti-windup, and both kernels' outputs bit for bit as they were
when each kernel had its own copy (fixtures/pid_law/reference.csv, scripts/make_pid_law_reference.py)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from core.pid_law import position_law

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
from make_pid_law_reference import OUT, outputs  # noqa: E402

GAINS = dict(Ts=1e-3, Kp=10.0, Ki=100.0, Kd=0.0, Kv=0.0, Ka=0.0, Kf0=0.0)


def _pid(e: float, integ: float, u_max: float) -> tuple[float, float]:
    g = GAINS
    return position_law(False, e, 0.0, 0.0, 0.0, 0.0, integ, g["Ts"], g["Kp"], g["Ki"], g["Kd"], g["Kv"],
                        g["Ka"], g["Kf0"], u_max)


def test_unclipped_pid_is_the_written_law_and_integrates_the_error():
    u, integ = _pid(0.2, 0.5, 1e300)
    assert integ == pytest.approx(0.5 + 1e-3 * 0.2)
    assert u == pytest.approx(10.0 * 0.2 + 100.0 * integ)


def test_a_clipped_output_stops_integrating_an_error_that_drives_it_further_into_the_limit():
    u, integ = _pid(1.0, 0.5, 1.0)  # 10 + 50 V asked, 1 V allowed: the integrator holds
    assert (u, integ) == (1.0, 0.5)
    u, integ = _pid(-1.0, -0.5, 1.0)  # clipped low, the error drives it down further: held
    assert (u, integ) == (-1.0, -0.5)
    u, integ = _pid(-0.001, 0.5, 1.0)  # clipped high, but the error pulls back: integrates
    assert u == 1.0 and integ == pytest.approx(0.5 - 1e-6)


def test_the_ppi_cascade_integrates_the_velocity_error():
    # e_v = Kp·e − v = 10·0.1 − 0.4 = 0.6; u = Kd·e_v + Ki·Σ
    u, integ = position_law(True, 0.1, 0.4, 0.0, 0.0, 0.0, 0.0, 1e-3, 10.0, 100.0, 2.0, 0.0, 0.0, 0.0, 1e300)
    assert integ == pytest.approx(0.6e-3)
    assert u == pytest.approx(2.0 * 0.6 + 100.0 * 0.6e-3)


def test_both_kernels_give_their_reference_outputs_bit_for_bit():
    ref = np.genfromtxt(OUT, delimiter=",", names=True, deletechars="")
    now = outputs()
    assert list(now) == list(ref.dtype.names)
    for name, col in now.items():
        assert np.array_equal(col, ref[name]), name
    # the step drives every kernel's output into its limit: the anti-windup is exercised
    for name, col in now.items():
        if name.endswith("_u"):
            assert np.max(np.abs(col)) >= (8.0 if name.startswith("loop") else 2.99), name

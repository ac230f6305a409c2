"""Presets reproduce the thesis's virtual drives (Tables 3.3–3.5) through eq. 3.4/3.5; TOML files."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from core.errors import MachineError
from virtual_cnc.drive import AxisDrive, Controller, Encoder, Plant, closed_loop_parameters, smc_gains
from virtual_cnc.effects import Backlash, TimeDelay
from virtual_cnc.presets import DEFAULT_MACHINE, PRESETS, load_machine, machine_to_toml

# "Actual" columns of thesis Tables 3.3 (P-PI), 3.4 (PID), 3.5 (SMC).
TABLES = {
    ("fadal-ppi", "X"): dict(a1=372.76, a2=62009.83, a3=1527104.87, b0=0, b1=0, b2=11106.33, d0=441, d1=-302),
    ("fadal-ppi", "Y"): dict(a1=372.76, a2=61999.31, a3=1527104.86, b0=0, b1=0, b2=11095.82, d0=409, d1=-388),
    ("fadal-pid", "X"): dict(a1=192.65, a2=44356.23, a3=316830.21, b0=0, b1=190.10, b2=44356.23, d0=441, d1=-302),
    ("fadal-pid", "Y"): dict(a1=178.75, a2=41031.98, a3=293085.57, b0=0, b1=175.85, b2=41031.98, d0=409, d1=-388),
    ("fadal-smc", "X"): dict(a1=390.10, a2=57029.44, a3=3801962.50, b0=1, b1=390.10, b2=57029.44, d0=441, d1=-302),
    ("fadal-smc", "Y"): dict(a1=493.09, a2=87925.67, a3=5861711.35, b0=1, b1=493.09, b2=87925.67, d0=409, d1=-388),
}

# Closed-loop poles of the same tables: (frequency Hz, damping) pairs.
POLES = {
    "fadal-ppi": [(36.26, 0.75), (36.26, 0.75), (4.68, 1.00)],
    "fadal-pid": [(33.00, 0.45), (33.00, 0.45), (1.17, 1.00)],
    "fadal-smc": [(31.83, 1.00), (21.94, 0.69), (21.94, 0.69)],
}


@pytest.mark.parametrize("preset,axis", sorted(TABLES))
def test_closed_loop_parameters_match_thesis_tables_within_1_percent(preset, axis):
    got = closed_loop_parameters(load_machine(preset).axes[axis])
    for key, want in TABLES[(preset, axis)].items():
        assert got[key] == pytest.approx(want, rel=0.01, abs=1e-9), key


@pytest.mark.parametrize("preset", sorted(POLES))
def test_closed_loop_poles_match_thesis_tables(preset):
    p = closed_loop_parameters(load_machine(preset).axes["X"])
    roots = np.roots([1.0, p["a1"], p["a2"], p["a3"]])
    got = sorted((abs(r) / (2 * math.pi), -r.real / abs(r)) for r in roots)
    want = sorted(POLES[preset])
    for (f, z), (fw, zw) in zip(got, want):
        assert f == pytest.approx(fw, rel=0.01)
        assert z == pytest.approx(zw, abs=0.01)


def test_eq_3_4_ppi_with_feedforward():
    plant = Plant(J=2.0, B=3.0, K=500.0)
    c = Controller("ppi", Kp=25.0, Ki=40.0, Kd=0.5, Kv=0.02, Ka=0.001)
    p = closed_loop_parameters(AxisDrive(c, plant))
    kj = 250.0
    assert p["a1"] == pytest.approx((3.0 + 500 * 0.5) / 2.0)
    assert p["a2"] == pytest.approx(kj * (0.5 * 25 + 40))
    assert p["a3"] == pytest.approx(kj * 25 * 40)
    assert p["b0"] == pytest.approx(kj * 25 * 0.5 * 0.001)
    assert p["b1"] == pytest.approx(kj * 25 * (0.5 * 0.02 + 0.001 * 40))
    assert p["b2"] == pytest.approx(kj * 25 * (0.5 + 0.02 * 40))


def test_sliding_mode_feedforward_cancels_the_poles():
    plant = Plant(J=0.004, B=0.01, K=4.0)
    p = closed_loop_parameters(AxisDrive(smc_gains(lam=150.0, Ks=0.2, rho=15.0, plant=plant), plant))
    assert p["b0"] == pytest.approx(1.0)
    assert p["b1"] == pytest.approx(p["a1"])
    assert p["b2"] == pytest.approx(p["a2"])
    # the sliding-surface pole -lambda is a root of the characteristic polynomial
    lam = 150.0
    assert -lam**3 + p["a1"] * lam**2 - p["a2"] * lam + p["a3"] == pytest.approx(0.0, abs=1e-6 * p["a3"])


def test_presets_stay_inside_the_actuator_limit_at_the_interpolator_acceleration():
    for machine in PRESETS.values():
        for axis in machine.axes.values():
            pl = axis.plant
            u_needed = machine.a_max / pl.K_over_J + max(pl.d_plus, -pl.d_minus) + pl.B_over_J * 200 / pl.K_over_J
            assert u_needed < 0.5 * pl.u_max


def test_default_machine_is_the_ppi_preset():
    assert DEFAULT_MACHINE == "fadal-ppi"
    assert load_machine(DEFAULT_MACHINE) is PRESETS["fadal-ppi"]
    assert set(load_machine(DEFAULT_MACHINE).axes) == {"X", "Y"}


def test_unknown_preset_is_a_one_line_error_listing_the_presets():
    with pytest.raises(MachineError, match=r"unknown machine 'fadal-xyz'.*fadal-ppi, fadal-pid, fadal-smc") as ei:
        load_machine("fadal-xyz")
    assert "\n" not in str(ei.value)


def test_toml_round_trip_reproduces_the_machine(tmp_path):
    m = load_machine("fadal-pid")
    m = replace(m, name="shop-vmc", effects=(Backlash(gap_mm=0.004, axis="X"), TimeDelay(0.0015, where="capture")),
                j_max=40000.0)
    path = tmp_path / "vmc.toml"
    path.write_text(machine_to_toml(m), encoding="utf-8")
    back = load_machine(str(path))
    assert back == m


def test_toml_file_can_start_from_a_preset_and_override_keys(tmp_path):
    path = tmp_path / "tuned.toml"
    path.write_text('base = "fadal-ppi"\neffects = ["backlash=0.01"]\n[axes.X]\nKp = 20.0\n'
                    '[axes.Z]\ncontroller = "pid"\nKp = 40.0\nKi = 300.0\nKd = 0.2\nJ = 0.0035\nB = 0.01\nK = 3.5\n',
                    encoding="utf-8")
    m = load_machine(path)
    assert m.name == "tuned"
    assert m.axes["X"].controller.Kp == 20.0
    assert m.axes["X"].controller.Kd == PRESETS["fadal-ppi"].axes["X"].controller.Kd
    assert m.axes["Y"] == PRESETS["fadal-ppi"].axes["Y"]
    assert m.axes["Z"].controller.kind == "pid"
    assert m.effects == (Backlash(gap_mm=0.01),)


@pytest.mark.parametrize(
    "text,match",
    [
        ("[axes.X\n", r"not valid TOML"),
        ('base = "nope"\n', r"unknown base preset 'nope'; known: fadal-ppi"),
        ('colour = 3\n[axes.X]\n', r"unknown key 'colour'"),
        ('[axes.X]\ncontroller = "ppi"\nKp = 30\nKi = 50\nKd = 0.37\nJ = 1\nB = 1\n', r"axis X: missing key 'K'"),
        ('[axes.X]\ncontroller = "lqr"\nKp = 30\nKi = 50\nKd = 0.37\nJ = 1\nB = 1\nK = 1\n', r"unknown controller kind 'lqr'"),
        ('base = "fadal-ppi"\n[axes.X]\nKp = "fast"\n', r"axis X: Kp must be a number"),
        ('base = "fadal-ppi"\n[axes.X]\nJ = -1.0\n', r"axis X: J must be > 0"),
        ('base = "fadal-ppi"\n[axes.X]\nd_minus_V = 0.3\n', r"d_minus must be <= 0"),
        ('base = "fadal-ppi"\n[axes.X]\nsubsteps = 4\n', r"substeps must be an integer >= 10"),
        ('base = "fadal-ppi"\n[axes.X]\ngain = 4\n', r"axis X: unknown key 'gain'"),
        ('base = "fadal-ppi"\neffects = ["wobble=3"]\n', r"unknown effect 'wobble'"),
        ('description = "no axes"\n', r"no axes"),
    ],
)
def test_bad_machine_files_give_one_line_errors(tmp_path, text, match):
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(MachineError, match=match) as ei:
        load_machine(str(path))
    assert "\n" not in str(ei.value)


def test_missing_machine_file_is_reported(tmp_path):
    with pytest.raises(MachineError, match=r"machine file .*missing\.toml.* not found"):
        load_machine(str(tmp_path / "missing.toml"))


def test_machine_forces_its_servo_period_on_every_axis():
    ax = AxisDrive(Controller("pid", Kp=40, Ki=300, Kd=0.2), Plant(J=1, B=1, K=1000), Encoder(), Ts=0.002)
    from virtual_cnc.presets import Machine

    m = Machine("m", "", {"X": ax}, Ts=0.0005)
    assert m.axes["X"].Ts == 0.0005

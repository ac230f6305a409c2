"""The plant fitted to the recording (ident.tuning.plant_fit, docs/tuning.md): it recovers a
known plant from a virtual-CNC recording, refuses a recording it cannot use with one line,
and ``agent tune --recording`` says which derivation it used."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

import gcode_gen
import virtual_cnc
from core.errors import InputError
from core.recording import AxisTrace, Recording
from ident.tuning import Gains
from ident.tuning.plant import Plant
from ident.tuning.plant_fit import FIT_MIN_PCT, fit_plant
from virtual_cnc.drive import Plant as DrivePlant
from virtual_cnc.presets import PRESETS

# a drive unlike the presets' (K/J 1000, B/J 2.55/2.90, friction +0.44/−0.30 V): the fit
# must find it, not the presets
KJ, BJ, DP, DM = 1500.0, 6.0, 0.25, -0.45
PID = PRESETS["fadal-pid"].axes["X"].controller
GAINS = Gains("pid", {"Kp": PID.Kp, "Ki": PID.Ki, "Kd": PID.Kd}, u_max=10.0)
START = Plant(1000.0, 1.0, 0.1, -0.1)  # a coefficient match far from the truth


def _known_machine():
    m = PRESETS["fadal-pid"]
    drive = DrivePlant(J=0.0035, B=0.0035 * BJ, K=0.0035 * KJ, d_plus=DP, d_minus=DM)
    return replace(m, name="known", axes={"X": replace(m.axes["X"], plant=drive)})


@pytest.fixture(scope="module")
def recording():
    """The virtual CNC (RK4 plant, encoder noise and quantisation, DAC) with the known drive
    under fadal-pid's X controller, on a short identification program."""
    return virtual_cnc.simulate(gcode_gen.generate(["X"], seed=5, n_low=40, n_high=30), _known_machine(), seed=5)


def test_a_known_plant_is_recovered_from_its_recording(recording):
    p = fit_plant(recording, "X", GAINS, START, 0.001)
    assert p.derivation == "recording" and p.fit_pct > 99.0
    assert p.kj == pytest.approx(KJ, rel=0.01)
    assert p.bj == pytest.approx(BJ, rel=0.02)
    assert p.d_plus == pytest.approx(DP, rel=0.02)
    assert p.d_minus == pytest.approx(DM, rel=0.02)


def test_the_loop_restarts_from_rest_after_a_gap_in_the_clock():
    """Two captures, each from rest at its own start, joined with 0.5 s of clock missing: the
    loop is not carried across the gap (it would jump to the second capture's start)."""
    runs = [virtual_cnc.simulate(gcode_gen.generate(["X"], seed=s, n_low=20, n_high=15, center=(c,)),
                                 _known_machine(), seed=s) for s, c in ((6, 0.0), (7, 5.0))]
    t = np.r_[runs[0].t, runs[0].t[-1] + 0.5 + runs[1].t]
    trace = AxisTrace(*(np.r_[getattr(runs[0].axes["X"], k), getattr(runs[1].axes["X"], k)]
                        for k in ("commanded", "actual")))
    p = fit_plant(Recording(t=t, axes={"X": trace}, sample_period=0.001), "X", GAINS, START, 0.001)
    assert p.fit_pct > 99.0
    assert p.kj == pytest.approx(KJ, rel=0.01) and p.d_minus == pytest.approx(DM, rel=0.02)


def test_the_accepted_effects_carry_over(recording):
    p = fit_plant(recording, "X", GAINS, replace(START, gap_mm=0.004), 0.001)
    assert p.gap_mm == 0.004 and p.delay_s == 0.0


def test_a_recording_without_the_axis_is_refused(recording):
    with pytest.raises(InputError, match=r"^the recording: no axis Y \(it has X\)$"):
        fit_plant(recording, "Y", GAINS, START, 0.001)


def test_another_sample_period_is_refused(recording):
    with pytest.raises(InputError, match=r"sample period 1 ms, the identified model's 2 ms"):
        fit_plant(recording, "X", GAINS, START, 0.002)


def test_an_axis_moving_one_way_only_is_refused():
    t = np.arange(2000) * 0.001
    cmd = np.clip(t - 0.2, 0.0, None) * 5.0
    rec = Recording(t=t, axes={"X": AxisTrace(cmd, cmd - 1e-3)}, sample_period=0.001,
                    metadata={"source": "ramp.csv"})
    with pytest.raises(InputError, match=r"^recording ramp.csv: axis X is never commanded in the − direction: "
                                         r"its Coulomb friction d⁻ cannot be fitted$"):
        fit_plant(rec, "X", GAINS, START, 0.001)


@pytest.mark.parametrize("gains", [Gains("p-pi", {"Kp": 30.0, "Ki": 50.9, "Kd": 0.37}, u_max=10.0),
                                   Gains("pid", {"Kp": PID.Kp, "Ki": 3 * PID.Ki, "Kd": PID.Kd / 2}, u_max=10.0)],
                         ids=["another form", "other gains"])
def test_gains_the_recording_did_not_run_with_are_refused(recording, gains):
    """The fitted loop cannot reproduce the recording: refused, not used."""
    with pytest.raises(InputError, match=rf"^the recording: the {gains.form} loop with the fitted plant reproduces "
                                         rf"axis X's tracking error to -?[0-9.]+ % \(< {FIT_MIN_PCT:.0f} %\): "
                                         r"are these the gains it ran with\?$"):
        fit_plant(recording, "X", gains, START, 0.001)


@pytest.mark.slow
def test_cli_says_which_derivation_it_used(tmp_path):
    """generate → simulate → identify → tune with and without --recording; a missing or
    mismatched recording is one error line, exit 2."""
    def agent(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "agent.cli", *args], capture_output=True, text=True,
                              timeout=600, cwd=tmp_path)

    for args in (("generate", "--axes", "X", "--seed", "5", "--n-low", "40", "--n-high", "30", "-o", "prog"),
                 ("simulate", "prog/ident_low.nc", "prog/ident_high.nc", "--machine", "fadal-pid", "--seed", "5",
                  "-o", "run.mcap"),
                 ("identify", "run.mcap", "--json", "result.json", "--no-diagnose")):
        assert agent(*args).returncode == 0
    tune = ("tune", "--machine", "result.json", "--controller", "pid", "--program", "prog/ident_high.nc",
            "--gain", f"Kp={PID.Kp}", "--gain", f"Ki={PID.Ki}", "--gain", f"Kd={PID.Kd}")
    fitted = agent(*tune, "--recording", "run.mcap")
    assert fitted.returncode == 0, fitted.stderr
    assert "  X plant fitted to the recording (tracking-error fit 99." in fitted.stdout
    model = agent(*tune)
    assert model.returncode == 0, model.stderr
    assert "  X plant from the identified model: " in model.stdout
    assert "note: the plants come from the identified models; --recording run.mcap fits them" in model.stdout
    missing = agent(*tune, "--recording", "nothere.mcap")
    assert missing.returncode == 2 and missing.stderr.count("\n") == 1
    assert missing.stderr.startswith("error: nothere.mcap: no such file")
    other = agent(*tune[:4], "p-pi", *tune[5:7], "--gain", "Kp=30", "--gain", "Ki=50.9", "--gain", "Kd=0.37",
                  "--recording", "run.mcap")
    assert other.returncode == 2 and other.stderr.count("\n") == 1
    assert other.stderr.startswith("error: --recording run.mcap: the p-pi loop with the fitted plant reproduces axis X")

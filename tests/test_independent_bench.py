"""Physics specifications of the independent feed-drive simulator (benchmarks/independent_bench)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.independent_bench import (ControllerParams, Drive, PlantParams, SensorParams,  # noqa: E402
                                          draw_case, case_recordings, simulate, tune_ppi)
from benchmarks.independent_bench.plant import substep  # noqa: E402

TS = 0.001


def ramp(v_mm_s: float, t_end: float = 2.0, t_start: float = 0.1) -> np.ndarray:
    t = np.arange(int(t_end / TS)) * TS
    return np.where(t > t_start, (t - t_start) * v_mm_s, 0.0)


def frictionless(**kw) -> PlantParams:
    return PlantParams(m_m=100.0, m_t=100.0, fc_pos=0.0, fc_neg=0.0, fs_pos=0.0, fs_neg=0.0, b_t=0.0, **kw)


@pytest.mark.parametrize("kvff, lag", [(0.0, 50.0 / 20.0), (1.0, 0.0)])
def test_ppi_ramp_lag(kvff, lag):
    """Rigid plant, P-PI: steady lag v/Kp without feed-forward, ~0 with full velocity feed-forward."""
    plant = PlantParams(m_m=100.0, m_t=100.0, fc_pos=30.0, fc_neg=25.0, fs_pos=30.0, fs_neg=25.0, b_t=200.0)
    drive = Drive(plant=plant, controller=tune_ppi(200.0, 50.0, 20.0, kvff=kvff),
                  sensors=SensorParams(q_enc=1e-8))
    sim = simulate(drive, ramp(50.0))
    e = (sim.x_r - sim.feedback)[-200:] * 1e3       # mm
    assert np.mean(e) == pytest.approx(lag, abs=0.01)
    assert np.ptp(e) < 0.01


def test_gap_gives_lost_motion_equal_to_gap_semi_closed():
    """Semi-closed: the motor goes +0.5 mm and back (slowly, so the table does not coast);
    the table comes back 0.5 mm minus the gap."""
    gap = 0.1e-3
    mu = 50.0
    k = mu * (2 * np.pi * 200.0) ** 2
    plant = PlantParams(m_m=100.0, m_t=100.0, two_mass=True, gap=gap, k_link=k, c_link=2 * 0.2 * np.sqrt(k * mu),
                        fc_pos=40.0, fc_neg=40.0, fs_pos=40.0, fs_neg=40.0, b_t=100.0)
    drive = Drive(plant=plant, controller=tune_ppi(200.0, 50.0, 20.0, kvff=1.0),
                  sensors=SensorParams(q_enc=1e-8, q_scale=1e-8, capture_table=True))
    t = np.arange(3000) * TS
    x_r = np.interp(t, [0.0, 0.2, 1.2, 1.5, 2.5, 3.0], [0.0, 0.0, 0.5, 0.5, 0.0, 0.0])
    sim = simulate(drive, x_r)
    i_fwd, i_back = 1450, 2950
    motor = sim.x_m[i_fwd] - sim.x_m[i_back]
    table = sim.captured[i_fwd] - sim.captured[i_back]
    assert motor == pytest.approx(0.5e-3, abs=2e-6)              # the loop holds the motor on the command
    assert motor - table == pytest.approx(gap, rel=0.05)        # lost motion = the gap


def stuck_run(force: float, n: int = 4000) -> np.ndarray:
    p = PlantParams(m_m=50.0, m_t=50.0, fc_pos=100.0, fc_neg=80.0, fs_pos=200.0, fs_neg=160.0,
                    v_s=2e-3, delta=2.0, b_t=50.0).pack()
    state = np.zeros(4)
    x = np.empty(n)
    for i in range(n):
        substep(state, force, 0.0, 5e-5, p)
        x[i] = state[0]
    return x


def test_stuck_mass_breaks_away_above_static_friction():
    """A mass at rest stays under a force below F_s (asymmetric), breaks away above it."""
    assert np.all(stuck_run(190.0) == 0.0)
    assert np.all(stuck_run(-150.0) == 0.0)
    assert stuck_run(210.0)[-1] > 1e-6
    assert stuck_run(-170.0)[-1] < -1e-6


def test_stick_slip_at_low_speed():
    """Pulled through a spring at 0.2 mm/s, a Stribeck-friction mass alternately sticks and slips."""
    p = PlantParams(m_m=50.0, m_t=50.0, fc_pos=100.0, fc_neg=100.0, fs_pos=250.0, fs_neg=250.0,
                    v_s=1e-3, delta=2.0, b_t=50.0).pack()
    state = np.zeros(4)
    dt, k, v0 = 5e-5, 2e6, 2e-4
    v = np.empty(60000)
    for i in range(v.size):
        substep(state, k * (v0 * i * dt - state[0]), 0.0, dt, p)
        v[i] = state[1]
    late = v[20000:]
    assert np.mean(late == 0.0) > 0.3               # stuck a good part of the time
    assert late.max() > 3 * v0                      # and slips faster than it is pulled
    stuck = (late == 0.0).astype(int)
    assert np.sum(np.diff(stuck) == 1) >= 2         # repeatedly


def test_quantization_grid():
    drive = Drive(plant=frictionless(), controller=tune_ppi(200.0, 50.0, 20.0),
                  sensors=SensorParams(q_enc=5e-7, noise_sd=2e-7))
    sim = simulate(drive, ramp(10.0, 0.5), seed=3)
    steps = sim.captured / 5e-7
    assert np.max(np.abs(steps - np.round(steps))) < 1e-6
    assert len(np.unique(np.round(steps))) > 100


def test_force_limit_holds():
    f_max = 150.0
    drive = Drive(plant=frictionless(), controller=tune_ppi(200.0, 50.0, 20.0, f_max=f_max))
    t = np.arange(1000) * TS
    sim = simulate(drive, np.where(t > 0.1, 5.0, 0.0))            # a 5 mm step: wants far more
    assert np.max(np.abs(sim.force)) == pytest.approx(f_max)
    assert np.max(np.abs(sim.force)) <= f_max


@pytest.mark.parametrize("where", ["actuation", "feedback"])
def test_dead_time_shifts_response(where):
    """Open loop (acceleration feed-forward only): dead time tau delays the captured motion by tau."""
    tau = 0.0027                                           # 2.7 samples: integer + fraction
    ctrl = ControllerParams(kind="ppi", kp=0.0, kv=0.0, ki=0.0, kaff=1.0, m_ff=200.0)
    t = np.arange(800) * TS
    x_r = np.where(t > 0.1, 0.5 * 2000.0 * np.minimum(t - 0.1, 0.2) ** 2, 0.0)
    base = simulate(Drive(plant=frictionless(), controller=ctrl, sensors=SensorParams(q_enc=0.0)), x_r)
    sens = SensorParams(q_enc=0.0, delay_act=tau if where == "actuation" else 0.0,
                        delay_fb=tau if where == "feedback" else 0.0)
    late = simulate(Drive(plant=frictionless(), controller=ctrl, sensors=sens), x_r)
    shifted = np.interp(t - tau, t, base.captured)
    assert np.max(np.abs(late.captured - shifted)) < 0.02 * np.max(np.abs(base.captured))
    assert np.max(np.abs(late.captured - base.captured)) > 0.02 * np.max(np.abs(base.captured))  # it did move


def test_case_is_deterministic_from_seed():
    a, b = draw_case("backlash", 77, 1, "full", "pid"), draw_case("backlash", 77, 1, "full", "pid")
    assert a.drive == b.drive and a.truth == b.truth
    ra, _ = case_recordings(a)
    rb, _ = case_recordings(b)
    np.testing.assert_array_equal(ra.axes["X"].actual, rb.axes["X"].actual)
    assert draw_case("backlash", 78, 1, "full", "pid").truth != a.truth


def test_calibrated_cases_fall_in_fit_window():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import bench_independent as bench

    for spec in ({"seed": 1018, "cls": "cyclic_error", "closure": "semi", "kind": "pid"},
                 {"seed": 1006, "cls": "none", "closure": "semi", "kind": "ppi"}):
        case, rec, val, fit, tries = bench.calibrate(spec, max_tries=2)
        assert case is not None
        assert bench.in_window(spec["cls"], fit)
        lo, hi = bench.FIT_WINDOW
        assert lo <= fit <= (hi if spec["cls"] != "none" else 100.0)


def test_load_force_step_is_rejected_by_the_integrator():
    """A 200 N load step on a drive at rest: a transient error, then back to the command (integral action)."""
    drive = Drive(plant=frictionless(), controller=tune_ppi(200.0, 50.0, 20.0),
                  sensors=SensorParams(q_enc=1e-9), load_windows=((0.3, 1.5, 200.0),))
    sim = simulate(drive, np.zeros(1500))
    e = -sim.feedback * 1e3                                     # mm, command is 0
    assert np.all(e[:300] == 0.0)
    assert np.max(np.abs(e[300:500])) > 1e-4                    # pushed off the command
    assert np.abs(e[-50:]).max() < 1e-5                         # and brought back
    assert np.mean(sim.force[-50:]) == pytest.approx(-200.0, rel=1e-3)


def test_closed_loop_mode_between_free_and_locked():
    """A soft loop leaves the two-mass mode at its free frequency; a stiff semi-closed loop
    holds the motor, and the table rings near sqrt(k / m_t)."""
    from benchmarks.independent_bench.linear import closed_loop_mode

    mu = 50.0
    k = mu * (2 * np.pi * 100.0) ** 2
    plant = PlantParams(m_m=100.0, m_t=100.0, two_mass=True, k_link=k, c_link=2 * 0.01 * np.sqrt(k * mu), b_t=0.0)
    assert plant.resonance_hz() == pytest.approx(100.0)
    soft, _ = closed_loop_mode(Drive(plant=plant, controller=tune_ppi(200.0, 2.0, 1.0)))
    stiff, _ = closed_loop_mode(Drive(plant=plant, controller=tune_ppi(200.0, 2000.0, 10.0)))
    assert soft == pytest.approx(100.0, rel=0.03)
    assert stiff == pytest.approx(100.0 / np.sqrt(2.0), rel=0.05)


def test_a_large_semi_closed_gap_with_the_tables_inertia_is_named_and_sized():
    """Diagnosis on this simulator, not ours: a semi-closed PID drive whose table (scale
    recorded) coasts into a 0.6 mm gap when the motor brakes (tuning seed 1042, never a
    report seed).  The base model identified without the gap took part of the lost motion
    as direction-dependent friction; the two-mass start on the motor-read loop must not
    add a Coulomb offset the loop never sees, or the gap's start is screened out as too
    dear and the search ends on a small massless-table gap that explains nothing."""
    import ident

    rec, val = case_recordings(draw_case("backlash", 1042, 0, "semi", "pid"))
    d = ident.identify(rec, validate=val).axes["X"].diagnosis
    assert d.verdict == "backlash"
    bl = next(c for c in d.candidates if c.effect == "backlash")
    assert bl.parameters["gap_mm"] == pytest.approx(0.599, rel=0.25)
    assert d.fit_after_pct > d.fit_before_pct + 3.0


def test_a_two_mass_mode_is_sized_by_its_free_mode_not_where_the_fit_entered_its_ridge():
    """Diagnosis on this simulator, not ours: a semi-closed P-PI drive with a 24 Hz free
    two-mass mode and a light motor (tuning seed 1002, never a report seed).  The
    recording shows the table ringing at about f·√μ; free mode f and motor share μ trade
    along that ridge, and the fit entered it at μ ≈ 0.8, 34 Hz (+40 %).  The scan along the
    ridge (candidates.scan_motor_fraction) must find the free mode within 25 %."""
    import ident

    rec, val = case_recordings(draw_case("resonance", 1002, 0, "semi", "ppi"))
    d = ident.identify(rec, validate=val).axes["X"].diagnosis
    assert d.verdict == "resonance"
    res = next(c for c in d.candidates if c.effect == "resonance")
    assert res.parameters["kind"] == "two_mass"
    assert res.parameters["freq_hz"] == pytest.approx(24.2, rel=0.25)


def test_a_full_closed_gap_is_sized_by_the_likelihood_with_a_variance_per_segment():
    """Diagnosis on this simulator, not ours: a full-closed PID drive with a 48 µm gap
    (tuning seed 1021, never a report seed).  In the low-speed set the integrator hunts
    across the gap in stick-slip, a response no model follows in phase; least squares with
    the tracking-error weights shrinks the gap to make that oscillation smaller.
    The accepted model re-fitted with a noise variance of each segment's own
    (candidates.segment_variance_fit) must size it closer to the truth.  The gap is tried
    alone: whether it or a 2.4 ms dead time is named is a close call (each removes about a
    third of the held-out residual, and the last bits of the fits decide which more), not
    what this test is about."""
    import ident
    from ident.diagnosis import diagnose
    from ident.diagnosis.config import DiagnosisConfig

    case = draw_case("backlash", 1021, 0, "full", "pid")
    rec, val = case_recordings(case)
    model = ident.identify(rec, diagnose=False).axes["X"].model
    tr, vt = rec.axes["X"], val.axes["X"]
    errors = []
    for steps in (0, DiagnosisConfig().segment_variance_steps):
        d = diagnose(tr.commanded, tr.actual, rec.sample_period, model, segment=rec.segment,
                     validation=(vt.commanded, vt.actual, val.segment), effects=("backlash",),
                     config=DiagnosisConfig(segment_variance_steps=steps))
        assert d.verdict == "backlash"
        gap = next(c for c in d.candidates if c.effect == "backlash" and c.accepted).parameters["gap_mm"]
        errors.append(abs(gap / case.truth["gap_mm"] - 1.0))
    assert errors[1] < errors[0]


def test_a_dead_time_fitted_on_the_continuous_controller_is_told_without_the_lag_of_sampling():
    """Diagnosis on this simulator, not ours: a semi-closed PID drive with a 1.4 ms dead time
    on its feedback (tuning seed 1017, never a report seed).  The continuous controller
    fits it best, with a delay of about 2.3 ms inside the loop: the dead time and the one
    sample a digital loop's hold and sampled velocity add.  The dead time told must be the
    drive's."""
    import ident

    case = draw_case("time_delay", 1017, 1, "semi", "pid")
    rec, val = case_recordings(case)
    d = ident.identify(rec, validate=val).axes["X"].diagnosis
    assert d.verdict == "time_delay"
    p = next(c for c in d.candidates if c.effect == "time_delay").parameters
    assert p["delay_s"] == pytest.approx(case.truth["delay_s"], rel=0.25)
    assert p["sampling_lag_s"] == pytest.approx(TS)  # the drive's 1 kHz servo cycle
    assert f"time delay {1e3 * p['delay_s']:.2f} ms" in d.summary


@pytest.mark.parametrize("seed, closure", [(1010, "full"), (1066, "full"), (1003, "semi")])
def test_a_dead_time_drive_is_tuned_stable_not_held_by_its_force_limit(seed, closure):
    """A P-PI drive with a dead time keeps its phase margin (ppi_bandwidth_for_margin):
    its force stays well inside the amplifier's limit.  Version 1's f_v <= 0.2/tau left
    these three (tuning seeds, first draw) in a limit cycle at the limit half the time."""
    import gcode_gen
    from benchmarks.independent_bench.simulate import command

    case = draw_case("time_delay", seed, 0, closure, "ppi")
    x_r, _seg = command(gcode_gen.generate(["X"], seed=case.id_seed))
    sim = simulate(case.drive, x_r, seed=case.id_seed)
    assert np.max(np.abs(sim.force)) < 0.5 * case.drive.controller.f_max

"""95 % intervals of identified parameters (ident/uncertainty.py): they cover a known truth,
mark what a recording cannot determine and what a bound holds, and reach the JSON."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import gcode_gen
import ident
import virtual_cnc
from _synthetic import PID_X, point_to_point
from core.recording import Recording
from ident.model import Bounds
from ident.simulation import simulate
from ident.uncertainty import PARAMETER_NAMES, SEARCH_NAMES, block_length

TS = 1e-3


def _ar1(n: int, rho: float, sigma_mm: float, seed: int) -> np.ndarray:
    """Stationary AR(1) noise of standard deviation ``sigma_mm``: correlated like a closed loop's residual."""
    rng = np.random.default_rng(seed)
    e = rng.standard_normal(n) * sigma_mm * math.sqrt(1.0 - rho * rho)
    out = np.empty(n)
    out[0] = rng.standard_normal() * sigma_mm
    for k in range(1, n):
        out[k] = rho * out[k - 1] + e[k]
    return out


@pytest.fixture(scope="module")
def pid_drive():
    """The thesis's PID drive (Table 3.4, X) run on a 20 s random point-to-point command by
    the model's own exact discretisation: the truth is in the model class, only noise is random."""
    cmd = point_to_point(20.0, TS, seed=3)
    return cmd, simulate(PID_X, cmd.x, TS)


def _truth() -> dict[str, float]:
    wn, zeta, p = PID_X.search_variables()
    return {**{k: getattr(PID_X, k) for k in PARAMETER_NAMES},
            "wn_hz": wn / (2 * math.pi), "zeta": zeta, "p_hz": p / (2 * math.pi)}


def _identify(cmd, x, **kw):
    rec = Recording.from_arrays(cmd.t, {"X": cmd.x}, {"X": x})
    return ident.identify(rec, diagnose=False, **kw)


def test_intervals_cover_the_true_parameters_of_a_simulated_drive(pid_drive):
    cmd, x = pid_drive
    truth = _truth()
    covered = total = 0
    for seed in range(4):  # four noise realisations, 0.5 µm, correlated over ~20 samples
        u = _identify(cmd, x + _ar1(x.size, 0.9, 0.5e-3, seed)).axes["X"].uncertainty
        assert u is not None
        for name in PARAMETER_NAMES + SEARCH_NAMES:
            iv = u.parameters[name]
            assert iv.lo <= iv.value <= iv.hi
            covered += iv.lo <= truth[name] <= iv.hi
            total += 1
            if name != "b0":  # b0 is 0 on this drive: its width is judged against its scale of 1
                assert 0.0 < (iv.hi - iv.lo) / 2 < 0.5 * abs(truth[name]), name  # sane: excludes 0, not zero width
        assert u.undetermined == [] and not u.is_equivalent, u.why
        assert u.parameters["b0"].near_zero or not u.parameters["b0"].undetermined
    # 95 % intervals: most cover the truth (the nominal rate, with room for four draws)
    assert covered / total >= 0.85, f"{covered} of {total}"


def test_block_length_follows_the_residual_correlation_time():
    white = np.random.default_rng(1).standard_normal((20000, 1))
    L_white, tau_white = block_length(white, 1)
    assert tau_white < 2.0 and L_white <= 10
    corr = _ar1(20000, 0.9, 1.0, 2)[:, None]  # integrated time (1 + ρ)/(1 − ρ) = 19
    L_corr, tau_corr = block_length(corr, 1)
    assert 12.0 < tau_corr < 30.0
    assert L_corr >= 5 * 12


def test_a_pole_held_by_a_bound_is_marked_at_bound(pid_drive):
    cmd, x = pid_drive
    # the drive's slow real pole is at 1.17 Hz: a 3 Hz lower bound holds it
    res = _identify(cmd, x + _ar1(x.size, 0.9, 0.5e-3, 0), bounds=Bounds(p_min_hz=3.0))
    r = res.axes["X"]
    u = r.uncertainty
    p = u.parameters["p_hz"]
    assert p.at_bound == "p_min" and p.lo == p.hi == pytest.approx(3.0)
    held = [pole for pole in u.poles if pole.at_bound]
    assert len(held) == 1 and held[0].freq_hz == pytest.approx(3.0, rel=1e-4)
    assert u.is_equivalent and any("p_min" in why for why in u.why)
    doc = json.loads(res.to_json())["axes"]["X"]  # strict JSON
    assert doc["at_bound"] == {"p_hz": "p_min"}
    assert [pole["at_bound"] for pole in doc["poles"]].count("p_min") == 1


def test_json_carries_intervals_beside_the_spec_keys(pid_drive):
    cmd, x = pid_drive
    doc = json.loads(_identify(cmd, x + _ar1(x.size, 0.9, 0.5e-3, 1)).to_json())["axes"]["X"]
    assert set(doc["model"]) == set(PARAMETER_NAMES)
    assert all(isinstance(v, float) for v in doc["model"].values())
    for name, (lo, hi) in doc["model_interval95"].items():
        assert lo <= doc["model"][name] <= hi
    assert set(doc["search_variables_interval95"]) == set(SEARCH_NAMES)
    for key in ("poles", "zeros"):
        for root in doc[key]:
            lo, hi = root["freq_hz_interval95"]
            assert lo <= root["freq_hz"] <= hi and "damping" in root and "at_bound" in root
    assert doc["equivalent_model"]["is_equivalent"] is False and doc["undetermined"] == []
    assert doc["intervals"]["samples"]["blocks"] >= 40


@pytest.mark.slow
def test_the_ppi_demo_drive_is_marked_an_equivalent_model():
    """The default demo machine (thesis Table 3.3's P-PI drive): its integrator and friction
    move together without changing the fit, as the thesis found (friction 17x off)."""
    from ident.headline import axis_headline

    rec = virtual_cnc.simulate(gcode_gen.generate(["X"], seed=1), "fadal-ppi", seed=1)
    r = ident.identify(rec, diagnose=False).axes["X"]
    u = r.uncertainty
    assert {"d0", "d1"} <= set(u.undetermined)
    assert any({"d0", "d1"} <= set(w.components) for w in u.weak_directions)
    assert u.is_equivalent
    assert "Table 3.3" in u.equivalent_text()
    # and the answer the report leads with says so
    assert "an equivalent model" in axis_headline(r).identified


def test_summary_and_report_show_each_interval_and_mark(pid_drive, tmp_path):
    """`agent identify` as a user runs it: every parameter, pole and zero with its interval
    and mark in the terminal summary and the HTML report."""
    import subprocess
    import sys

    from core.writer import write_recording_mcap

    cmd, x = pid_drive
    log = write_recording_mcap(Recording.from_arrays(cmd.t, {"X": cmd.x}, {"X": x + _ar1(x.size, 0.9, 0.5e-3, 2)}),
                               tmp_path / "pid.mcap")
    proc = subprocess.run([sys.executable, "-m", "agent.cli", "identify", str(log), "--no-diagnose",
                           "--p-min-hz", "3", "--report", str(tmp_path / "r.html")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "95 % intervals" in out
    rows = [line.split() for line in out.splitlines() if line.startswith("    ")]
    named = {" ".join(w[:2]) if w[0] in ("pole", "zero") else w[0] for w in rows}
    assert set(PARAMETER_NAMES + SEARCH_NAMES) | {"pole 1", "pole 2", "pole 3", "zero 1"} <= named
    assert "at bound (p_min)" in out and "Equivalent model" in out
    page = (tmp_path / "r.html").read_text()
    assert "95 % interval" in page and "at bound (p_min)" in page and "Equivalent model" in page


def test_a_critically_damped_pair_gets_a_finite_interval():
    """Two (nearly) equal poles move as the square root of the noise: each alone has no
    useful linearisation, the pair (ω_n, ζ) has; the interval is the pair's and covers it."""
    from ident.model import DriveModel

    wn, p = 2 * math.pi * 30.0, 2 * math.pi * 2.0  # a double pole at 30 Hz (ζ = 1) and 2 Hz
    a1, a2, a3 = p + 2 * wn, wn * wn + 2 * p * wn, p * wn * wn
    truth = DriveModel(a1=a1, a2=a2, a3=a3, b0=0.0, b1=a1, b2=a2, d0=441.0, d1=-302.0)
    cmd = point_to_point(20.0, TS, seed=3)
    x = simulate(truth, cmd.x, TS) + _ar1(cmd.x.size, 0.9, 0.5e-3, 5)
    u = _identify(cmd, x).axes["X"].uncertainty
    fast = [pole for pole in u.poles if pole.freq_hz > 10.0]
    assert len(fast) == 2
    for pole in fast:
        lo, hi = pole.freq_hz_interval95
        assert not pole.undetermined and hi - lo < 0.2 * 30.0
        assert lo <= 30.0 <= hi
    assert u.parameters["wn_hz"].lo <= 30.0 <= u.parameters["wn_hz"].hi

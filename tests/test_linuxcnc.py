"""Capture from a real LinuxCNC over HAL (``linuxcnc://``) on the headless test machine.

LinuxCNC runs in real time, so every run here takes as long as its programs (a few s).
Where LinuxCNC is not installed these tests skip with the reason (the error test runs).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from core.reader import load_recording
import _linuxcnc as lx

pytestmark = pytest.mark.slow


def _agent(*args: str, cwd: Path = lx.ROOT) -> subprocess.CompletedProcess:
    return subprocess.run(lx.AGENT + list(args), cwd=cwd, capture_output=True, text=True, timeout=300)


def _one_error_line(res: subprocess.CompletedProcess) -> str:
    assert "Traceback" not in res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), res.stderr
    return lines[0]


def _netlist(m) -> list[str]:
    """HAL's own dump of components, threads, nets and settings, without run-time statistics."""
    return [ln for ln in m.halcmd("save", "all").splitlines() if ".tmax" not in ln]


# --- errors ---------------------------------------------------------------------------------

def test_capture_when_linuxcnc_is_not_running_is_one_line(tmp_path):
    lx.stop_machine()  # one LinuxCNC per computer: make sure ours is not up
    if lx.lm.missing() is None and subprocess.run(["pgrep", "-x", "rtapi_app"], capture_output=True).returncode == 0:
        pytest.skip("another LinuxCNC is running on this computer")
    res = _agent("capture", "--port", "linuxcnc://", "-o", str(tmp_path / "log.mcap"))
    assert res.returncode == 1
    line = _one_error_line(res)
    assert ("LinuxCNC is not running" in line) if lx.lm.missing() is None else ("not installed" in line)
    assert not (tmp_path / "log.mcap").exists()


@pytest.mark.parametrize("query, pin", [("joints=3", "joint.3.motor-pos-cmd"),
                                        ("fb=joint.{j}.no-such-pin", "joint.0.no-such-pin"),
                                        ("running=halui.no-such-pin", "halui.no-such-pin")])
def test_a_pin_that_does_not_exist_is_one_line_and_leaves_hal_alone(tmp_path, query, pin):
    m = lx.machine()
    before = _netlist(m)
    res = _agent("capture", "--port", f"linuxcnc://?{query}", "-o", str(tmp_path / "log.mcap"))
    assert res.returncode == 2
    assert f"HAL has no pin {pin!r}" in _one_error_line(res)
    assert not (tmp_path / "log.mcap").exists()
    assert _netlist(m) == before


# --- capture ---------------------------------------------------------------------------------

def _read_reference(path: Path) -> np.ndarray:
    """halsampler -t lines of cfg ffbs → rows [servo period, cmd, fb, running]."""
    rows = []
    for line in path.read_text().splitlines():
        f = line.split()
        if len(f) == 5:
            rows.append([int(f[0]) + int(f[4]), float(f[1]), float(f[2]), int(f[3])])
    return np.array(rows)


def test_capture_records_every_servo_period_as_motion_commanded_it(tmp_path):
    """Both generated programs at 1 kHz: zero drops, one sample per servo period, and the
    commanded/actual positions equal those a halsampler of this test's own recorded from the
    motion module's pins in the same periods."""
    m = lx.machine()
    progs = lx.generate(tmp_path, seed=1)
    # Only one sampler module can be loaded: this test loads it with two FIFOs, its own
    # reference (FIFO 1) and one for the capture (FIFO 0, linuxcnc://?channel=0).
    m.halcmd("loadrt", "sampler", "depth=60000,60000", "cfg=ffbs,ffbs")
    ref_file = tmp_path / "reference.txt"
    ref = None
    try:
        for col, sig in enumerate(["x-pos-cmd", "x-pos-fb", "test-running"]):
            if sig == "test-running":
                m.halcmd("net", sig, "halui.program.is-running", "sampler.1.pin.2")
            else:
                m.halcmd("net", sig, f"sampler.1.pin.{col}")
        m.halcmd("net", "test-overruns", "sampler.1.overruns", "sampler.1.pin.3")
        with open(ref_file, "w") as out:
            ref = subprocess.Popen(["halsampler", "-c", "1", "-t"], stdout=out, stderr=subprocess.DEVNULL,
                                   **lx.lm.user_kwargs(m.user))
        m.halcmd("addf", "sampler.1", "servo-thread")
        res = lx.capture_run(m, progs, tmp_path / "log.mcap", port="linuxcnc://?channel=0")
        time.sleep(0.3)
    finally:
        m.halcmd("delf", "sampler.1", "servo-thread", check=False)
        if ref is not None:
            ref.terminate()
            ref.wait(10)
        for p in ("sampler.1.pin.0", "sampler.1.pin.1", "sampler.1.pin.2", "sampler.1.pin.3", "sampler.1.overruns"):
            m.halcmd("unlinkp", p, check=False)
        for sig in ("test-running", "test-overruns"):
            m.halcmd("delsig", sig, check=False)
        m.halcmd("unloadrt", "sampler", check=False)
    assert res.returncode == 0, res.stderr
    log = load_recording(tmp_path / "log.mcap")
    s = log.metadata["summary"]
    k = np.asarray(log.metadata["counter"])
    n = len(k)
    print(f"\ncapture: {n} samples at {1 / log.sample_period:.0f} Hz, dropped {s['dropped']}, end {s['end']}")
    assert log.sample_period == pytest.approx(0.001)
    assert (s["received"], s["dropped"], s["corrupt"], s["end"]) == (n, 0, 0, "program ended")
    np.testing.assert_array_equal(k, np.arange(k[0], k[0] + n))  # one sample per servo period
    assert set(np.unique(log.segment)) == {0}  # one continuous run: the loop runs on between programs

    r = _read_reference(ref_file)
    np.testing.assert_array_equal(r[:, 0], np.arange(r[0, 0], r[0, 0] + len(r)))  # the reference lost nothing
    cmd, act = log.axes["X"].commanded, log.axes["X"].actual
    moving = int(np.flatnonzero(np.diff(cmd))[0])  # the first commanded step locates the capture in it
    cand = np.flatnonzero((r[1:, 1] == cmd[moving + 1]) & (r[:-1, 1] == cmd[moving]))
    assert len(cand) == 1
    o = int(cand[0]) - moving
    assert 0 <= o and o + n <= len(r)
    np.testing.assert_array_equal(cmd, r[o:o + n, 1])
    np.testing.assert_array_equal(act, r[o:o + n, 2])
    running = np.flatnonzero(r[:, 3] == 1)
    assert o <= running[0] and running[-1] < o + n  # every period a program ran is in the capture
    print(f"reference: {len(r)} periods; the {len(running)} with a program running all captured, "
          f"commanded and actual identical in all {n}")


def test_an_inch_machine_is_recorded_in_mm_read_from_the_ini_it_runs(tmp_path):
    """HAL's positions are in the INI's units: on a machine of ``LINEAR_UNITS = inch`` the
    capture (no ``scale=``) reads the INI LinuxCNC was started with and records mm."""
    ini = tmp_path / "inch.ini"
    ini.write_text((lx.lm.HERE / "machine.ini").read_text().replace("LINEAR_UNITS = mm", "LINEAR_UNITS = inch"))
    prog = tmp_path / "half_inch.ngc"
    prog.write_text("G20 G90 G61 G1 X0.5 F30\nG4 P0.3\nG1 X0\nM2\n")  # an exact stop at 0.5 in
    lx.stop_machine()  # one LinuxCNC per computer
    m = lx.lm.Machine(ini=ini).start()
    try:
        res = lx.capture_run(m, [prog], tmp_path / "log.mcap")
    finally:
        m.stop()
    assert res.returncode == 0, res.stderr
    log = load_recording(tmp_path / "log.mcap")
    stream = log.metadata["stream"]
    assert "machine.ini: [TRAJ] LINEAR_UNITS" in stream["units_from"]
    assert stream["scale_to_mm"] == [25.4]
    assert log.axes["X"].commanded.max() == pytest.approx(12.7, abs=1e-9)  # 0.5 in


def test_capture_is_passive_the_netlist_is_unchanged(tmp_path):
    m = lx.machine()
    prog = tmp_path / "short.ngc"
    prog.write_text("G21 G90 G61.1\nG1 X3 F6000\nG1 X0\nM2\n")
    before = _netlist(m)
    res = lx.capture_run(m, [prog], tmp_path / "log.mcap")
    assert res.returncode == 0, res.stderr
    assert _netlist(m) == before
    log = load_recording(tmp_path / "log.mcap")
    assert log.metadata["summary"]["dropped"] == 0
    assert np.ptp(log.axes["X"].commanded) == pytest.approx(3.0, abs=1e-3)  # the planner splits the reversal period


# --- identification --------------------------------------------------------------------------

# --- diagnosis ------------------------------------------------------------------------------

def _identify_pair(m, tmp_path: Path) -> dict:
    """Capture an identification (seed 1) and a validation (seed 2) run; the identify JSON of axis X."""
    for seed in (1, 2):
        res = lx.capture_run(m, lx.generate(tmp_path / f"seed{seed}", seed), tmp_path / f"run{seed}.mcap")
        assert res.returncode == 0, res.stderr
    res = _agent("identify", str(tmp_path / "run1.mcap"), "--validate", str(tmp_path / "run2.mcap"),
                 "--json", str(tmp_path / "result.json"))
    assert res.returncode == 0, res.stderr
    return json.loads((tmp_path / "result.json").read_text())["axes"]["X"]


def _accepted(ax: dict) -> list[dict]:
    return [c for c in ax["diagnosis"]["candidates"] if c.get("accepted")]


def _print_diagnosis(name: str, d: dict) -> None:
    for c in d["candidates"]:
        print(f"\n  {c['effect']}: held-out fit {c['fit_before_pct']:.2f} % -> {c['fit_after_pct']:.2f} %, "
              f"accepted {c.get('accepted')}, {c['parameters']}", end="")
    print(f"\n{name}: verdict {d['verdict']}")


def test_identify_on_the_clean_machine_matches_the_hal_plant(tmp_path):
    """Identification and validation runs (seeds 1 and 2): validation fit >= 99 %, a2, d0 and
    d1 within 20 % of what the plant and pid gains imply, and nothing left out."""
    m = lx.machine()
    ax = _identify_pair(m, tmp_path)
    implied = lx.implied_model(m.plant, lx.pid_gains(m))
    fit = ax["fit"]["validation"]["tracking_error_fit_pct"]
    print(f"\nvalidation fit {fit:.2f} %; " + ", ".join(
        f"{p} {ax['model'][p]:.4g} (implied {implied[p]:.4g}, {100 * (ax['model'][p] / implied[p] - 1):+.1f} %)"
        for p in ("a1", "a2", "a3", "d0", "d1")), end="")
    _print_diagnosis("clean", ax["diagnosis"])
    assert fit >= 99.0
    for p in ("a2", "d0", "d1"):
        assert ax["model"][p] == pytest.approx(implied[p], rel=0.20), p
    assert ax["diagnosis"]["verdict"] == "none"


@pytest.mark.parametrize("overrides, verdict", [({"gap_mm": 0.02}, "backlash"), ({"static_n": 32.0}, "stribeck")],
                         ids=["backlash", "stiction"])
def test_diagnosis_names_the_physics_switched_on_in_the_hal_plant(tmp_path, overrides, verdict):
    m = lx.machine(**overrides)
    ax = _identify_pair(m, tmp_path)
    d = ax["diagnosis"]
    _print_diagnosis(str(overrides), d)
    assert d["verdict"] == verdict
    if verdict == "backlash":
        (c,) = _accepted(ax)
        assert c["parameters"]["gap_mm"] == pytest.approx(overrides["gap_mm"], rel=0.25)
        assert c["fit_after_pct"] > c["fit_before_pct"]
    if verdict == "stribeck":
        (c,) = _accepted(ax)
        assert c["fit_after_pct"] > c["fit_before_pct"]


def test_ctrl_c_ends_the_capture_cleanly_and_removes_the_sampler(tmp_path):
    """Ctrl-C on a terminal signals the whole foreground process group (halsampler too)."""
    m = lx.machine()
    before = _netlist(m)
    out = tmp_path / "log.mcap"
    proc = subprocess.Popen(lx.AGENT + ["capture", "--quiet", "--port", "linuxcnc://", "-o", str(out)], cwd=lx.ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    while not out.exists():
        assert proc.poll() is None, proc.stderr.read()
        time.sleep(0.05)
    time.sleep(1.0)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    s = load_recording(out).metadata["summary"]
    assert (s["end"], s["dropped"]) == ("interrupted", 0) and s["received"] > 900
    assert _netlist(m) == before

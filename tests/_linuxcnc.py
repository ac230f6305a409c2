"""The headless LinuxCNC test machine (fixtures/linuxcnc/) for the tests that capture from it.

* :func:`require_linuxcnc` skips a test, with a one-line reason, where LinuxCNC is not
  installed; :func:`machine` starts the machine (X, or X and Y) with some [PLANT] overrides
  (one LinuxCNC at a time on a computer: a machine with other axes or overrides is stopped
  first) and stops it at the end of the session;
* :func:`generate` writes identification programs with ``agent generate``;
* :func:`capture_run` captures while the machine runs programs, as a user would:
  ``agent capture --port linuxcnc://…`` in the background, then the programs, then waits
  for the capture to stop at the program end.
"""

from __future__ import annotations

import atexit
import importlib.util
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
AGENT = [sys.executable, "-m", "agent.cli"]

_spec = importlib.util.spec_from_file_location("linuxcnc_machine", ROOT / "fixtures/linuxcnc/machine.py")
lm = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(lm)

_current: dict = {"overrides": None, "machine": None}


def require_linuxcnc() -> None:
    why = lm.missing()
    if why:
        pytest.skip(why)


def machine(axes: str = "X", **overrides: float):
    """The running test machine with these axes (X or XY) and [PLANT] overrides (started, or
    restarted, as needed)."""
    require_linuxcnc()
    key = (axes, overrides)
    if _current["machine"] is not None and _current["overrides"] == key:
        return _current["machine"]
    stop_machine()
    m = lm.Machine(overrides, axes=axes).start()
    _current.update(overrides=key, machine=m)
    return m


def stop_machine() -> None:
    m = _current["machine"]
    if m is not None:
        _current.update(overrides=None, machine=None)
        m.stop()


atexit.register(stop_machine)


def generate(out: Path, seed: int, n_low: int = 200, n_high: int = 30, axes: str = "X") -> list[Path]:
    """The low- and high-speed identification programs, LinuxCNC dialect (about 1.2 + 3.5 s per axis)."""
    subprocess.run(AGENT + ["generate", "--axes", ",".join(axes), "--dialect", "linuxcnc", "--seed", str(seed),
                            "--n-low", str(n_low), "--n-high", str(n_high), "-o", str(out)],
                   check=True, capture_output=True, cwd=ROOT)
    return [out / "ident_low.ngc", out / "ident_high.ngc"]


def start_capture(port: str, out: Path) -> subprocess.Popen:
    """``agent capture`` in the background, returned once it is recording (its log exists)."""
    proc = subprocess.Popen(AGENT + ["capture", "--quiet", "--port", port, "-o", str(out)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    end = time.monotonic() + 30
    while not out.exists():
        if proc.poll() is not None:
            raise AssertionError(f"capture exited {proc.returncode}: {proc.stderr.read()}")
        assert time.monotonic() < end, "capture did not start within 30 s"
        time.sleep(0.05)
    time.sleep(0.2)  # a little standstill before the program
    return proc


def capture_run(m, programs: list[Path], out: Path, port: str = "linuxcnc://") -> subprocess.CompletedProcess:
    """Capture ``out`` while ``m`` runs ``programs``; the finished capture (it stops at the program end).

    The machine is switched off and on after the capture started, so the recording starts
    with pid's integrator at 0, as eq. 3.3 assumes (docs/linuxcnc.md).
    """
    proc = start_capture(port, out)
    try:
        m.run(*programs, restart=True)
        stdout, stderr = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)


def implied_model(plant: dict[str, float], gains: dict[str, float]) -> dict[str, float]:
    """The eq. 3.3 parameters the HAL plant and the pid gains imply (docs/linuxcnc.md).

    m ẍ = K u − c ẋ − F_c sgn ẋ (x in mm, so ẍ = 1000·F/m), u = P e + I ∫e + D ė + FF1 ẋ_r + FF2 ẍ_r.
    """
    k = 1000.0 * plant["FORCE_PER_VOLT"] / plant["MASS_KG"]  # mm/s² per V
    return {
        "a1": 1000.0 * plant["VISCOUS_N_PER_MM_S"] / plant["MASS_KG"] + k * gains["D"],
        "a2": k * gains["P"],
        "a3": k * gains["I"],
        "b0": k * gains["FF2"],
        "b1": k * (gains["D"] + gains["FF1"]),
        "b2": k * gains["P"],
        "d0": 1000.0 * plant["COULOMB_N"] / plant["MASS_KG"],
        "d1": -1000.0 * plant["COULOMB_N"] / plant["MASS_KG"],
    }


def pid_gains(m, joint: int = 0) -> dict[str, float]:
    """[JOINT_n] P, I, D, FF1, FF2 of the running machine's INI."""
    import configparser

    cp = configparser.ConfigParser(strict=False, interpolation=None)
    cp.optionxform = str
    cp.read(m.run_dir / "machine.ini")
    return {k: float(cp[f"JOINT_{joint}"][k]) for k in ("P", "I", "D", "FF1", "FF2")}

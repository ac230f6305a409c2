"""Recordings the benchmarks share: 25 s identification runs on each preset, and EMPS."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from scipy.io import loadmat

from virtual_cnc.machine_run import simulate as run_programs
from gcode_gen import dialects
from gcode_gen.excitation import identification_programs
from core.recording import AxisTrace, Recording

ROOT = Path(__file__).resolve().parents[1]
EMPS = ROOT.parent / "shared" / "data" / "emps" / "DATA_EMPS.mat"
PRESETS = ("fadal-ppi", "fadal-pid", "fadal-smc")


def program_files(seed: int, directory: Path) -> list[Path]:
    """The default identification set (X axis, LinuxCNC dialect) for ``seed``, written to ``directory``."""
    return [dialects.save(tp, "linuxcnc", directory) for tp in identification_programs(axes=("X",), seed=seed)]


def preset_recording(machine: str, seed: int = 1) -> Recording:
    with tempfile.TemporaryDirectory() as tmp:
        return run_programs(program_files(seed, Path(tmp)), machine, seed=seed)


def emps_recording() -> Recording | None:
    if not EMPS.exists():
        return None
    m = loadmat(EMPS)
    t = m["t"].ravel() - m["t"].ravel()[0]
    return Recording(t, {"X": AxisTrace(m["qg"].ravel() * 1e3, m["qm"].ravel() * 1e3)}, float(np.median(np.diff(t))))

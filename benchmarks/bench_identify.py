"""Wall time of `agent identify` on a 25 s, 1 kHz recording (issue 3: <= 2 s without the HTML report).

Measured two ways in one run: ``ident.identify`` in-process (after one warm-up,
so numba's on-disk cache is loaded), and the whole command as a user runs it
(`agent identify LOG --json OUT`, a fresh process: imports and cached JIT loading
included), with and without the diagnosis, and with the diagnosis scored on a validation
recording (a second program, seed 2, on the same drive: `--validate`) — the case issue 13's
speed target is stated for (<= 5 s).

    python benchmarks/bench_identify.py
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import ident
from _recordings import preset_recording
from core.writer import write_recording_mcap


def main() -> None:
    recording = preset_recording("fadal-pid")
    validation = preset_recording("fadal-pid", seed=2)
    with tempfile.TemporaryDirectory() as tmp:
        log = write_recording_mcap(recording, Path(tmp) / "pid.mcap")  # for the command-line runs
        val_log = write_recording_mcap(validation, Path(tmp) / "pid-validation.mcap")
        ident.identify(recording, diagnose=False)  # warm-up: numba cache, imports
        for label, opts in (("exact, no diagnosis", dict(diagnose=False)),
                            ("ga 4000x500, no diagnosis", dict(solver="ga", diagnose=False)),
                            ("exact + diagnosis", dict(diagnose=True)),
                            ("exact + diagnosis, validated", dict(diagnose=True, validate=validation))):
            t0 = time.perf_counter()
            res = ident.identify(recording, **opts)
            wall = time.perf_counter() - t0
            r = res.axes["X"]
            stages = ", ".join(f"{k} {v:.2f}" for k, v in r.timings.items())
            print(f"in-process  {label:28s} {wall:6.2f} s  (fit {r.fit_identification.tracking_error_fit_pct:.2f} %; {stages})")
        for label, extra in (("no diagnosis", ["--no-diagnose"]), ("with diagnosis", []),
                             ("diagnosis, validated", ["--validate", str(val_log)])):
            t0 = time.perf_counter()
            proc = subprocess.run([sys.executable, "-m", "agent.cli", "identify", str(log), "--json",
                                   str(Path(tmp) / "r.json"), *extra], capture_output=True, text=True)
            wall = time.perf_counter() - t0
            status = "ok" if proc.returncode == 0 else f"exit {proc.returncode}: {proc.stderr.strip()}"
            print(f"command     agent identify, {label:20s} {wall:6.2f} s  ({status})")


if __name__ == "__main__":
    main()

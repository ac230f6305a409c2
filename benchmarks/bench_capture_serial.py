"""Benchmark: capture 6 axes at 1 kHz over the simulated serial link (pseudo-terminal).

Runs ``agent serve --transport serial --recording SRC`` and ``agent capture`` as two
processes, as a user would, for ``--seconds`` of real time (default 60), and prints

* samples captured / expected and the drops and corrupt frames counted (target: 0),
* the capture process's CPU share while streaming (utime + stime from /proc/<pid>/stat,
  sampled once the log exists and as late as possible before the process ends, over the
  same wall interval; start-up imports are not included),
* MCAP writing alone (the recorder, in this process) as a multiple of real time,
* binary frame decoding alone as a multiple of real time.

Usage: ``python benchmarks/bench_capture_serial.py [--seconds 60] [--format binary|ascii]``
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from drivers.base import Sample
from drivers.recorder import McapRecorder, write_recording_mcap
from drivers.transports.serial_framing import BinaryCodec
from ident.loading import load_recording
from ident.recording import AxisTrace, Recording

AXES = "XYZABC"
AGENT = [sys.executable, "-m", "agent.cli"]
CLK = os.sysconf("SC_CLK_TCK")


def six_axis_recording(seconds: float, Ts: float = 0.001) -> Recording:
    n = int(round(seconds / Ts))
    rng = np.random.default_rng(0)
    axes = {}
    for a in AXES:
        c = np.cumsum(rng.normal(0, 0.005, n))
        axes[a] = AxisTrace(c, c + rng.normal(0, 5e-4, n))
    return Recording(np.arange(n) * Ts, axes, Ts, metadata={"controller": "benchmark 6-axis random walk"})


def cpu_s(pid: int) -> float | None:
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / CLK  # utime + stime (fields 14, 15)


def bench_transport(seconds: float, fmt: str, work: Path) -> dict:
    src = work / "src.mcap"
    rec = six_axis_recording(seconds)
    write_recording_mcap(rec, src)
    serve = subprocess.Popen(AGENT + ["serve", "-t", "serial", "--recording", str(src), "--opt", f"format={fmt}",
                                      "--linger", "1"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    port = serve.stdout.readline().split("port: ", 1)[1].strip()
    out = work / "cap.mcap"
    cap = subprocess.Popen(AGENT + ["capture", "--quiet", "--port", port, "-o", str(out)],
                           stderr=subprocess.PIPE, text=True)
    first = last = None
    while cap.poll() is None:
        c = cpu_s(cap.pid)
        now = time.monotonic()
        if c is not None:
            if first is None and out.exists():
                first = (now, c)
            elif first is not None:
                last = (now, c)
        time.sleep(0.25)
    err = cap.stderr.read()
    serve.wait(30)
    log = load_recording(out)
    s = log.metadata["summary"]
    share = (last[1] - first[1]) / (last[0] - first[0]) if first and last and last[0] > first[0] else float("nan")
    return {"expected": rec.n_samples, "captured": log.n_samples, "dropped": s["dropped"], "corrupt": s["corrupt"],
            "end": s["end"], "cpu_share": share, "returncode": cap.returncode, "stderr": err.strip()}


def bench_mcap_write(seconds: float, work: Path) -> float:
    rec = six_axis_recording(seconds)
    cmd = np.column_stack([rec.axes[a].commanded for a in AXES]).tolist()
    act = np.column_stack([rec.axes[a].actual for a in AXES]).tolist()
    samples = [Sample(k, k * 0.001, tuple(cmd[k]), tuple(act[k])) for k in range(rec.n_samples)]
    t0 = time.perf_counter()
    with McapRecorder(work / "w.mcap", list(AXES), 0.001, {}, flush_interval_s=0.5) as r:
        for s in samples:
            r.write(s)
    return seconds / (time.perf_counter() - t0)


def bench_decode(seconds: float) -> float:
    enc = BinaryCodec()
    rng = np.random.default_rng(1)
    n = int(seconds * 1000)
    vals = rng.integers(-10**6, 10**6, size=(n, 12)).tolist()
    data = b"".join(enc.encode_sample(k, 0, v[:6], v[6:]) for k, v in enumerate(vals))
    dec = BinaryCodec()
    t0 = time.perf_counter()
    for i in range(0, len(data), 4096):
        dec.feed(data[i:i + 4096])
    return seconds / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="length of the served run, s (default 60)")
    ap.add_argument("--format", default="binary", choices=["binary", "ascii"])
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        r = bench_transport(args.seconds, args.format, work)
        w = bench_mcap_write(min(args.seconds, 20.0), work)
    d = bench_decode(min(args.seconds, 20.0))
    print(f"serial ({args.format}) capture, 6 axes @ 1 kHz, {args.seconds:g} s served in real time:")
    print(f"  samples captured          {r['captured']} of {r['expected']}  (dropped {r['dropped']}, "
          f"corrupt {r['corrupt']}, end: {r['end']}, exit {r['returncode']})")
    print(f"  capture process CPU share {100 * r['cpu_share']:.1f} % of one core while streaming")
    print(f"  MCAP writing alone        {w:.1f} x real time")
    print(f"  binary decoding alone     {d:.1f} x real time")
    if r["returncode"] != 0:
        print(r["stderr"], file=sys.stderr)


if __name__ == "__main__":
    main()

"""Benchmark: capture 6 axes at 1 kHz from simulated CiA 402 drives over python-can udp_multicast.

Runs ``agent serve --transport can --recording SRC`` (six CANopen nodes + the SYNC
producer: 7 frames per 1 ms tick, one 8-byte TPDO per axis carrying 0x6062 and 0x6064)
and ``agent capture`` as two processes, as a user would, for ``--seconds`` of real time
(default 60), and prints

* samples captured / expected and the drops and corrupt frames counted (target: 0),
* the CPU share of the capture process and of the serving process while streaming
  (utime + stime from /proc/<pid>/stat over the same wall interval; start-up excluded),
* MCAP writing alone (the recorder, in this process) as a multiple of real time,
* frame handling alone (CanDriver reading pre-queued frames from python-can's in-process
  ``virtual`` bus: unpack, assemble ticks) as a multiple of real time.

Usage: ``python benchmarks/bench_capture_can.py [--seconds 60] [--protocol canopen|dbc]``
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import can
import numpy as np

from drivers.base import Sample
from drivers.endpoints.can_endpoint import CanEndpoint
from drivers.endpoints.source import RealTimeSource, stream_info_for
from drivers.recorder import McapRecorder, write_recording_mcap
from drivers.registry import open_driver
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


def bench_transport(seconds: float, protocol: str, work: Path) -> dict:
    src = work / "src.mcap"
    rec = six_axis_recording(seconds)
    write_recording_mcap(rec, src)
    serve = subprocess.Popen(AGENT + ["serve", "-t", "can", "--recording", str(src), "--opt", f"protocol={protocol}",
                                      "--linger", "1"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    port = serve.stdout.readline().split("port: ", 1)[1].strip()
    out = work / "cap.mcap"
    cap = subprocess.Popen(AGENT + ["capture", "--quiet", "--port", port, "-o", str(out)],
                           stderr=subprocess.PIPE, text=True)
    first = last = None
    while cap.poll() is None:
        c, s = cpu_s(cap.pid), cpu_s(serve.pid)
        now = time.monotonic()
        if c is not None and s is not None:
            if first is None and out.exists():
                time.sleep(1.0)  # past the SDO reads and the start of the program
                first = (time.monotonic(), cpu_s(cap.pid), cpu_s(serve.pid))
            elif first is not None:
                last = (now, c, s)
        time.sleep(0.25)
    err = cap.stderr.read()
    serve.wait(30)
    log = load_recording(out)
    s = log.metadata["summary"]
    if first and last and last[0] > first[0]:
        wall = last[0] - first[0]
        cap_share, serve_share = (last[1] - first[1]) / wall, (last[2] - first[2]) / wall
    else:
        cap_share = serve_share = float("nan")
    return {"expected": rec.n_samples, "captured": log.n_samples, "dropped": s["dropped"], "corrupt": s["corrupt"],
            "end": s["end"], "cpu_share": cap_share, "serve_share": serve_share, "returncode": cap.returncode,
            "stderr": err.strip()}


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



def bench_frames(seconds: float, protocol: str) -> float:
    """Driver frame handling alone: frames pre-queued on a virtual bus, drained by CanDriver.read."""
    rec = six_axis_recording(seconds)
    src = RealTimeSource(rec, speed=float("inf"))
    ep = CanEndpoint(src, stream_info_for(rec), {"interface": "virtual", "channel": "bench", "wait": False,
                                                 "protocol": protocol, "linger": 0})
    ep.start()
    drv = open_driver(ep.port_url() + ("&sdo=0" if protocol == "canopen" else ""))
    drv.open()
    ep.run()  # speed=inf: every frame is queued in the driver's virtual bus now
    n = 0
    t0 = time.perf_counter()
    while not drv.ended:
        n += len(drv.read(0.05))
    dt = time.perf_counter() - t0
    drv.close()
    ep.close()
    assert n == rec.n_samples, (n, rec.n_samples)
    return seconds / dt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="length of the served run, s (default 60)")
    ap.add_argument("--protocol", default="canopen", choices=["canopen", "dbc"])
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        r = bench_transport(args.seconds, args.protocol, work)
        w = bench_mcap_write(min(args.seconds, 20.0), work)
    f = bench_frames(min(args.seconds, 10.0), args.protocol)
    print(f"CAN ({args.protocol}, udp_multicast) capture, 6 axes @ 1 kHz = 7000 frames/s, "
          f"{args.seconds:g} s served in real time:")
    print(f"  samples captured          {r['captured']} of {r['expected']}  (dropped {r['dropped']}, "
          f"corrupt {r['corrupt']}, end: {r['end']}, exit {r['returncode']})")
    print(f"  capture process CPU share {100 * r['cpu_share']:.1f} % of one core while streaming")
    print(f"  serving process CPU share {100 * r['serve_share']:.1f} % of one core (simulated drives)")
    print(f"  MCAP writing alone        {w:.1f} x real time")
    print(f"  frame handling alone      {f:.1f} x real time (CanDriver on the in-process virtual bus)")
    if r["returncode"] != 0:
        print(r["stderr"], file=sys.stderr)


if __name__ == "__main__":
    main()

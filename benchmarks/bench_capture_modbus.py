"""Benchmark: capture 6 axes at 1 kHz over the simulated Modbus controller (TCP and RTU).

Runs ``agent serve --transport modbus --recording SRC`` and ``agent capture`` as two
processes, as a user would, for ``--seconds`` of real time (default 60) per case:

* trace-buffer upload over TCP on 127.0.0.1 (the way to get 1 kHz through Modbus),
* live polling over TCP (one read of counter + positions per poll),
* trace-buffer upload over RTU on a pseudo-terminal (``--rtu``; a pty has no baud rate,
  so this measures the protocol stack, not a real 115200-baud line),

and prints per case: samples captured / expected, drops and corrupt responses counted
(target for trace mode: 0 drops), the Modbus requests the capture sent (from the
endpoint's count, all FC 3) per second, and the capture process's CPU share while
streaming (utime + stime from /proc/<pid>/stat over the same wall interval).  Then, in
this process: MCAP writing alone and trace-record decoding alone as multiples of real time.

Usage: ``python benchmarks/bench_capture_modbus.py [--seconds 60] [--modes trace,live] [--rtu]``
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from drivers.base import Sample
from drivers.endpoints.modbus_endpoint import encode_records
from drivers.endpoints.source import RealTimeSource
from drivers.modbus_map import default_map
from drivers.recorder import McapRecorder, write_recording_mcap
from drivers.transports.modbus import ModbusDriver
from drivers.url import parse_port_url
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


def bench_case(src: Path, n: int, link: str, mode: str, work: Path) -> dict:
    faults = work / f"faults-{link}-{mode}.json"
    serve = subprocess.Popen(AGENT + ["serve", "-t", "modbus", "--recording", str(src), "--opt", f"link={link}",
                                      "--opt", f"mode={mode}", "--linger", "1", "--fault-log", str(faults)],
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    port = serve.stdout.readline().split("port: ", 1)[1].strip()
    out = work / f"cap-{link}-{mode}.mcap"
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
    serve.wait(60)
    log = load_recording(out)
    s = log.metadata["summary"]
    report = json.loads(faults.read_text())
    requests = sum(report.get("function_codes", {}).values())
    share = (last[1] - first[1]) / (last[0] - first[0]) if first and last and last[0] > first[0] else float("nan")
    return {"expected": n, "captured": log.n_samples, "dropped": s["dropped"], "corrupt": s["corrupt"],
            "end": s["end"], "cpu_share": share, "returncode": cap.returncode, "stderr": err.strip(),
            "requests_per_s": requests / (n * 0.001), "codes": sorted(report.get("function_codes", {}))}


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
    """Decode trace records (as read, 4 per 108-register request) into Samples, no I/O."""
    rec = six_axis_recording(seconds)
    rmap = default_map(list(AXES))
    records = encode_records(RealTimeSource(rec), rmap)
    drv = ModbusDriver(parse_port_url("modbus-tcp://127.0.0.1:1"))
    drv.rmap, drv.period = rmap, 0.001
    drv._cols = list(range(len(AXES)))
    drv._scale = np.array([a.scale_mm for a in rmap.axes])
    drv._prepare_decoders(rmap)
    per = drv._per_read
    t0 = time.perf_counter()
    got = 0
    for c in range(0, len(records), per):
        got += len(drv.decode_records(c, records[c:c + per]))
    assert got == len(records)
    return seconds / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="length of each served run, s (default 60)")
    ap.add_argument("--modes", default="trace,live", help="comma list of trace, live (TCP)")
    ap.add_argument("--rtu", action="store_true", help="also trace mode over RTU on a pseudo-terminal")
    args = ap.parse_args()
    cases = [("tcp", m.strip()) for m in args.modes.split(",") if m.strip()]
    if args.rtu:
        cases.append(("rtu", "trace"))
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        rec = six_axis_recording(args.seconds)
        src = work / "src.mcap"
        write_recording_mcap(rec, src)
        for link, mode in cases:
            results[(link, mode)] = bench_case(src, rec.n_samples, link, mode, work)
        w = bench_mcap_write(min(args.seconds, 20.0), work)
    d = bench_decode(min(args.seconds, 20.0))
    print(f"Modbus capture, 6 axes @ 1 kHz, {args.seconds:g} s served in real time per case:")
    for (link, mode), r in results.items():
        print(f"  {link} {mode:5s}: captured {r['captured']} of {r['expected']} "
              f"({100 * r['captured'] / r['expected']:.2f} %), dropped {r['dropped']}, corrupt {r['corrupt']}, "
              f"end: {r['end']}, exit {r['returncode']}")
        print(f"             {r['requests_per_s']:.0f} read requests/s (function codes {','.join(r['codes'])}), "
              f"capture process CPU {100 * r['cpu_share']:.1f} % of one core while streaming")
        if r["returncode"] != 0:
            print("             " + r["stderr"], file=sys.stderr)
    print(f"  MCAP writing alone           {w:.1f} x real time")
    print(f"  trace-record decoding alone  {d:.1f} x real time")


if __name__ == "__main__":
    main()

"""Benchmark: capture 6 axes at 1 kHz over the simulated serial, Modbus and CAN links.

For each transport asked for, runs ``agent serve --transport T --recording SRC`` and
``agent capture`` as two processes, as a user would, for ``--seconds`` of real time
(default 60) per case, and prints

* samples captured / expected and the drops and corrupt frames counted (target: 0; Modbus
  live polling is never exact and its share of ticks seen is the figure),
* the capture process's CPU share while streaming (utime + stime from /proc/<pid>/stat,
  sampled once the log exists and as late as possible before the process ends, over the
  same wall interval; start-up imports are not included), and for CAN also the serving
  process's (the simulated drives),
* the transport's decoding alone (in this process, no I/O) as a multiple of real time.

The cases per transport:

* serial: CRC-32 framed binary or checksummed ASCII over a pseudo-terminal (``--format``);
* modbus: trace-buffer upload (the way to get 1 kHz through Modbus) and live polling over
  TCP on 127.0.0.1 (``--modes``), plus trace upload over RTU on a pseudo-terminal
  (``--rtu``; a pty has no baud rate, so this measures the protocol stack, not a real
  115200-baud line); it also prints the Modbus requests the capture sent per second (from
  the endpoint's count, all FC 3);
* can: six CiA 402 nodes + the SYNC producer over python-can udp_multicast, 7 frames per
  1 ms tick, one 8-byte TPDO per axis carrying 0x6062 and 0x6064 (``--protocol canopen``),
  or DBC frames (``--protocol dbc``); frame handling alone is CanDriver reading pre-queued
  frames from python-can's in-process ``virtual`` bus (unpack, assemble ticks).

Last, MCAP writing alone (the recorder, in this process) as a multiple of real time.

Usage: ``python benchmarks/bench_capture.py [--transport serial|modbus|can|all] [--seconds 60]
[--format binary|ascii] [--modes trace,live] [--rtu] [--protocol canopen|dbc]``
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from drivers.base import Sample
from drivers.endpoints.can_endpoint import CanEndpoint
from drivers.endpoints.modbus_endpoint import encode_records
from drivers.endpoints.source import RealTimeSource, stream_info_for
from drivers.modbus_map import default_map
from core.writer import McapRecorder, write_recording_mcap
from drivers.registry import open_driver
from drivers.transports.modbus import ModbusDriver
from drivers.transports.serial_framing import BinaryCodec
from drivers.url import parse_port_url
from core.reader import load_recording
from core.recording import AxisTrace, Recording

AXES = "XYZABC"
Ts = 0.001  # s, the served sample period (1 kHz)
AGENT = [sys.executable, "-m", "agent.cli"]
CLK = os.sysconf("SC_CLK_TCK")
TRANSPORTS = ("serial", "modbus", "can")


def six_axis_recording(seconds: float) -> Recording:
    """A random walk on 6 axes at 1 kHz, ``seconds`` s long (positions in mm, seed 0)."""
    n = int(round(seconds / Ts))
    rng = np.random.default_rng(0)
    axes = {}
    for a in AXES:
        c = np.cumsum(rng.normal(0, 0.005, n))
        axes[a] = AxisTrace(c, c + rng.normal(0, 5e-4, n))
    return Recording(np.arange(n) * Ts, axes, Ts, metadata={"controller": "benchmark 6-axis random walk"})


def cpu_s(pid: int) -> float | None:
    """CPU time (s) the process has used so far, or None once it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / CLK  # utime + stime (fields 14, 15)


def cpu_shares(cap: subprocess.Popen, pids: list[int], out: Path, settle_s: float = 0.0) -> list[float]:
    """Poll until ``cap`` exits; the CPU share (of one core) of each of ``pids`` while streaming.

    The window opens when the capture's log ``out`` first exists (``settle_s`` s later, to skip
    a start-up phase) and closes at the last poll before the capture ends.
    """
    first = last = None
    while cap.poll() is None:
        cpu = [cpu_s(p) for p in pids]
        now = time.monotonic()
        if None not in cpu:
            if first is None and out.exists():
                if settle_s:
                    time.sleep(settle_s)
                    now, cpu = time.monotonic(), [cpu_s(p) for p in pids]
                first = (now, cpu)
            elif first is not None:
                last = (now, cpu)
        time.sleep(0.25)
    if first and last and last[0] > first[0]:
        wall = last[0] - first[0]
        return [(b - a) / wall for a, b in zip(first[1], last[1])]
    return [float("nan")] * len(pids)


def stream(transport: str, src: Path, n: int, opts: list[str], work: Path, name: str,
           settle_s: float = 0.0, serve_share: bool = False, fault_log: Path | None = None) -> dict:
    """Serve ``src`` in real time over ``transport`` (``--opt`` k=v in ``opts``) and capture it.

    Returns the counts from the captured log's summary, the capture's exit code and stderr,
    ``cpu_share`` of the capture process and, with ``serve_share``, of the serving process.
    """
    extra = ["--fault-log", str(fault_log)] if fault_log else []
    serve = subprocess.Popen(AGENT + ["serve", "-t", transport, "--recording", str(src),
                                      *[a for o in opts for a in ("--opt", o)], "--linger", "1", *extra],
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    port = serve.stdout.readline().split("port: ", 1)[1].strip()
    out = work / f"cap-{name}.mcap"
    cap = subprocess.Popen(AGENT + ["capture", "--quiet", "--port", port, "-o", str(out)],
                           stderr=subprocess.PIPE, text=True)
    shares = cpu_shares(cap, [cap.pid, serve.pid] if serve_share else [cap.pid], out, settle_s)
    err = cap.stderr.read()
    serve.wait(60)
    log = load_recording(out)
    s = log.metadata["summary"]
    return {"expected": n, "captured": log.n_samples, "dropped": s["dropped"], "corrupt": s["corrupt"],
            "end": s["end"], "cpu_share": shares[0], "serve_share": shares[1] if serve_share else None,
            "returncode": cap.returncode, "stderr": err.strip()}


def print_streaming(r: dict) -> None:
    print(f"  samples captured          {r['captured']} of {r['expected']}  (dropped {r['dropped']}, "
          f"corrupt {r['corrupt']}, end: {r['end']}, exit {r['returncode']})")
    print(f"  capture process CPU share {100 * r['cpu_share']:.1f} % of one core while streaming")


def print_failure(r: dict, indent: str = "") -> None:
    if r["returncode"] != 0:
        print(indent + r["stderr"], file=sys.stderr)


# --- decoding alone, per transport (in this process, no I/O) --------------------------------

def serial_decode_rate(seconds: float) -> float:
    """Binary frame decoding alone, × real time."""
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


def modbus_decode_rate(seconds: float) -> float:
    """Decode trace records (as read, 4 per 108-register request) into Samples, × real time."""
    rec = six_axis_recording(seconds)
    rmap = default_map(list(AXES))
    records = encode_records(RealTimeSource(rec), rmap)
    drv = ModbusDriver(parse_port_url("modbus-tcp://127.0.0.1:1"))
    drv.rmap, drv.period = rmap, Ts
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


def can_frame_rate(seconds: float, protocol: str) -> float:
    """Driver frame handling alone: frames pre-queued on a virtual bus, drained by CanDriver.read; × real time."""
    rec = six_axis_recording(seconds)
    src = RealTimeSource(rec, speed=float("inf"))
    ep = CanEndpoint(src, stream_info_for(rec), {"interface": "virtual", "channel": "bench", "wait": False,
                                                 "protocol": protocol, "linger": 0})
    ep.start()
    drv = open_driver(ep.port_url() + ("&sdo=0" if protocol == "canopen" else ""))
    opener = threading.Thread(target=drv.open)  # opening waits for the first frame
    opener.start()
    while drv._bus is None and opener.is_alive():
        time.sleep(0.001)
    ep.run()  # speed=inf: every frame is queued in the driver's virtual bus now
    opener.join()
    n = 0
    t0 = time.perf_counter()
    while not drv.ended:
        n += len(drv.read(0.05))
    dt = time.perf_counter() - t0
    drv.close()
    ep.close()
    assert n == rec.n_samples, (n, rec.n_samples)
    return seconds / dt


def mcap_write_rate(seconds: float, work: Path) -> float:
    """The MCAP recorder alone writing 6-axis samples, × real time."""
    rec = six_axis_recording(seconds)
    cmd = np.column_stack([rec.axes[a].commanded for a in AXES]).tolist()
    act = np.column_stack([rec.axes[a].actual for a in AXES]).tolist()
    samples = [Sample(k, k * Ts, tuple(cmd[k]), tuple(act[k])) for k in range(rec.n_samples)]
    t0 = time.perf_counter()
    with McapRecorder(work / "w.mcap", list(AXES), Ts, {}, flush_interval_s=0.5) as r:
        for s in samples:
            r.write(s)
    return seconds / (time.perf_counter() - t0)


# --- one section per transport ---------------------------------------------------------------

def bench_serial(args: argparse.Namespace, src: Path, n: int, work: Path) -> None:
    r = stream("serial", src, n, [f"format={args.format}"], work, "serial")
    d = serial_decode_rate(min(args.seconds, 20.0))
    print(f"serial ({args.format}) capture, 6 axes @ 1 kHz, {args.seconds:g} s served in real time:")
    print_streaming(r)
    print(f"  binary decoding alone     {d:.1f} x real time")
    print_failure(r)


def bench_modbus(args: argparse.Namespace, src: Path, n: int, work: Path) -> None:
    cases = [("tcp", m.strip()) for m in args.modes.split(",") if m.strip()]
    if args.rtu:
        cases.append(("rtu", "trace"))
    results = {}
    for link, mode in cases:
        faults = work / f"faults-{link}-{mode}.json"
        r = stream("modbus", src, n, [f"link={link}", f"mode={mode}"], work, f"modbus-{link}-{mode}",
                   fault_log=faults)
        codes = json.loads(faults.read_text()).get("function_codes", {})
        r["requests_per_s"], r["codes"] = sum(codes.values()) / (n * Ts), sorted(codes)
        results[(link, mode)] = r
    d = modbus_decode_rate(min(args.seconds, 20.0))
    print(f"Modbus capture, 6 axes @ 1 kHz, {args.seconds:g} s served in real time per case:")
    for (link, mode), r in results.items():
        print(f"  {link} {mode:5s}: captured {r['captured']} of {r['expected']} "
              f"({100 * r['captured'] / r['expected']:.2f} %), dropped {r['dropped']}, corrupt {r['corrupt']}, "
              f"end: {r['end']}, exit {r['returncode']}")
        print(f"             {r['requests_per_s']:.0f} read requests/s (function codes {','.join(r['codes'])}), "
              f"capture process CPU {100 * r['cpu_share']:.1f} % of one core while streaming")
        print_failure(r, indent="             ")
    print(f"  trace-record decoding alone  {d:.1f} x real time")


def bench_can(args: argparse.Namespace, src: Path, n: int, work: Path) -> None:
    # settle 1 s: past the SDO reads and the start of the program
    r = stream("can", src, n, [f"protocol={args.protocol}"], work, "can", settle_s=1.0, serve_share=True)
    f = can_frame_rate(min(args.seconds, 10.0), args.protocol)
    print(f"CAN ({args.protocol}, udp_multicast) capture, 6 axes @ 1 kHz = 7000 frames/s, "
          f"{args.seconds:g} s served in real time:")
    print_streaming(r)
    print(f"  serving process CPU share {100 * r['serve_share']:.1f} % of one core (simulated drives)")
    print(f"  frame handling alone      {f:.1f} x real time (CanDriver on the in-process virtual bus)")
    print_failure(r)


BENCHES = {"serial": bench_serial, "modbus": bench_modbus, "can": bench_can}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--transport", default="all", choices=[*TRANSPORTS, "all"], help="which link (default all)")
    ap.add_argument("--seconds", type=float, default=60.0, help="length of each served run, s (default 60)")
    ap.add_argument("--format", default="binary", choices=["binary", "ascii"], help="serial: frame format")
    ap.add_argument("--modes", default="trace,live", help="modbus: comma list of trace, live (TCP)")
    ap.add_argument("--rtu", action="store_true", help="modbus: also trace mode over RTU on a pseudo-terminal")
    ap.add_argument("--protocol", default="canopen", choices=["canopen", "dbc"], help="can: frame layout")
    args = ap.parse_args()
    transports = TRANSPORTS if args.transport == "all" else (args.transport,)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        rec = six_axis_recording(args.seconds)
        src = work / "src.mcap"
        write_recording_mcap(rec, src)
        for transport in transports:
            BENCHES[transport](args, src, rec.n_samples, work)
            sys.stdout.flush()
        w = mcap_write_rate(min(args.seconds, 20.0), work)
    print(f"MCAP writing alone          {w:.1f} x real time")


if __name__ == "__main__":
    main()

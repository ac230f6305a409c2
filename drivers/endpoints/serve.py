"""The ``agent serve`` workflow: run programs on the virtual CNC, then serve the result in real time.

Steps: build the :class:`~core.recording.Recording` (the G-code programs through
:func:`virtual_cnc.machine_run.simulate`, or an existing log given with
``recording=``), wrap it in a :class:`~drivers.endpoints.source.RealTimeSource` with the
fault plan, pick the transport's endpoint from :data:`ENDPOINTS`, start it, print
``port: <url>`` (shell-quoted where the URL needs it) as the FIRST line of stdout (flushed: a test or script reads it to know
where to capture from), write the fault log, serve, and on the way out rewrite the
fault log with what the endpoint did (ticks not sent because of a disconnect, and a
timeline of what had been sent when).

SIGINT/SIGTERM stop serving early and still close the endpoint.
"""

from __future__ import annotations

import importlib
import json
import shlex
import signal
import sys
import threading
from pathlib import Path
from typing import Any, Sequence, TextIO

from core.errors import InputError, TransportError
from drivers.endpoints.base import Endpoint, parse_endpoint_options
from drivers.endpoints.source import FaultPlan, RealTimeSource, stream_info_for
from core.recording import Recording

__all__ = ["ENDPOINTS", "endpoint_class", "build_recording", "serve"]

#: transport name (``--transport``) -> (module, class); imported only when used
ENDPOINTS: dict[str, tuple[str, str]] = {
    "serial": ("drivers.endpoints.serial_endpoint", "SerialEndpoint"),
    "modbus": ("drivers.endpoints.modbus_endpoint", "ModbusEndpoint"),
    "can": ("drivers.endpoints.can_endpoint", "CanEndpoint"),
}


def endpoint_class(transport: str) -> type[Endpoint]:
    """The endpoint class serving ``transport``; one-line errors for unknown or unloadable ones."""
    try:
        module_name, class_name = ENDPOINTS[transport]
    except KeyError:
        raise InputError.about("transport", f"transport {transport!r} is not known (known: {', '.join(ENDPOINTS)})") from None
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise TransportError(f"the {transport} endpoint cannot be loaded: {exc}") from exc
    return getattr(module, class_name)


def build_recording(programs: Sequence[str | Path] = (), machine: str | Path | None = None,
                    effects: Sequence[str] = (), seed: int = 0,
                    recording: str | Path | None = None) -> Recording:
    """The samples to serve: the programs run on the virtual CNC, or a recorded log replayed."""
    if recording is not None:
        if programs:
            raise InputError("give either programs or a recording to serve, not both")
        from core.reader import load_recording

        return load_recording(recording)
    if not programs:
        raise InputError.about("programs", "no program to serve; give a G-code program (or a recording to replay)")
    for p in programs:
        if not Path(p).is_file():
            raise InputError.about("programs", f"{p}: no such file")
    try:
        from virtual_cnc.machine_run import simulate as run_programs
    except ImportError as exc:
        raise TransportError(f"the virtual CNC is not available: {exc}") from exc
    return run_programs([Path(p) for p in programs], machine=machine, effects=list(effects), seed=seed)


def serve(
    transport: str,
    recording: Recording,
    speed: float = 1.0,
    faults: FaultPlan | None = None,
    options: dict[str, Any] | list[str] | None = None,
    fault_log: str | Path | None = None,
    stdout: TextIO | None = None,
) -> dict:
    """Serve ``recording`` over ``transport`` in real time; returns the fault/endpoint report.

    Parameters
    ----------
    transport : ``serial``, ``modbus`` or ``can`` (keys of :data:`ENDPOINTS`).
    recording : what the controller "runs" (positions in mm, controller sample period).
    speed : 1.0 real time, 2.0 twice as fast.
    faults : dropped/corrupted ticks and a disconnect time in s of controller time.
    options : endpoint options, typed dict or ``["NAME=VALUE", ...]`` strings.
    fault_log : JSON file to write the injected faults to (written before serving
        starts, rewritten at the end with the endpoint's report).
    stdout : where the ``port: <url>`` line goes (default sys.stdout).
    """
    if not speed > 0:
        raise InputError.about("speed", f"speed must be > 0, got {speed}")
    faults = faults or FaultPlan()
    for name, rate in (("drop_rate", faults.drop_rate), ("corrupt_rate", faults.corrupt_rate)):
        if not 0 <= rate < 1:
            raise InputError.about(name, f"{name.replace('_', ' ')} must be in [0, 1), got {rate}")
    if faults.drop_rate + faults.corrupt_rate >= 1:
        raise InputError("drop rate + corrupt rate must stay below 1")
    cls = endpoint_class(transport)
    if isinstance(options, list):
        options = parse_endpoint_options(cls, options)
    source = RealTimeSource(recording, speed=speed, faults=faults)
    endpoint = cls(source, stream_info_for(recording), options or {})
    stdout = stdout or sys.stdout
    old_handlers = {}
    if threading.current_thread() is threading.main_thread():
        def _stop(signum, frame):  # noqa: ANN001
            endpoint.stop_event.set()

        old_handlers = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    report = source.fault_report()
    try:
        endpoint.start()
        url = endpoint.port_url()
        if speed != 1.0:  # the capture's clock check then expects this controller to run `speed` x real time
            url += f"{'&' if '?' in url else '?'}replay_speed={speed:g}"
        # quoted for the shell: a URL's ? and & would break the pasted command line
        print(f"port: {shlex.quote(url)}", file=stdout, flush=True)
        if fault_log:
            _write_json(fault_log, report)
        endpoint.run()
    finally:
        endpoint.close()
        for s, h in old_handlers.items():
            signal.signal(s, h)
        report.update(endpoint.report())
        report["stopped_early"] = endpoint.stop_event.is_set()
        if fault_log:
            _write_json(fault_log, report)
    return report


def _write_json(path: str | Path, data: dict) -> None:
    try:
        tmp = Path(str(path) + ".tmp")
        tmp.write_text(json.dumps(data))
        tmp.replace(path)
    except OSError as exc:
        raise InputError.about("fault_log", f"{path}: cannot write ({exc.strerror})") from exc

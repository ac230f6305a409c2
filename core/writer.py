"""Write recordings to MCAP as samples arrive (capture) or all at once (simulate), and to CSV.

:class:`McapRecorder` is a context manager: samples are appended as they arrive and
the file is flushed (the open chunk finished and written) at least every
``flush_interval_s`` seconds of host time, so a capture killed with SIGKILL loses at
most that much; :meth:`McapRecorder.close` writes the summary metadata and the MCAP
footer and is idempotent.  Timestamps are controller-clock nanoseconds (see
:mod:`core.log_format`).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from mcap.writer import CompressionType, Writer

from core.errors import InputError
from core.log_format import (
    EVENT_SCHEMA,
    EVENT_SCHEMA_NAME,
    END_REASONS,
    EVENTS_TOPIC,
    FORMAT,
    SAMPLE_SCHEMA_NAME,
    SAMPLES_TOPIC,
    SUMMARY_METADATA,
    sample_schema,
)
from core.recording import Recording, Sample

__all__ = ["McapRecorder", "write_recording_mcap", "write_recording_csv"]


class McapRecorder:
    """Append controller samples to an MCAP file.

    Parameters
    ----------
    path : output ``.mcap`` file (overwritten).
    axes : axis names, in the order of :attr:`Sample.commanded`.
    sample_period : controller sample period T_s in s.
    metadata : extra channel metadata (transport, controller, programs, units, machine ...);
        values are converted to strings (lists/dicts as JSON).
    flush_interval_s : host seconds between flushes (1.0 keeps a SIGKILL loss under 1 s).
    """

    def __init__(
        self,
        path: str | Path,
        axes: Sequence[str],
        sample_period: float,
        metadata: dict[str, Any] | None = None,
        flush_interval_s: float = 1.0,
    ) -> None:
        if not axes:
            raise InputError("no axes to record")
        if not sample_period > 0:
            raise InputError(f"sample period must be > 0 s, got {sample_period}")
        self.path = Path(path)
        self.axes = list(axes)
        self.sample_period = float(sample_period)
        self.flush_interval_s = flush_interval_s
        self.count = 0
        self._closed = False
        self._seq = 0
        self._last_flush = time.monotonic()
        self._t0_ns: int | None = None
        try:
            self._file = open(self.path, "wb")
        except OSError as exc:
            raise InputError(f"cannot write {self.path}: {exc.strerror}") from exc
        # ZSTD chunks; flushing every second keeps chunks small enough for a 1 s loss bound.
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="", library=f"rapid-ident ({FORMAT})")
        meta = {
            "format": FORMAT,
            "sample_period_s": repr(self.sample_period),
            "axes": ",".join(self.axes),
            "units": ",".join(["mm"] * len(self.axes)),
        }
        for key, value in (metadata or {}).items():
            meta[key] = value if isinstance(value, str) else json.dumps(value)
        self.channel_metadata = meta
        sid = self._writer.register_schema(SAMPLE_SCHEMA_NAME, "jsonschema", sample_schema(self.axes))
        self._samples = self._writer.register_channel(SAMPLES_TOPIC, "json", sid, meta)
        eid = self._writer.register_schema(EVENT_SCHEMA_NAME, "jsonschema", EVENT_SCHEMA)
        self._events = self._writer.register_channel(EVENTS_TOPIC, "json", eid, {})
        self._writer.flush()

    # -- writing -----------------------------------------------------------------------
    def write(self, sample: Sample, receive_time_ns: int | None = None) -> None:
        """Append one sample tick (all axes)."""
        log_ns = int(round(sample.t_s * 1e9))
        msg = {
            "counter": sample.counter,
            "t": sample.t_s,
            "segment": sample.segment,
            "commanded": dict(zip(self.axes, sample.commanded)),
            "actual": dict(zip(self.axes, sample.actual)),
        }
        self._writer.add_message(
            self._samples,
            log_time=max(log_ns, 0),
            data=json.dumps(msg, separators=(",", ":")).encode(),
            publish_time=receive_time_ns if receive_time_ns is not None else time.time_ns(),
            sequence=self._seq & 0xFFFFFFFF,
        )
        self._seq += 1
        self.count += 1
        self.maybe_flush()

    def event(self, kind: str, counter: int = 0, count: int = 0, message: str = "") -> None:
        """Record a capture event (dropped, corrupt, reconnect, segment, note) at controller time."""
        t_ns = max(int(round(counter * self.sample_period * 1e9)), 0)
        data = {"kind": kind, "counter": int(counter), "count": int(count), "message": message}
        self._writer.add_message(self._events, log_time=t_ns, data=json.dumps(data).encode(),
                                 publish_time=time.time_ns(), sequence=0)
        self.maybe_flush()

    def maybe_flush(self) -> None:
        now = time.monotonic()
        if now - self._last_flush >= self.flush_interval_s:
            self.flush()

    def flush(self) -> None:
        """Finish the open chunk and push it to the OS (not fsync)."""
        self._writer.flush()
        self._last_flush = time.monotonic()

    def close(self, summary: dict[str, Any] | None = None) -> None:
        """Write the ``rapid-ident.summary`` metadata and the footer; idempotent."""
        if self._closed:
            return
        end = (summary or {}).get("end")
        if end is not None and end not in END_REASONS:  # the documented list is the only one
            raise ValueError(f"end reason {end!r} is not one of core.log_format.END_REASONS")
        self._closed = True
        summ = {"samples": str(self.count)}
        for key, value in (summary or {}).items():
            summ[key] = value if isinstance(value, str) else json.dumps(value)
        self._writer.add_metadata(SUMMARY_METADATA, summ)
        self._writer.finish()
        self._file.close()

    def __enter__(self) -> "McapRecorder":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close({"end": "error" if exc_type else "finished"})


def _recording_meta(recording: Recording, extra: dict[str, Any] | None) -> dict[str, Any]:
    meta = {k: v for k, v in recording.metadata.items() if k not in ("dropped", "corrupt")}
    meta.update(extra or {})
    return meta


def write_recording_mcap(recording: Recording, path: str | Path, metadata: dict[str, Any] | None = None) -> Path:
    """Write a whole in-memory recording (e.g. from ``agent simulate``) in the capture layout."""
    axes = recording.axis_names
    cmd = np.column_stack([recording.axes[a].commanded for a in axes]).tolist()
    act = np.column_stack([recording.axes[a].actual for a in axes]).tolist()
    counters = np.rint(recording.t / recording.sample_period).astype(np.int64).tolist()
    t = recording.t.tolist()
    seg = recording.segment.tolist()
    now = time.time_ns()
    with McapRecorder(path, axes, recording.sample_period, _recording_meta(recording, metadata),
                      flush_interval_s=float("inf")) as rec:
        last_seg = None
        for k in range(recording.n_samples):
            if seg[k] != last_seg:
                rec.event("segment", counters[k], seg[k], f"segment {seg[k]} starts")
                last_seg = seg[k]
            rec.write(Sample(counters[k], t[k], tuple(cmd[k]), tuple(act[k]), seg[k]), now)
        rec.close({"end": "finished", "dropped": 0, "corrupt": 0})
    return Path(path)


def write_recording_csv(recording: Recording, path: str | Path) -> Path:
    """Write SPEC §4 CSV: ``t_s``, then ``<AXIS>_commanded_mm,<AXIS>_actual_mm`` per axis, then ``segment``."""
    axes = recording.axis_names
    cols = [recording.t]
    header = ["t_s"]
    for a in axes:
        header += [f"{a}_commanded_mm", f"{a}_actual_mm"]
        cols += [recording.axes[a].commanded, recording.axes[a].actual]
    header.append("segment")
    cols.append(recording.segment.astype(float))
    data = np.column_stack(cols)
    fmt = ["%.9g"] + ["%.10g"] * (2 * len(axes)) + ["%d"]
    try:
        np.savetxt(path, data, delimiter=",", header=",".join(header), comments="", fmt=fmt)
    except OSError as exc:
        raise InputError(f"cannot write {path}: {exc.strerror}") from exc
    return Path(path)

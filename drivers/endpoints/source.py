"""Pace a recording out in real time, with seeded fault injection, for the simulated endpoints.

Every endpoint (serial, Modbus, CAN) takes its samples from a :class:`RealTimeSource`:
it runs the virtual CNC result (a :class:`Recording`) forward at the controller's
sample rate against the wall clock and tells the transport which ticks to send,
which to drop and which to corrupt.  The fault plan is decided up front from a seed,
so a test can compare what a capture counted with what was injected, exactly.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from drivers.base import Sample, StreamInfo
from core.recording import Recording

__all__ = ["FaultPlan", "RealTimeSource", "stream_info_for"]


@dataclass(frozen=True)
class FaultPlan:
    """Faults to inject: fractions of ticks dropped / corrupted, and a disconnect time.

    ``drop_rate`` and ``corrupt_rate`` are probabilities per sample tick (0..1);
    ``disconnect_at_s`` closes the connection once at that controller time (the
    endpoint accepts a new connection afterwards when it can), ``None`` never.
    """

    drop_rate: float = 0.0
    corrupt_rate: float = 0.0
    disconnect_at_s: float | None = None
    seed: int = 0

    def masks(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Boolean (dropped, corrupted) masks over n ticks; a tick is never both."""
        rng = np.random.default_rng(self.seed)
        u = rng.random(n)
        drop = u < self.drop_rate
        corrupt = (~drop) & (u < self.drop_rate + self.corrupt_rate)
        # Never fault the first and last tick: the capture needs to see the start and the end.
        drop[[0, -1]] = False
        corrupt[[0, -1]] = False
        return drop, corrupt


@dataclass
class RealTimeSource:
    """Iterate a recording's ticks in batches, paced to the wall clock.

    Parameters
    ----------
    recording : the virtual CNC result to serve (commanded/actual per axis, mm).
    speed : 1.0 = real time; 2.0 = twice as fast (tests); ``inf`` = as fast as possible.
    faults : what to inject.
    batch_s : how much controller time each :meth:`batches` step covers (s).
    """

    recording: Recording
    speed: float = 1.0
    faults: FaultPlan = field(default_factory=FaultPlan)
    batch_s: float = 0.005

    def __post_init__(self) -> None:
        rec = self.recording
        self.axes = tuple(rec.axis_names)
        self.n = rec.n_samples
        self.counter = np.rint(rec.t / rec.sample_period).astype(np.int64)
        self.commanded = np.column_stack([rec.axes[a].commanded for a in self.axes])
        self.actual = np.column_stack([rec.axes[a].actual for a in self.axes])
        self.dropped, self.corrupted = self.faults.masks(self.n)

    def sample(self, k: int) -> Sample:
        rec = self.recording
        return Sample(int(self.counter[k]), float(rec.t[k]), tuple(self.commanded[k].tolist()),
                      tuple(self.actual[k].tolist()), int(rec.segment[k]))

    def batches(self) -> Iterator[tuple[range, float]]:
        """Yield (tick indices due now, controller time) in order, sleeping to keep pace."""
        per = max(1, int(round(self.batch_s / self.recording.sample_period)))
        start = time.monotonic()
        for k0 in range(0, self.n, per):
            k1 = min(k0 + per, self.n)
            due = (self.recording.t[k1 - 1] - self.recording.t[0]) / self.speed
            delay = start + due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            yield range(k0, k1), float(self.recording.t[k1 - 1])

    def fault_report(self) -> dict:
        """What was injected, by controller counter (for tests and the serve log)."""
        return {
            "samples": int(self.n),
            "dropped": int(self.dropped.sum()),
            "corrupted": int(self.corrupted.sum()),
            "dropped_counters": self.counter[self.dropped].tolist(),
            "corrupted_counters": self.counter[self.corrupted].tolist(),
            "disconnect_at_s": self.faults.disconnect_at_s,
        }

    def write_fault_report(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.fault_report()))


def stream_info_for(recording: Recording) -> StreamInfo:
    """The StreamInfo an endpoint announces for a recording made by the virtual CNC."""
    meta = recording.metadata
    return StreamInfo(
        axes=tuple(recording.axis_names),
        sample_period=recording.sample_period,
        controller=str(meta.get("controller", "rapid-ident virtual CNC")),
        units=tuple(["mm"] * len(recording.axes)),
        programs=tuple(meta.get("programs", ())),
    )

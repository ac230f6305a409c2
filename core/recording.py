"""The in-memory recording: what every stage after capture works on.

Array layout (the one convention of the project, see ``docs/recording-format.md``):
time runs along axis 0; every per-sample array has shape ``(N,)``; one
:class:`AxisTrace` per axis holds commanded and actual position in mm (degrees for
rotary axes) on the controller's own sample clock ``t`` in seconds.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

__all__ = ["AxisTrace", "Recording", "Sample"]


@dataclass(frozen=True)
class AxisTrace:
    """Commanded and actual position of one axis, mm (deg for rotary axes), shape (N,)."""

    commanded: np.ndarray
    actual: np.ndarray

    @property
    def tracking_error(self) -> np.ndarray:
        """e = commanded - actual, mm."""
        return self.commanded - self.actual


@dataclass
class Recording:
    """A recording of one or more axes.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Controller time in s: sample counter x period, from the controller's counter 0 (a
        simulation starts there; a capture starts wherever the controller's counter stood).
    axes : dict[str, AxisTrace]
        Per-axis traces, in the recorded axis order (e.g. ``{"X": ..., "Y": ...}``).
    sample_period : float
        Nominal controller sample period T_s in s.
    segment : ndarray of int, shape (N,)
        Index of the program (or capture segment) each sample belongs to; the low- and
        high-speed identification sets are segments 0 and 1.  Never differentiate or
        integrate across a change of segment.
    metadata : dict
        Free-form description: ``units``, ``transport``, ``controller``, ``programs``
        (list of ``{"name", "sha256"}``), ``dropped``, ``corrupt``, ``machine`` ...
    """

    t: np.ndarray
    axes: dict[str, AxisTrace]
    sample_period: float
    segment: np.ndarray = field(default=None)  # type: ignore[assignment]
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, dtype=float)
        n = self.t.shape[0]
        if self.segment is None:
            self.segment = np.zeros(n, dtype=np.int32)
        else:
            self.segment = np.asarray(self.segment, dtype=np.int32)
        for name, tr in self.axes.items():
            if tr.commanded.shape != (n,) or tr.actual.shape != (n,):
                raise ValueError(
                    f"axis {name}: commanded {tr.commanded.shape} and actual {tr.actual.shape} "
                    f"must both have shape ({n},) like t"
                )
        if self.segment.shape != (n,):
            raise ValueError(f"segment has shape {self.segment.shape}, expected ({n},)")

    @classmethod
    def from_arrays(
        cls,
        t: Any,
        commanded: Mapping[str, Any],
        actual: Mapping[str, Any],
        *,
        segment: Any = None,
        sample_period: float | None = None,
        metadata: dict[str, Any] | None = None,
    ) -> "Recording":
        """A recording from arrays in memory, e.g. a controller scope export.

        Parameters
        ----------
        t : array_like (N,)
            Sample times, s, increasing.
        commanded, actual : mapping axis name -> array_like (N,)
            Commanded and actual position per axis, mm (deg for rotary axes); the same axes.
        segment : array_like of int (N,), optional
            Program/segment index per sample (default one segment).
        sample_period : float, optional
            Controller sample period, s; default the median step of ``t``.
        metadata : dict, optional
            Free-form description (``controller``, ``units`` ...).
        """
        from core.errors import RecordingError

        t = np.asarray(t, dtype=float)
        if t.ndim != 1 or t.size < 2:
            raise RecordingError(f"t must be a 1-D array of at least 2 sample times, got shape {t.shape}")
        if set(commanded) != set(actual):
            raise RecordingError(f"commanded has axes {sorted(commanded)} but actual has {sorted(actual)}")
        if sample_period is None:
            sample_period = float(np.median(np.diff(t)))
        if not sample_period > 0:
            raise RecordingError(f"sample period must be > 0 s, got {sample_period}")
        axes = {}
        for name in commanded:
            x_r = np.asarray(commanded[name], dtype=float)
            x = np.asarray(actual[name], dtype=float)
            if x_r.shape != t.shape or x.shape != t.shape:
                raise RecordingError(f"axis {name}: commanded {x_r.shape} and actual {x.shape} must both "
                                     f"have the shape of t {t.shape}")
            axes[str(name).upper()] = AxisTrace(x_r, x)
        return cls(t=t, axes=axes, sample_period=float(sample_period), segment=segment,
                   metadata=dict(metadata or {}))

    @property
    def n_samples(self) -> int:
        return int(self.t.shape[0])

    @property
    def axis_names(self) -> list[str]:
        return list(self.axes)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if self.n_samples > 1 else 0.0

    def segments(self) -> list[slice]:
        """Contiguous slices of samples that share a segment index, in time order."""
        if self.n_samples == 0:
            return []
        cuts = np.flatnonzero(np.diff(self.segment) != 0) + 1
        bounds = np.concatenate([[0], cuts, [self.n_samples]])
        return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]

    def select(self, index: slice | np.ndarray) -> "Recording":
        """A new recording holding only the samples ``index`` (a slice or boolean/int array)."""
        return Recording(
            t=self.t[index],
            axes={k: AxisTrace(v.commanded[index], v.actual[index]) for k, v in self.axes.items()},
            sample_period=self.sample_period,
            segment=self.segment[index],
            metadata=dict(self.metadata),
        )


@dataclass(frozen=True)
class Sample:
    """One controller sample tick, every axis.

    ``counter`` is the controller's sample counter (monotonic, wraps handled by the
    driver); ``t_s`` = counter x sample period, in s, controller clock.  Positions in
    mm (deg for rotary axes), in the order of :attr:`StreamInfo.axes`.
    """

    counter: int
    t_s: float
    commanded: tuple[float, ...]
    actual: tuple[float, ...]
    segment: int = 0

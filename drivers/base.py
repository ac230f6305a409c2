"""The transport-independent driver interface (one class per transport subclasses it).

A driver opens a connection to a controller, streams :class:`Sample` batches stamped
with the controller's own sample counter, and keeps :class:`CaptureStats`.  It is
passive: it may read, and may send only the non-moving frames its module docstring
names (a Modbus read, a CAN SYNC when asked) — never a write that could move an axis.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass, field
from typing import Any, ClassVar

from core.recording import Sample
from drivers.url import PortURL

__all__ = ["Sample", "StreamInfo", "CaptureStats", "Driver"]


@dataclass(frozen=True)
class StreamInfo:
    """What a controller says about its stream once opened."""

    axes: tuple[str, ...]
    sample_period: float  # s
    controller: str = ""  # free text: make/model/firmware or "rapid-ident virtual CNC (preset ...)"
    units: tuple[str, ...] = ()  # per axis, "mm" or "deg"; empty means all mm
    programs: tuple[dict[str, str], ...] = ()  # [{"name":..., "sha256":...}] when the controller knows
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass
class CaptureStats:
    """Running counts kept by a driver.

    Drivers leave ``dropped`` at 0 for losses that show as a gap in the sample counter:
    the capture loop counts those (drivers.capture).  A driver adds to ``dropped`` only
    losses it knows of that cannot show as a gap.  ``corrupt`` counts frames rejected by
    a checksum or format check; ``reconnects`` successful re-opens.  ``skipped`` counts
    sample records that arrived intact but could not be made into a sample (a Modbus
    trace slot not holding its counter, a CAN tick missing an axis' PDO): not a loss
    count of its own (such ticks show as counter gaps too), but the capture loop compares
    ``received`` with everything read to catch a capture that reads data and records none.
    """

    received: int = 0
    dropped: int = 0
    corrupt: int = 0  # frames/lines/responses rejected by a checksum or a format check
    reconnects: int = 0
    skipped: int = 0  # intact sample records that could not be used

    def as_dict(self) -> dict[str, int]:
        return {"received": self.received, "dropped": self.dropped, "corrupt": self.corrupt,
                "reconnects": self.reconnects, "skipped": self.skipped}


class Driver(abc.ABC):
    """Base class of every transport driver.

    Subclasses set ``schemes`` (the URL schemes they serve), implement :meth:`_open`,
    :meth:`_read` and :meth:`_close`.  The base supplies the context manager, the
    statistics and the end-of-program flag.
    """

    schemes: ClassVar[tuple[str, ...]] = ()
    #: URL query options this driver accepts, name -> type (int, float, str, bool)
    options: ClassVar[dict[str, type]] = {}

    def __init__(self, url: PortURL, axes: list[str] | None = None) -> None:
        url.check_options(self.options)
        self.url = url
        self.wanted_axes = axes
        self.stats = CaptureStats()
        self.info: StreamInfo | None = None
        #: set by the driver when the controller signals the program has ended
        self.ended = False
        #: (counter of the newest sample the running controller has made, host time.monotonic()
        #: s by which it had made it), set by a transport that reports it (a trace ring's head);
        #: None: the newest sample read stands for it.  The clock check reads it, so that a
        #: reader falling behind a ring is not taken for a slow controller clock.
        self.newest: tuple[int, float] | None = None
        #: one-line warnings about the stream the driver raised since the capture last took
        #: them (e.g. a trace ring that overran); the capture records and prints each once
        self.notices: list[str] = []
        self._is_open = False

    # -- public API -----------------------------------------------------------------
    def open(self) -> StreamInfo:
        """Connect and return the stream description; raises TransportError."""
        self.info = self._open()
        self._is_open = True
        return self.info

    def read(self, timeout: float = 0.5) -> list[Sample]:
        """Samples received since the last call (possibly none), waiting at most ``timeout`` s."""
        if not self._is_open:
            raise RuntimeError("driver not open")
        return self._read(timeout)

    def close(self) -> None:
        """Release the connection; idempotent."""
        if self._is_open:
            self._is_open = False
            self._close()

    def unusable_reason(self) -> str:
        """Why the records counted in ``stats.skipped`` could not be used, in the driver's terms
        (e.g. which map field to check); "" when the driver cannot tell."""
        return ""

    def position_hint(self, axis: str) -> str:
        """Where the position scale and word order of ``axis`` are set, for a plausibility warning."""
        return "the position scale the controller announces"

    def __enter__(self) -> "Driver":
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- for subclasses -------------------------------------------------------------
    @abc.abstractmethod
    def _open(self) -> StreamInfo: ...

    @abc.abstractmethod
    def _read(self, timeout: float) -> list[Sample]: ...

    @abc.abstractmethod
    def _close(self) -> None: ...

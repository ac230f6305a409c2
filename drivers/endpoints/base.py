"""The interface of a simulated controller endpoint (serial, Modbus, CAN), used by ``agent serve``.

An endpoint takes samples from a :class:`~drivers.endpoints.source.RealTimeSource`
(the virtual CNC result paced against the wall clock, with its fault plan) and puts
them on its transport the way a real controller would.  Life cycle, driven by
:func:`drivers.endpoints.serve.serve`::

    ep = EndpointClass(source, info, options)
    ep.start()                # open the pty / bind the socket / join the bus
    print("port:", ep.port_url())   # what `agent capture --port` takes
    ep.run()                  # serve every tick (honouring drops/corruptions/disconnect),
                              # then keep the connection up for `linger_s` seconds
    ep.close()                # idempotent

Fault injection is the endpoint's job because only it knows what a dropped or a
corrupted frame looks like on its wire: a tick with ``source.dropped[k]`` is not sent
at all; a tick with ``source.corrupted[k]`` is sent damaged so that the receiver's
check (CRC, checksum, range check) rejects it; at controller time
``source.faults.disconnect_at_s`` the connection is broken once (each endpoint documents
what that looks like on its transport).  Endpoints listen on loopback only (SPEC §8).
"""

from __future__ import annotations

import abc
import threading
import time
from typing import Any, ClassVar

from core.errors import InputError
from drivers.base import StreamInfo
from drivers.endpoints.source import RealTimeSource

__all__ = ["Endpoint", "parse_endpoint_options"]


class Endpoint(abc.ABC):
    """Base class of the simulated endpoints.

    Parameters
    ----------
    source : the ticks to serve, paced in real time, with the fault plan.
    info : what the endpoint announces (axes, sample period in s, controller, programs).
    options : endpoint options, already typed by :func:`parse_endpoint_options`
        (``linger`` in s is common to all; the others are per transport, see
        :attr:`option_types`).

    Subclasses set ``name`` and ``option_types`` and implement :meth:`start`,
    :meth:`port_url`, :meth:`serve_ticks` and :meth:`_close`.  The base supplies
    :meth:`run` (serve, then linger), the stop event and the context manager.
    """

    #: transport name as given to ``agent serve --transport``
    name: ClassVar[str] = ""
    #: endpoint-specific options, name -> type (int, float, str, bool); ``linger`` is always accepted
    option_types: ClassVar[dict[str, type]] = {}
    #: default linger after the last tick, s (lets a capture see the end-of-program marker)
    default_linger_s: ClassVar[float] = 1.0

    def __init__(self, source: RealTimeSource, info: StreamInfo, options: dict[str, Any] | None = None) -> None:
        options = dict(options or {})
        unknown = sorted(set(options) - set(self.option_types) - {"linger"})
        if unknown:
            known = ", ".join(sorted(set(self.option_types) | {"linger"}))
            raise InputError(f"{self.name} endpoint: unknown option {unknown[0]!r} (known: {known})")
        self.source = source
        self.info = info
        self.options = options
        self.linger_s = float(options.get("linger", self.default_linger_s))
        if self.linger_s < 0:
            raise InputError.about("linger", f"linger must be >= 0 s, got {self.linger_s}")
        #: set to stop serving early (SIGINT/SIGTERM in ``agent serve``)
        self.stop_event = threading.Event()
        #: controller counters of ticks not put on the wire for reasons outside the fault
        #: plan (disconnected, nobody listening, send buffer full); in the fault log
        self.unsent_counters: list[int] = []
        #: (host Unix time s, last counter sent) about every 50 ms; lets a test tell what
        #: had been sent when it killed a capture
        self.sent_timeline: list[tuple[float, int]] = []
        self._closed = False

    # -- to implement -------------------------------------------------------------------
    @abc.abstractmethod
    def start(self) -> None:
        """Open the transport (pty, socket, bus) so that :meth:`port_url` is valid."""

    @abc.abstractmethod
    def port_url(self) -> str:
        """The ``--port`` URL a capture uses to reach this endpoint (valid after :meth:`start`)."""

    @abc.abstractmethod
    def serve_ticks(self) -> None:
        """Serve every tick of ``self.source`` (iterate ``self.source.batches()``), honouring
        the fault plan; return early when ``self.stop_event`` is set."""

    @abc.abstractmethod
    def _close(self) -> None:
        """Release the transport."""

    # -- provided -----------------------------------------------------------------------
    def note_sent(self, counter: int) -> None:
        """Record that ticks up to ``counter`` are on the wire (call once per batch)."""
        now = time.time()
        if not self.sent_timeline or now - self.sent_timeline[-1][0] >= 0.05:
            self.sent_timeline.append((now, int(counter)))

    def report(self) -> dict[str, Any]:
        """What the endpoint did beyond the fault plan (merged into ``--fault-log``)."""
        return {"unsent_counters": list(self.unsent_counters), "sent_timeline": list(self.sent_timeline)}

    def linger(self) -> None:
        """Keep the connection up after the program so the capture sees the end; overridable."""
        self.stop_event.wait(self.linger_s)

    def run(self) -> None:
        """Serve the whole program in real time, then linger; blocks."""
        self.serve_ticks()
        if not self.stop_event.is_set():
            self.linger()

    def close(self) -> None:
        """Release the transport; idempotent."""
        if not self._closed:
            self._closed = True
            self._close()

    def __enter__(self) -> "Endpoint":
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}


def parse_endpoint_options(cls: type[Endpoint], pairs: list[str]) -> dict[str, Any]:
    """Turn ``["format=ascii", "baud=115200"]`` (``agent serve --opt``) into typed options."""
    types = dict(cls.option_types, linger=float)
    out: dict[str, Any] = {}
    for pair in pairs:
        if "=" not in pair:
            raise InputError.about("options", f"{pair!r}: expected NAME=VALUE")
        key, text = (s.strip() for s in pair.split("=", 1))
        if key not in types:
            known = ", ".join(sorted(types))
            raise InputError.about("options", f"{key!r}: not an option of the {cls.name} endpoint (known: {known})")
        kind = types[key]
        try:
            if kind is bool:
                if text.lower() in _TRUE:
                    value: Any = True
                elif text.lower() in _FALSE:
                    value = False
                else:
                    raise ValueError(text)
            else:
                value = kind(text)
        except ValueError:
            raise InputError.about("options", f"{key}={text!r} is not a valid {kind.__name__}") from None
        out[key] = value
    return out

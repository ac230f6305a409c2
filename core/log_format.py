"""The rapid-ident MCAP log layout (format ``rapid-ident/1``), shared by writer and loader.

One MCAP file per capture or simulation (documented in docs/recording-format.md):

* topic ``/samples`` (JSON, schema ``rapid_ident.Sample``): one message per controller
  sample tick carrying every axis::

      {"counter": 1234, "t": 1.234, "segment": 0,
       "commanded": {"X": 1.2345, "Y": -0.5}, "actual": {"X": 1.2331, "Y": -0.5004}}

  ``log_time`` = ``t`` in integer ns, i.e. the controller's own sample counter x period:
  it starts wherever the controller's counter stood (0 for ``agent simulate``, the
  controller's running counter for a capture), never at the host clock;
  ``publish_time`` = host receive time in ns since the Unix epoch.
  Positions in mm (deg for rotary axes).  In Foxglove, plot ``/samples.commanded.X``
  against ``/samples.actual.X``.
* topic ``/events`` (JSON, schema ``rapid_ident.Event``): gaps, corrupt frames,
  reconnects, segment (program) starts, plausibility warnings and the end, as they happen
  (kinds: :data:`EVENT_KINDS`).
* the ``/samples`` channel metadata holds what is known at the start: sample period,
  axes, units, transport, controller, programs.
* an MCAP metadata record ``rapid-ident.summary`` written when the recording closes
  cleanly: counts of received, dropped and corrupt samples and why it ended (``end``,
  one of :data:`END_REASONS`, with ``error`` saying what went wrong, empty if nothing
  did).  A log without it was cut off (e.g. the capture was killed).

:data:`END_REASONS` and :data:`EVENT_KINDS` are the lists docs/recording-format.md
documents; tests/test_log_docs.py checks that the document and these lists agree.
"""

from __future__ import annotations

import json

FORMAT = "rapid-ident/1"
SAMPLES_TOPIC = "/samples"
EVENTS_TOPIC = "/events"
SUMMARY_METADATA = "rapid-ident.summary"

SAMPLE_SCHEMA_NAME = "rapid_ident.Sample"
EVENT_SCHEMA_NAME = "rapid_ident.Event"

#: Every value the summary's ``end`` takes -> when (the capture loop in drivers/capture.py
#: and the writer in core/writer.py use these names and no others).
END_REASONS: dict[str, str] = {
    "program ended": "the controller signalled the end of the program",
    "duration": "the requested duration of controller time has been recorded",
    "duration (host clock)": "the requested duration + 1 s of host time has passed "
                             "(a controller slower than announced, or silent)",
    "interrupted": "Ctrl-C (SIGINT)",
    "terminated": "SIGTERM",
    "transport error": "the link failed for good (port gone, connection not re-established, bus silent)",
    "unusable data": "the controller sent data but (almost) none of it could be recorded, "
                     "e.g. trace records whose counters never match (word order or map layout)",
    "controller restarted": "the controller's sample counter went back and counted on (a restart): "
                            "what follows is a new run, for a new capture",
    "clock mismatch": "the controller's clock ran much faster or slower than the host's "
                      "(a wrong sample period or counter word order): its times would be wrong",
    "finished": "agent simulate: the whole simulated run was written",
    "error": "an unexpected error stopped the recording (the summary's error names it)",
}
#: The end reasons after which ``agent capture`` exits non-zero (the summary's ``error`` says why).
FAILED_ENDS = frozenset({"transport error", "unusable data", "controller restarted", "clock mismatch", "error"})

#: Every ``kind`` of an ``/events`` message -> what it marks.
EVENT_KINDS: dict[str, str] = {
    "dropped": "samples missing from a gap in the controller's counter (count = how many)",
    "corrupt": "frames rejected by a checksum or format check (count = how many)",
    "reconnect": "the link was re-established",
    "segment": "a program (segment) starts (count = its index)",
    "warning": "the data looks implausible (e.g. a position jumping faster than any feed drive moves)",
    "end": "the recording ended: message = the end reason and, if any, the error",
    "note": "anything else worth keeping with the log",
}


def sample_schema(axes: list[str]) -> bytes:
    """JSON Schema of a ``/samples`` message for the given axes (lets Foxglove list the fields)."""
    per_axis = {"type": "object", "properties": {a: {"type": "number"} for a in axes}}
    schema = {
        "title": SAMPLE_SCHEMA_NAME,
        "type": "object",
        "properties": {
            "counter": {"type": "integer", "description": "controller sample counter"},
            "t": {"type": "number", "description": "controller time, s"},
            "segment": {"type": "integer", "description": "program/segment index"},
            "commanded": dict(per_axis, description="commanded position, mm (deg rotary)"),
            "actual": dict(per_axis, description="actual (encoder) position, mm (deg rotary)"),
        },
    }
    return json.dumps(schema).encode()


EVENT_SCHEMA = json.dumps(
    {
        "title": EVENT_SCHEMA_NAME,
        "type": "object",
        "properties": {
            "kind": {"type": "string", "description": " | ".join(EVENT_KINDS)},
            "counter": {"type": "integer"},
            "count": {"type": "integer"},
            "message": {"type": "string"},
        },
    }
).encode()

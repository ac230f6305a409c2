"""The rapid-ident MCAP log layout (format ``rapid-ident/1``), shared by writer and loader.

One MCAP file per capture or simulation (documented in docs/recording-format.md):

* topic ``/samples`` (JSON, schema ``rapid_ident.Sample``): one message per controller
  sample tick carrying every axis::

      {"counter": 1234, "t": 1.234, "segment": 0,
       "commanded": {"X": 1.2345, "Y": -0.5}, "actual": {"X": 1.2331, "Y": -0.5004}}

  ``log_time`` = controller time (counter x period) in integer ns from the start of the
  recording; ``publish_time`` = host receive time in ns since the Unix epoch.
  Positions in mm (deg for rotary axes).  In Foxglove, plot ``/samples.commanded.X``
  against ``/samples.actual.X``.
* topic ``/events`` (JSON, schema ``rapid_ident.Event``): gaps, corrupt frames,
  reconnects and segment (program) starts, as they happen.
* the ``/samples`` channel metadata holds what is known at the start: sample period,
  axes, units, transport, controller, programs.
* an MCAP metadata record ``rapid-ident.summary`` written when the recording closes
  cleanly: counts of received, dropped and corrupt samples and why it ended.  A log
  without it was cut off (e.g. the capture was killed).
"""

from __future__ import annotations

import json

FORMAT = "rapid-ident/1"
SAMPLES_TOPIC = "/samples"
EVENTS_TOPIC = "/events"
SUMMARY_METADATA = "rapid-ident.summary"

SAMPLE_SCHEMA_NAME = "rapid_ident.Sample"
EVENT_SCHEMA_NAME = "rapid_ident.Event"


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
            "kind": {"type": "string", "description": "dropped | corrupt | reconnect | segment | note"},
            "counter": {"type": "integer"},
            "count": {"type": "integer"},
            "message": {"type": "string"},
        },
    }
).encode()

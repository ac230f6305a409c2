"""The documents say what a log contains: the `end` values, the event kinds and the time origin
that docs/recording-format.md and docs/capture.md describe are the ones a capture writes.

The lists live once, in core.log_format (END_REASONS, EVENT_KINDS); the tables in the
documents are compared with them, and real captures (a serial controller on a pseudo-terminal)
are compared with the tables.
"""

from __future__ import annotations

import json
import re
import threading
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from core.log_format import END_REASONS, EVENT_KINDS, FAILED_ENDS
from core.reader import load_mcap
from core.recording import AxisTrace, Recording
from core.writer import write_recording_mcap
from drivers.capture import capture
from drivers.endpoints.serial_endpoint import SerialEndpoint
from drivers.endpoints.source import FaultPlan, RealTimeSource, stream_info_for

DOCS = Path(__file__).resolve().parents[1] / "docs"


def doc_table(doc: str, header: str) -> list[list[str]]:
    """Rows (cells stripped, backticks removed) of the Markdown table in ``doc`` whose header
    row starts with the cell ``header``."""
    lines = (DOCS / doc).read_text().splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith(f"| {header} |"))
    rows = []
    for ln in lines[start + 2:]:
        if not ln.startswith("|"):
            break
        rows.append([c.strip().replace("`", "") for c in ln.strip("|").split(" | ")])
    return rows


def documented_ends() -> list[str]:
    return [row[0] for row in doc_table("recording-format.md", "end")]


def test_recording_format_lists_exactly_the_end_reasons_the_code_uses():
    assert documented_ends() == list(END_REASONS)
    failed = {row[0] for row in doc_table("recording-format.md", "end") if "*failed*" in row[1]}
    assert failed == FAILED_ENDS


def test_capture_doc_lists_every_capture_end_with_its_exit_status():
    rows = doc_table("capture.md", "end reason (summary `end`)")
    assert [r[0] for r in rows] == [e for e in END_REASONS if e != "finished"]
    assert {r[0] for r in rows if not r[2].startswith("0")} == FAILED_ENDS


def test_recording_format_lists_exactly_the_event_kinds():
    assert [row[0] for row in doc_table("recording-format.md", "kind")] == list(EVENT_KINDS)


# -- what real logs contain ----------------------------------------------------------------------

COUNTER0 = 504_200  # a controller that has been counting for 504.2 s at 1 kHz


def walk(n: int, counter0: int) -> Recording:
    rng = np.random.default_rng(3)
    c = np.cumsum(rng.normal(0, 0.01, n))
    return Recording((counter0 + np.arange(n)) * 0.001, {"X": AxisTrace(c, c + 0.001)}, 0.001,
                     metadata={"controller": "doc test", "programs": []})


@contextmanager
def serial_controller(rec: Recording, faults: FaultPlan | None = None):
    ep = SerialEndpoint(RealTimeSource(rec, speed=4.0, faults=faults or FaultPlan()), stream_info_for(rec), {})
    ep.start()
    th = threading.Thread(target=ep.run, daemon=True)
    th.start()
    try:
        yield ep.port_url()
    finally:
        ep.stop_event.set()
        th.join(5)
        ep.close()


def first_log_times(path: Path) -> tuple[int, float]:
    """(log_time, t) of the first /samples message, read with the mcap library alone."""
    with open(path, "rb") as fh:
        for _schema, _channel, message in make_reader(fh).iter_messages(topics=["/samples"]):
            return message.log_time, json.loads(message.data)["t"]
    raise AssertionError("no /samples message")


@pytest.mark.parametrize("how, expected_end", [
    ("to the end of the program", "program ended"),
    ("for a duration", "duration"),
    ("of frames that all fail their CRC", "unusable data"),
])
def test_a_capture_writes_a_documented_end_and_keeps_the_controllers_time_origin(tmp_path, how, expected_end):
    rec = walk(400, COUNTER0)
    faults = FaultPlan(corrupt_rate=1.0) if expected_end == "unusable data" else None
    with serial_controller(rec, faults) as port:
        s = capture(port, tmp_path / "a.mcap", progress=False,
                    duration=0.2 if expected_end == "duration" else None)
    log = load_mcap(tmp_path / "a.mcap")
    end = log.metadata["summary"]["end"]
    assert end == s.end == expected_end
    assert end in documented_ends()
    assert (end in FAILED_ENDS) == bool(s.error)
    events = log.metadata["events"]
    assert {e["kind"] for e in events} <= set(EVENT_KINDS)
    assert events[-1]["kind"] == "end" and events[-1]["message"].split(":")[0] == end
    # t and log_time: the controller's counter x period, not time since the start of the log
    assert log.metadata["counter"][0] == COUNTER0
    assert log.t[0] == pytest.approx(504.2, abs=1e-9)
    log_time, t = first_log_times(tmp_path / "a.mcap")
    assert log_time == round(t * 1e9) == 504_200_000_000


def test_a_simulated_log_ends_finished_and_starts_at_0(tmp_path):
    write_recording_mcap(walk(50, 0), tmp_path / "sim.mcap")
    log = load_mcap(tmp_path / "sim.mcap")
    assert log.metadata["summary"]["end"] == "finished" and "finished" in documented_ends()
    assert log.t[0] == 0.0 and first_log_times(tmp_path / "sim.mcap")[0] == 0


def test_the_doc_says_where_t_starts():
    text = re.sub(r"\s+", " ", (DOCS / "recording-format.md").read_text())
    assert "starting at 0" not in text and "from the start of the recording" not in text
    assert "a capture keeps the controller's running counter" in text

"""The MCAP and CSV recording formats: round trips, cut-off logs and bad files."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mcap.reader import make_reader

from core.errors import RapidIdentWarning, RecordingError
from drivers.base import Sample
from core.writer import McapRecorder, write_recording_csv, write_recording_mcap
from core.reader import load_recording
from core.recording import AxisTrace, Recording


@pytest.fixture
def two_axis() -> Recording:
    n = 2000
    t = np.arange(n) * 1e-3
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.normal(0, 0.01, n))
    y = np.cumsum(rng.normal(0, 0.01, n))
    return Recording(
        t,
        {"X": AxisTrace(x, x - 1e-3), "Y": AxisTrace(y, y + 2e-4)},
        1e-3,
        segment=(t >= 1.0).astype(int),
        metadata={"machine": "fadal-ppi", "programs": [{"name": "a.ngc", "sha256": "00"}]},
    )


def test_mcap_round_trip_is_exact(tmp_path, two_axis):
    path = write_recording_mcap(two_axis, tmp_path / "run.mcap")
    rec = load_recording(path)
    assert rec.axis_names == ["X", "Y"]
    assert rec.sample_period == pytest.approx(1e-3)
    for a in ("X", "Y"):
        np.testing.assert_array_equal(rec.axes[a].commanded, two_axis.axes[a].commanded)
        np.testing.assert_array_equal(rec.axes[a].actual, two_axis.axes[a].actual)
    np.testing.assert_array_equal(rec.segment, two_axis.segment)
    assert rec.metadata["programs"] == [{"name": "a.ngc", "sha256": "00"}]
    assert rec.metadata["summary"]["dropped"] == 0


def test_mcap_is_readable_by_the_mcap_library_with_controller_clock_timestamps(tmp_path, two_axis):
    path = write_recording_mcap(two_axis, tmp_path / "run.mcap")
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        msgs = list(reader.iter_messages(topics=["/samples"]))
        channel = msgs[0][1]
    assert len(msgs) == two_axis.n_samples
    assert channel.metadata["axes"] == "X,Y"
    assert channel.metadata["sample_period_s"] == "0.001"
    assert [m.log_time for _, _, m in msgs[:3]] == [0, 1_000_000, 2_000_000]
    first = json.loads(msgs[0][2].data)
    assert set(first) == {"counter", "t", "segment", "commanded", "actual"}


def test_cut_off_log_loads_complete_chunks_with_a_warning(tmp_path):
    path = tmp_path / "killed.mcap"
    rec = McapRecorder(path, ["X"], 1e-3, flush_interval_s=1e9)
    for k in range(3000):
        rec.write(Sample(k, k * 1e-3, (k * 1e-3,), (k * 1e-3,)))
        if k in (999, 1999):
            rec.flush()  # what the 1 s timer does during a capture
    # never closed: simulate SIGKILL by abandoning the writer
    with pytest.warns(RapidIdentWarning, match="cut off after 2000 samples"):
        loaded = load_recording(path)
    np.testing.assert_array_equal(loaded.axes["X"].commanded, np.arange(2000) * 1e-3)


def test_csv_round_trip(tmp_path, two_axis):
    path = write_recording_csv(two_axis, tmp_path / "run.csv")
    rec = load_recording(path)
    np.testing.assert_allclose(rec.axes["Y"].actual, two_axis.axes["Y"].actual, atol=1e-9)
    np.testing.assert_array_equal(rec.segment, two_axis.segment)


def test_single_axis_csv_header_is_accepted(tmp_path):
    path = tmp_path / "one.csv"
    path.write_text("t_s,commanded_mm,actual_mm\n0,0,0\n0.001,0.1,0.05\n0.002,0.2,0.15\n")
    rec = load_recording(path)
    assert rec.axis_names == ["X"]
    assert rec.sample_period == pytest.approx(1e-3)


def test_csv_axis_letters_have_no_case_as_in_g_code(tmp_path):
    path = tmp_path / "lower.csv"
    path.write_text("t_s,x_commanded_mm,x_actual_mm\n0,0,0\n0.001,0.1,0.05\n0.002,0.2,0.15\n")
    assert load_recording(path).axis_names == ["X"]  # the axis a part program's X moves
    path.write_text("t_s,x_commanded_mm,x_actual_mm,X_commanded_mm,X_actual_mm\n0,0,0,0,0\n0.001,0,0,0,0\n")
    with pytest.raises(RecordingError, match="two column pairs name axis X"):
        load_recording(path)


def test_a_file_that_is_no_recording_is_called_so_whatever_its_suffix(tmp_path):
    program = tmp_path / "part.ngc"
    program.write_text("G21 G90\nG1 X10 F600\nM2\n")
    with pytest.raises(RecordingError, match=r"part\.ngc: not a recording \(an \.mcap log, or a CSV"):
        load_recording(program)
    quoted = tmp_path / "log.txt"  # a CSV by another name still loads
    quoted.write_text('"t_s","commanded_mm","actual_mm"\n0,0,0\n0.001,0.1,0.05\n')
    assert load_recording(quoted).axis_names == ["X"]


@pytest.mark.parametrize("content", [
    "\ufefft_s,commanded_mm,actual_mm\n0,0,0\n0.001,0.1,0.05\n",  # Excel's "CSV UTF-8": a byte-order mark
    "t_s;commanded_mm;actual_mm\n0;0;0\n0,001;0,1;0,05\n",  # a European locale: semicolons, decimal commas
    "t_s;commanded_mm;actual_mm\n0;0;0\n0.001;0.1;0.05\n",
    "t_s\tcommanded_mm\tactual_mm\n0\t0\t0\n0.001\t0.1\t0.05\n",
    "T_S,COMMANDED_MM,ACTUAL_MM\n0,0,0\n0.001,0.1,0.05\n",
])
def test_a_csv_is_read_as_spreadsheets_write_it(tmp_path, content):
    for name in ("run.csv", "run.txt"):  # by its suffix, and by what it holds
        path = tmp_path / name
        path.write_bytes(content.encode())
        rec = load_recording(path)
        assert rec.axis_names == ["X"]
        np.testing.assert_array_equal(rec.t, [0.0, 0.001])
        np.testing.assert_array_equal(rec.axes["X"].commanded, [0.0, 0.1])
        np.testing.assert_array_equal(rec.axes["X"].actual, [0.0, 0.05])


@pytest.mark.parametrize(
    "content, message",
    [
        ("", "file is empty"),
        ("t_s,commanded_mm,actual_mm\n", "contains no samples"),
        ("t_s,commanded_mm,actual_mm\n0,0,0\n", "single sample"),
        ("t_s,commanded_mm,actual_mm\n0,0,0\n0.001,nan,0\n0.002,0,0\n", "NaN/inf at sample 1"),
        ("t_s,commanded_mm,actual_mm\n0,0,0\n0.001,1e300,0\n0.002,0,0\n", "1e\\+300 at sample 1 .* is no machine position"),
        ("t_s,commanded_mm,actual_mm\n0,0,0\n0.002,0,0\n0.001,0,0\n", "time goes backwards at sample 2"),
        ("t_s,commanded_mm,actual_mm\n0,0,0\n0.001,0\n", "truncated row"),
        ("time,x,y\n0,0,0\n", "first column must be t_s"),
        ("t_s,X_commanded_m,X_actual_m\n0,0,0\n", "in metres"),
        ("t_s,foo\n0,1\n", "no position columns"),
    ],
)
def test_bad_csv_gives_one_line_error(tmp_path, content, message):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    with pytest.raises(RecordingError, match=message) as info:
        load_recording(path)
    assert "\n" not in str(info.value)


def test_missing_and_non_mcap_files(tmp_path):
    with pytest.raises(RecordingError, match="no such file"):
        load_recording(tmp_path / "absent.mcap")
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"this is not mcap at all")
    with pytest.raises(RecordingError, match="not a readable MCAP file"):
        load_recording(junk)


def test_a_file_shorter_than_the_mcap_magic_is_not_a_readable_mcap_file(tmp_path):
    # the mcap reader fails on it with a bare struct.error, before it can check the magic
    stub = tmp_path / "stub.mcap"
    stub.write_bytes(b"junk\n")
    with pytest.raises(RecordingError, match="not a readable MCAP file"):
        load_recording(stub)

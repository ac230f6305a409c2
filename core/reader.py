"""Load recordings (MCAP in the rapid-ident layout, or CSV) into :class:`Recording`.

Structural problems are one-line :class:`RecordingError` s naming the file and the
problem (missing, empty, not MCAP, no samples, malformed row, NaN, time going
backwards).  A log that was cut off (a killed capture) is still loaded up to its last
complete chunk, with a warning, so that nothing already recorded is lost.
"""

from __future__ import annotations

import csv
import io
import json
import struct
import warnings
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError
from mcap.records import Channel, Message, Metadata
from mcap.stream_reader import StreamReader

from core.errors import RapidIdentWarning, RecordingError
from core.log_format import EVENTS_TOPIC, SAMPLES_TOPIC, SUMMARY_METADATA
from core.recording import AxisTrace, Recording

__all__ = ["load_recording", "load_mcap", "load_csv", "check_recording"]


def load_recording(path: str | Path) -> Recording:
    """Load ``.mcap`` or ``.csv`` by suffix (content sniffed when the suffix is neither)."""
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such file")
    if path.is_dir():
        raise RecordingError(f"{path}: is a directory, expected a .mcap or .csv recording")
    if path.stat().st_size == 0:
        raise RecordingError(f"{path}: file is empty")
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        rec = load_mcap(path)
    elif suffix == ".csv":
        rec = load_csv(path)
    else:
        with open(path, "rb") as fh:
            head = fh.read(8)
        if head.startswith(b"\x89MCAP"):
            rec = load_mcap(path)
        elif head.removeprefix(b"\xef\xbb\xbf").lstrip(b' \t"').lower().startswith(b"t_s"):
            rec = load_csv(path)
        else:  # a part program, a .mat file, …
            raise RecordingError(f"{path}: not a recording (an .mcap log, or a CSV whose first column is t_s)")
    check_recording(rec, str(path))
    rec.metadata["source"] = str(path)
    return rec


#: A position farther than this from zero (mm, or degrees) is no machine axis's: 1000 km, or
#: 2.8 million turns.  Beyond it the recording's squares and differences overflow.
MAX_POSITION = 1e9


def check_recording(rec: Recording, name: str = "recording") -> None:
    """Reject recordings no stage can use: too short, NaN/inf, time not increasing."""
    if rec.n_samples == 0:
        raise RecordingError(f"{name}: contains no samples")
    if rec.n_samples == 1:
        raise RecordingError(f"{name}: contains a single sample; a recording needs many")
    if not np.all(np.isfinite(rec.t)):
        k = int(np.flatnonzero(~np.isfinite(rec.t))[0])
        raise RecordingError(f"{name}: time is not a number at sample {k}")
    for axis, tr in rec.axes.items():
        for label, arr in (("commanded", tr.commanded), ("actual", tr.actual)):
            bad = ~np.isfinite(arr)
            if bad.any():
                k = int(np.flatnonzero(bad)[0])
                raise RecordingError(
                    f"{name}: axis {axis} {label} position is NaN/inf at sample {k} (t={rec.t[k]:.6g} s)"
                )
            far = np.abs(arr) > MAX_POSITION
            if far.any():
                k = int(np.flatnonzero(far)[0])
                raise RecordingError(
                    f"{name}: axis {axis} {label} position {arr[k]:.6g} at sample {k} (t={rec.t[k]:.6g} s) "
                    f"is no machine position (farther than {MAX_POSITION:g} from zero)"
                )
    dt = np.diff(rec.t)
    if np.any(dt <= 0):
        k = int(np.flatnonzero(dt <= 0)[0]) + 1
        what = "repeats" if dt[k - 1] == 0 else "goes backwards"
        raise RecordingError(f"{name}: time {what} at sample {k} (t={rec.t[k-1]:.6g} -> {rec.t[k]:.6g} s)")


def load_mcap(path: str | Path) -> Recording:
    """Read a rapid-ident MCAP log; tolerant of a cut-off tail (warns, keeps what was read)."""
    path = Path(path)
    samples_channel: int | None = None
    channel_meta: dict[str, str] = {}
    summary: dict[str, str] | None = None
    events: list[dict] = []
    counter: list[int] = []
    t: list[float] = []
    seg: list[int] = []
    cmd: dict[str, list[float]] = {}
    act: dict[str, list[float]] = {}
    axes: list[str] = []
    events_channel: int | None = None
    truncated = None
    try:
        with open(path, "rb") as fh:
            reader = StreamReader(fh)
            for record in reader.records:
                if isinstance(record, Channel):
                    if record.topic == SAMPLES_TOPIC:
                        samples_channel = record.id
                        channel_meta = dict(record.metadata)
                        axes = [a for a in channel_meta.get("axes", "").split(",") if a]
                        for a in axes:
                            cmd.setdefault(a, [])
                            act.setdefault(a, [])
                    elif record.topic == EVENTS_TOPIC:
                        events_channel = record.id
                elif isinstance(record, Message):
                    if record.channel_id == samples_channel:
                        m = json.loads(record.data)
                        counter.append(m["counter"])
                        t.append(m["t"])
                        seg.append(m.get("segment", 0))
                        c, x = m["commanded"], m["actual"]
                        for a in axes:
                            cmd[a].append(c[a])
                            act[a].append(x[a])
                    elif record.channel_id == events_channel:
                        events.append(json.loads(record.data))
                elif isinstance(record, Metadata) and record.name == SUMMARY_METADATA:
                    summary = dict(record.metadata)
    except (McapError, EOFError, ValueError, KeyError, TypeError, OSError, struct.error) as exc:  # struct: < 8 bytes
        if isinstance(exc, (KeyError, TypeError)) and samples_channel is not None and not t:
            raise RecordingError(f"{path}: /samples messages are malformed ({exc!r})") from exc
        if samples_channel is None:
            raise RecordingError(f"{path}: not a readable MCAP file ({type(exc).__name__}: {exc})") from exc
        truncated = exc
    if samples_channel is None:
        raise RecordingError(f"{path}: no {SAMPLES_TOPIC} channel; not a rapid-ident log")
    # A message may have been half-appended when the stream broke: keep equal lengths.
    n = min([len(t)] + [len(v) for v in cmd.values()] + [len(v) for v in act.values()])
    if truncated is not None:
        warnings.warn(
            f"{path}: log is cut off after {n} samples ({type(truncated).__name__}); loading what was recorded",
            RapidIdentWarning,
            stacklevel=2,
        )
    elif summary is None:
        warnings.warn(f"{path}: no capture summary; the capture did not close cleanly", RapidIdentWarning,
                      stacklevel=2)
    try:
        period = float(channel_meta["sample_period_s"])
    except (KeyError, ValueError):
        raise RecordingError(f"{path}: channel metadata lacks a valid sample_period_s") from None
    metadata: dict = {k: _maybe_json(v) for k, v in channel_meta.items()}
    metadata["summary"] = {k: _maybe_json(v) for k, v in (summary or {}).items()}
    metadata["events"] = events
    metadata["truncated"] = truncated is not None
    units = str(channel_meta.get("units", "")).split(",")
    metadata["units"] = {a: (units[i] if i < len(units) and units[i] else "mm") for i, a in enumerate(axes)}
    if summary:
        for key in ("dropped", "corrupt"):
            if key in summary:
                metadata[key] = _maybe_json(summary[key])
    rec = Recording(
        t=np.asarray(t[:n], dtype=float),
        axes={a: AxisTrace(np.asarray(cmd[a][:n], float), np.asarray(act[a][:n], float)) for a in axes},
        sample_period=period,
        segment=np.asarray(seg[:n], dtype=np.int32),
        metadata=metadata,
    )
    rec.metadata["counter"] = np.asarray(counter[:n], dtype=np.int64)
    return rec


def _maybe_json(value: str):
    try:
        return json.loads(value)
    except (ValueError, TypeError):
        return value


def load_csv(path: str | Path) -> Recording:
    """Read SPEC §4 CSV: ``t_s`` then ``<AXIS>_commanded_mm,<AXIS>_actual_mm`` per axis.

    A single axis may be written ``commanded_mm,actual_mm`` (named ``X``).  An optional
    ``segment`` column marks program segments.  The sample period is the median step of t.

    Read as spreadsheets write it too: a UTF-8 byte-order mark (Excel's "CSV UTF-8") is
    skipped, column names have no case, and a header without a comma but with semicolons
    or tabs sets that separator — numbers may then use a decimal comma (``0,001``), as a
    spreadsheet set to a European locale writes them.
    """
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError:
        raise RecordingError(f"{path}: not a text CSV file") from None
    first = text.split("\n", 1)[0]
    sep = next((c for c in ",;\t" if c in first), ",")
    reader = csv.reader(io.StringIO(text), delimiter=sep)
    try:
        header = [h.strip().lower() for h in next(reader)]
    except StopIteration:
        raise RecordingError(f"{path}: file is empty") from None
    if not header or header[0] != "t_s":
        raise RecordingError(f"{path}: first column must be t_s, found {header[0] if header else 'nothing'!r}")
    cols = header[1:]
    seg_col = None
    if "segment" in cols:
        seg_col = header.index("segment")
    axes: list[tuple[str, int, int]] = []
    if "commanded_mm" in header and "actual_mm" in header:
        axes.append(("X", header.index("commanded_mm"), header.index("actual_mm")))
    else:
        for i, name in enumerate(header):
            if name.endswith("_commanded_mm"):
                given = name[: -len("_commanded_mm")]
                partner = f"{given}_actual_mm"
                if partner not in header:
                    raise RecordingError(f"{path}: column {name} has no matching {partner}")
                # an axis is a G-code address letter, and G-code letters have no case: x_… is
                # the axis X a part program moves (and a model identified from it predicts)
                axis = given.upper()
                if any(a == axis for a, _, _ in axes):
                    raise RecordingError(f"{path}: two column pairs name axis {axis} (axis names have no case)")
                axes.append((axis, i, header.index(partner)))
            elif name.endswith(("_commanded_m", "_actual_m")):
                raise RecordingError(f"{path}: column {name} is in metres; give positions in mm (*_mm)")
    if not axes:
        raise RecordingError(
            f"{path}: no position columns; expected <AXIS>_commanded_mm,<AXIS>_actual_mm or commanded_mm,actual_mm"
        )
    rows = []
    for lineno, row in enumerate(reader, start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise RecordingError(f"{path}:{lineno}: {len(row)} fields, header has {len(header)} (truncated row?)")
        try:
            rows.append([float(c) for c in row] if sep == "," else [float(c.replace(",", ".")) for c in row])
        except ValueError:
            raise RecordingError(f"{path}:{lineno}: a field is not a number: {row!r}") from None
    if not rows:
        raise RecordingError(f"{path}: contains no samples")
    data = np.asarray(rows, dtype=float)
    t = data[:, 0]
    dt = np.diff(t)
    period = float(np.median(dt)) if dt.size and np.all(np.isfinite(dt)) else float("nan")
    if len(t) > 1 and not period > 0:
        # let check_recording name the exact sample
        period = 1.0
    segment = data[:, seg_col].astype(np.int32) if seg_col is not None else None
    return Recording(
        t=t,
        axes={a: AxisTrace(data[:, ic].copy(), data[:, ia].copy()) for a, ic, ia in axes},
        sample_period=period if len(t) > 1 else 0.001,
        segment=segment,
        metadata={"source": "csv", "units": {a: "mm" for a, _, _ in axes}},
    )

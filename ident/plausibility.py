"""Is this recording a measurement a drive model can be identified from?  Checked before any fit.

:func:`ident.preprocessing.prepare_recording` makes a recording *readable* (finite values,
a regular clock); this module decides whether it is *plausible* as the commanded and actual
positions of a CNC feed drive, and says what is wrong in the recording's terms instead of
letting a solver fail later in its own ("regressor column e_i is all zero", "Phi is rank
deficient") or, worse, fit nonsense with a good figure.  Every check is on the identified
axes only: an idle axis of a multi-axis capture is no error.

What each check catches (all :class:`UnusableRecordingError`, exit 2 at the CLI):

* a prediction log (its metadata says the "actual" channel is a model output);
* a sample clock slower than 50 Hz — the recordings are sampled at the servo rate
  (thesis §4.3: 1 kHz and above), so a 1 s step is a time column in ms;
* positions that look like metres (under 1 mm of travel at under 1 mm/s) unless the
  caller says which units they are in (``units="mm"`` or ``"m"``);
* a command that never moves; a recording shorter than 1 s or 200 samples (the thesis's
  eq. 3.8 bounds reach down to 0.2 Hz poles, and the friction terms need moves both ways);
* an actual position equal to the commanded one, or equal to it plus a constant (no
  tracking error, hence no drive dynamics, to identify);
* actual and commanded swapped: the actual position *leads* the command (a drive lags
  its command; a preview controller by at most a sample or two, thesis §4.3.2).
"""

from __future__ import annotations

import warnings
from typing import Sequence

import numpy as np

from core.errors import InputError, RapidIdentWarning, UnusableRecordingError
from core.recording import AxisTrace, Recording
from ident.preprocessing import segment_slices

__all__ = ["check_identifiable", "UNITS", "MIN_DURATION_S", "MIN_SAMPLES", "MAX_SAMPLE_PERIOD_S", "never_moves"]

#: What ``units`` may say: "auto" (detect metres and refuse them), "mm", or "m" (converted).
UNITS = ("auto", "mm", "m")
#: Shortest recording identified: the slowest allowed pole (0.2 Hz) has a 0.8 s time constant.
MIN_DURATION_S = 1.0
MIN_SAMPLES = 200
#: Slowest sample clock accepted (50 Hz): drives are recorded at the servo rate.
MAX_SAMPLE_PERIOD_S = 0.02
#: A commanded position that spans no more than this (mm) never moves.
STILL_MM = 1e-9
#: Actual leading the command by more than this many samples, with the lag explaining at
#: least half the tracking error's variance, is a swap (measured on the presets and the
#: drive zoo: real drives lead by at most 0.2 samples, with under 5 % explained; swapped
#: columns lead by 33 samples with 100 % explained).
SWAP_LEAD_SAMPLES = 1.0
SWAP_EXPLAINED = 0.5

_METRES = ("m", "meter", "meters", "metre", "metres")


def _name(rec: Recording) -> str:
    return str(rec.metadata.get("source") or "the recording")


def _declared_units(rec: Recording, axis: str) -> str | None:
    units = rec.metadata.get("units") if isinstance(rec.metadata, dict) else None
    u = units.get(axis) if isinstance(units, dict) else units
    return str(u).strip().lower() if u else None


def _peak_speed(x: np.ndarray, Ts: float, segment: np.ndarray) -> float:
    v = [np.max(np.abs(np.diff(x[s]))) / Ts for s in segment_slices(segment, x.size) if s.stop - s.start > 1]
    return float(max(v, default=0.0))


def _lead_samples(tr: AxisTrace, Ts: float, segment: np.ndarray) -> tuple[float, float]:
    """Least-squares lag L of the tracking error on the commanded velocity, e ≈ L·ẋ_r, in samples
    (negative: the actual position leads), and the share of e's variance it explains."""
    num = den = ee = 0.0
    for s in segment_slices(segment, tr.commanded.size):
        x_r, x = tr.commanded[s], tr.actual[s]
        if x.size < 3:
            continue
        v = np.gradient(x_r, Ts)
        e = (x_r - x) - np.mean(x_r - x)
        num, den, ee = num + float(e @ v), den + float(v @ v), ee + float(e @ e)
    if den <= 0 or ee <= 0:
        return 0.0, 0.0
    lag = num / den
    return lag / Ts, lag * lag * den / ee


def _in_mm(rec: Recording, names: Sequence[str], units: str) -> Recording:
    """The recording with the identified axes in mm: converted where units (given or recorded) are metres."""
    axes = dict(rec.axes)
    metres = []
    for a in names:
        declared = units if units != "auto" else _declared_units(rec, a)
        if declared in _METRES:
            axes[a] = AxisTrace(rec.axes[a].commanded * 1e3, rec.axes[a].actual * 1e3)
            metres.append(a)
    if not metres:
        return rec
    if units == "auto":
        warnings.warn(f"{_name(rec)}: axis {', '.join(metres)} recorded in metres (its units metadata); "
                      "converted to mm", RapidIdentWarning, stacklevel=3)
    meta = dict(rec.metadata)
    meta["units"] = {a: "mm" for a in rec.axes}
    return Recording(t=rec.t, axes=axes, sample_period=rec.sample_period, segment=rec.segment, metadata=meta)


def never_moves(tr: AxisTrace) -> bool:
    """Whether the axis's commanded position stays put over the whole recording."""
    return float(np.ptp(tr.commanded)) <= STILL_MM


def check_identifiable(rec: Recording, names: Sequence[str], *, units: str = "auto") -> Recording:
    """Refuse a recording no drive model can be identified from; return it with positions in mm.

    Parameters
    ----------
    rec : a recording already through :func:`ident.preprocessing.prepare_recording`.
    names : the axes to identify.
    units : "auto" (metres recorded in the metadata are converted; values that only *look*
        like metres are refused), "mm" (trust the values) or "m" (convert).

    Raises
    ------
    UnusableRecordingError
        With a one-line message saying what is wrong with the recording (see the module).
    """
    if units not in UNITS:
        raise InputError.about("units", f"units {units!r}: choose {', '.join(UNITS)}")
    name = _name(rec)
    actual_is = rec.metadata.get("actual_is") if isinstance(rec.metadata, dict) else None
    if actual_is or rec.metadata.get("transport") == "prediction":
        raise UnusableRecordingError(
            f"{name} is a prediction written by agent simulate --machine / agent predict: its actual positions "
            f"are {actual_is or 'a model output'}; identify a recording of the machine itself")
    Ts = rec.sample_period
    if Ts > MAX_SAMPLE_PERIOD_S:
        hint = " (t_s looks like milliseconds: give time in seconds)" if 0.05 <= Ts <= 20 else ""
        raise UnusableRecordingError(
            f"{name}: one sample every {Ts:g} s ({1 / Ts:.3g} Hz) is far slower than a servo loop; a drive is "
            f"recorded at 1 kHz or faster{hint}")
    rec = _in_mm(rec, names, units)
    for a in names:
        tr = rec.axes[a]
        span = float(np.ptp(tr.commanded))
        if never_moves(tr):
            raise UnusableRecordingError(
                f"no motion on axis {a} in {name}: the commanded position stays at {tr.commanded[0]:.6g} mm; "
                "record the axis while it runs the identification programs (agent generate)")
        v_peak = _peak_speed(tr.commanded, Ts, rec.segment)
        if units == "auto" and span < 1.0 and v_peak < 1.0:
            raise UnusableRecordingError.about(
                "units", f"axis {a} of {name} moves only {span:.3g} mm at up to {v_peak:.3g} mm/s: the values look "
                "like metres; say which (m to convert them, mm to keep them)")
    if rec.n_samples < MIN_SAMPLES or rec.duration < MIN_DURATION_S:
        raise UnusableRecordingError(
            f"{name} is only {rec.duration:.3g} s ({rec.n_samples} samples) long: identification needs at least "
            f"{MIN_DURATION_S:g} s and {MIN_SAMPLES} samples of moves in both directions (agent generate's "
            "programs take about 25 s)")
    for a in names:
        tr = rec.axes[a]
        e = tr.commanded - tr.actual
        # a CSV's 10 significant digits round 100 mm to 1e-8 mm: a tolerance of 1e-7 relative
        tol = 1e-9 + 1e-7 * float(np.max(np.abs(tr.commanded)))
        if np.ptp(e) <= tol:
            offset = float(np.mean(e))
            same = ("equals the commanded position" if abs(offset) <= tol else
                    f"is the commanded position {'minus' if offset > 0 else 'plus'} a constant {abs(offset):.6g} mm")
            raise UnusableRecordingError(
                f"axis {a} of {name}: the actual position {same} at every sample, so the recording holds no "
                "tracking error to identify a drive from (the commanded channel recorded twice?)")
        lead, explained = _lead_samples(tr, Ts, rec.segment)
        if lead < -SWAP_LEAD_SAMPLES and explained > SWAP_EXPLAINED:
            raise UnusableRecordingError(
                f"axis {a} of {name}: the actual position leads the commanded position by {-lead * Ts * 1e3:.3g} ms; "
                "a drive follows its command, so the commanded and actual columns look swapped")
    return rec

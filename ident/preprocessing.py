"""Preprocessing of recorded positions before identification (thesis §3.2–3.3, §4.3.2–4.3.3).

Arrays in, arrays out; the sample period ``Ts`` (s) is always passed explicitly and
positions are mm.  The stages, in the order :func:`ident.regression.build_regression`
uses them:

1. **Sampling** (:func:`regularise_sampling`): time must increase strictly (otherwise
   :class:`RecordingError`); a step longer than ``gap_factor·Ts`` (default 1.5) is a gap
   that splits the recording into segments — never bridged; irregular steps (jitter above
   ``jitter_tol·Ts``) are resampled onto the nominal grid by linear interpolation with a
   :class:`RapidIdentWarning`.  NaN/inf values are a :class:`RecordingError` naming the
   axis and sample (:func:`check_finite`).
2. **Plausibility** (:func:`check_motion`, :func:`check_reversals`): no motion, metres
   given as mm, never reversing.
3. **Command shift** (:func:`shift_command`): the integer preview/delay shift of §4.3.2.
4. **Optional zero-phase low-pass** (:func:`lowpass`), **derivatives** by central
   differences as in eq. 3.9 (:func:`central_derivatives`), **integrated tracking error**
   (:func:`integrated_error`), and the **direction** of motion for PV/NV with a noise
   threshold and hysteresis (:func:`velocity_threshold`, :func:`direction`).

Segments (``segment``: int array (N,), one id per contiguous run of samples, e.g. the
low- and high-speed sets of §4.3.3, or the pieces between capture gaps) are processed
independently: no derivative, filter or integral ever spans a seam.

Choices documented here because the rest of the package depends on them:

* **Integral restarts per segment.**  ``e_i`` starts at 0 at each segment's first sample.
  The free-run simulator (:mod:`ident.simulation`) starts its integral state at 0 at each
  segment start too, so the regression and the simulation describe the same model.
  Carrying the integral across a seam would integrate over the unrecorded time in between
  (a gap, or the pause between the low- and high-speed programs), which is unknown.
* **Trapezoidal integral by default.**  Eq. 3.9 writes the rectangle sum
  ``e_i,k = Ts·Σ_{m≤k} e_m``; that differs from the model's continuous integral by
  ``Ts·e_k/2``, which biases α_i by a relative ``α_i·Ts/2`` (1 % for the thesis's DMG
  X axis).  ``rule="rectangle"`` reproduces the thesis exactly.
* **No low-pass by default.**  Central differences are already a low-pass (gain
  sin(ωTs)/(ωTs), zero at Nyquist); a filter applied to ``x`` and ``x_r`` alike leaves the
  linear part of eq. 3.3 unchanged but smears the friction switch at reversals, and the
  fit that matters (SPEC §5) is the free run, which uses no derivatives of ``x`` at all.
  Use ``lowpass_hz`` for noisy analogue feedback.
* **Standstill rows are left out of the regression** (``standstill="drop"`` in
  :func:`ident.regression.build_regression`): while the axis sticks, the friction is
  whatever holds it, anywhere in [d1, d0], and eq. 3.9's PV/NV terms (d0 or d1 exactly)
  are simply wrong there.  Dropping those rows gave the better equation-error start on
  every thesis preset (e.g. PID 99.1 % vs 98.8 %, feedforward preset 79 % vs 76 % before
  refinement) and changed nothing on EMPS.  The direction signal itself
  (:func:`direction`) is a Schmitt trigger: it changes only when the velocity passes the
  threshold on the other side, so noise inside the band cannot flip PV/NV;
  ``standstill="hold"`` keeps those rows with the last direction and ``"zero"`` with
  PV = NV = 0.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, Literal, Mapping

import numpy as np

from core.errors import IdentificationError, InputError, RecordingError, RapidIdentWarning, UnusableRecordingError

if TYPE_CHECKING:
    from core.recording import Recording

__all__ = [
    "segment_slices",
    "check_finite",
    "regularise_sampling",
    "check_motion",
    "check_reversals",
    "shift_command",
    "lowpass",
    "central_derivatives",
    "integrated_error",
    "position_resolution",
    "velocity_threshold",
    "direction",
    "interior_mask",
    "prepare_recording",
    "remove_reference",
    "POSITION_GRID_MM",
]

#: Samples dropped at each segment end: ẍ_k = (ẋ_{k+1} − ẋ_{k−1})/(2Ts) needs x_{k±2} (eq. 3.9).
EDGE = 2


# --------------------------------------------------------------------------- segments


def _segment_array(segment: np.ndarray | None, n: int) -> np.ndarray:
    if segment is None:
        return np.zeros(n, dtype=np.int32)
    segment = np.asarray(segment)
    if segment.shape != (n,):
        raise ValueError(f"segment has shape {segment.shape}, expected ({n},)")
    return segment


def segment_slices(segment: np.ndarray | None, n: int | None = None) -> list[slice]:
    """Contiguous runs of equal segment id, as slices in time order.

    Parameters
    ----------
    segment : ndarray of int (N,) or None
        Segment id per sample; ``None`` means one segment of ``n`` samples.
    n : int, optional
        Number of samples (needed when ``segment`` is None).
    """
    if segment is None:
        if n is None:
            raise ValueError("segment_slices needs n when segment is None")
        return [slice(0, n)] if n > 0 else []
    segment = np.asarray(segment)
    if segment.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(segment) != 0) + 1
    bounds = np.concatenate([[0], cuts, [segment.size]])
    return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]


def interior_mask(segment: np.ndarray | None, n: int, edge: int = EDGE, *,
                  head: int = 0, tail: int = 0) -> np.ndarray:
    """Boolean mask (N,) of samples at least ``edge`` samples from each segment end.

    ``head``/``tail`` drop extra samples at the start/end of every segment (the samples a
    command shift fills by holding the edge value).
    """
    mask = np.zeros(n, dtype=bool)
    for s in segment_slices(segment, n):
        a, b = s.start + edge + head, s.stop - edge - tail
        if b > a:
            mask[a:b] = True
    return mask


# --------------------------------------------------------------------------- sampling


def check_finite(values: np.ndarray, *, axis: str, what: str, t: np.ndarray | None = None) -> None:
    """Raise :class:`RecordingError` at the first NaN/inf in ``values``.

    Parameters
    ----------
    values : ndarray (N,)
        Positions, mm (or times, s).
    axis, what : str
        Axis name and signal name for the message (e.g. ``"X"``, ``"commanded position"``).
    t : ndarray (N,), optional
        Sample times, s, quoted in the message.
    """
    bad = ~np.isfinite(np.asarray(values, dtype=float))
    if bad.any():
        k = int(np.argmax(bad))
        when = f" (t = {t[k]:.6g} s)" if t is not None and np.isfinite(t[k]) else ""
        raise RecordingError(
            f"axis {axis}: {what} is {float(values[k])} at sample {k}{when}; "
            f"{int(bad.sum())} non-finite sample(s) in all"
        )


def regularise_sampling(
    t: np.ndarray,
    signals: Mapping[str, np.ndarray],
    Ts: float,
    segment: np.ndarray | None = None,
    *,
    jitter_tol: float = 0.01,
    gap_factor: float = 1.5,
) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:
    """Check the sample clock; split at gaps; resample jittered pieces onto the nominal grid.

    Parameters
    ----------
    t : ndarray (N,)
        Sample times, s (controller clock).
    signals : mapping name → ndarray (N,)
        Signals sampled at ``t`` (positions in mm), resampled alongside.
    Ts : float
        Nominal sample period, s.
    segment : ndarray of int (N,), optional
        Segment ids already known (e.g. one per program); their boundaries are kept.
    jitter_tol : float
        Steps within ``Ts·(1 ± jitter_tol)`` count as regular (clock rounding); larger
        deviations (still ≤ ``gap_factor·Ts``) trigger resampling with a warning.
    gap_factor : float
        A step longer than ``gap_factor·Ts`` is a gap: missing samples.  The recording is
        split there into separate segments; nothing is interpolated across it.

    Returns
    -------
    t, signals, segment
        Regular time base, resampled signals, and segment ids renumbered 0, 1, 2, … in time
        order (one id per contiguous piece).

    Raises
    ------
    RecordingError
        Fewer than 2 samples, non-finite or non-increasing time, bad ``Ts`` or a ``Ts``
        that disagrees with the median clock step by more than 25 %.
    """
    t = np.asarray(t, dtype=float)
    n = t.shape[0] if t.ndim == 1 else -1
    if t.ndim != 1:
        raise RecordingError(f"time must be a 1-D array, got shape {t.shape}")
    if n == 0:
        raise RecordingError("recording is empty (0 samples)")
    if n == 1:
        raise RecordingError("recording has only 1 sample; identification needs a trajectory")
    if not (np.isfinite(Ts) and Ts > 0):
        raise RecordingError(f"sample period must be a positive number of seconds, got {Ts!r}")
    bad_t = ~np.isfinite(t)
    if bad_t.any():
        k = int(np.argmax(bad_t))
        raise RecordingError(f"time is {float(t[k])} at sample {k}; the controller clock must be finite")
    sig = {k: np.asarray(v, dtype=float) for k, v in signals.items()}
    for k, v in sig.items():
        if v.shape != (n,):
            raise RecordingError(f"signal {k} has shape {v.shape}, expected ({n},) like time")
    seg_in = _segment_array(segment, n)

    dt = np.diff(t)
    back = np.flatnonzero(dt <= 0)
    if back.size:
        k = int(back[0]) + 1
        verb = "goes backwards" if dt[k - 1] < 0 else "does not advance"
        raise RecordingError(
            f"time {verb} at sample {k}: t = {t[k]:.9g} s after {t[k - 1]:.9g} s "
            f"({back.size} such step(s)); the controller clock must increase"
        )
    typical = float(np.median(dt))
    if abs(typical - Ts) > 0.25 * Ts:
        raise RecordingError(
            f"sample period Ts = {Ts * 1e3:.6g} ms disagrees with the clock: the median step is "
            f"{typical * 1e3:.6g} ms"
        )
    cut = (dt > gap_factor * Ts) | (np.diff(seg_in) != 0)
    bounds = np.concatenate([[0], np.flatnonzero(cut) + 1, [n]])

    t_out, seg_out = [], []
    sig_out: dict[str, list[np.ndarray]] = {k: [] for k in sig}
    worst, worst_k = 0.0, -1
    for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
        tp = t[a:b]
        dev = np.abs(np.diff(tp) - Ts)
        if dev.size and dev.max() > jitter_tol * Ts:
            j = int(np.argmax(dev))
            if dev[j] > worst:
                worst, worst_k = float(dev[j]), int(a + j + 1)
            m = int(np.floor((tp[-1] - tp[0]) / Ts + 1e-9)) + 1
            tg = tp[0] + Ts * np.arange(m)
            for k, v in sig.items():
                sig_out[k].append(np.interp(tg, tp, v[a:b]))
            tp = tg
        else:
            for k, v in sig.items():
                sig_out[k].append(v[a:b])
        t_out.append(tp)
        seg_out.append(np.full(tp.size, i, dtype=np.int32))
    if worst_k >= 0:
        warnings.warn(
            f"irregular sample timing: step deviates from Ts = {Ts * 1e3:.6g} ms by up to "
            f"{worst * 1e3:.3g} ms (at sample {worst_k}); resampled onto the nominal grid",
            RapidIdentWarning,
            stacklevel=2,
        )
    n_gaps = int(np.count_nonzero(dt > gap_factor * Ts))
    if n_gaps:
        k = int(np.argmax(dt > gap_factor * Ts)) + 1
        warnings.warn(
            f"{n_gaps} gap(s) in the sample clock (first at sample {k}: {dt[k - 1] * 1e3:.6g} ms "
            f"step for Ts = {Ts * 1e3:.6g} ms); the recording is split there, never bridged",
            RapidIdentWarning,
            stacklevel=2,
        )
    return (
        np.concatenate(t_out),
        {k: np.concatenate(v) for k, v in sig_out.items()},
        np.concatenate(seg_out),
    )


# --------------------------------------------------------------------------- plausibility


def check_motion(
    x_r: np.ndarray,
    x: np.ndarray,
    Ts: float,
    *,
    axis: str = "X",
    units: str | None = None,
    segment: np.ndarray | None = None,
    warn_units: bool = True,
) -> None:
    """Physical plausibility of one axis: finite, moving, plausibly in mm.

    Parameters
    ----------
    x_r, x : ndarray (N,)
        Commanded and actual position, mm.
    Ts : float
        Sample period, s.
    axis : str
        Axis name for messages.
    units : str, optional
        Units recorded in the metadata; ``"m"`` triggers the metres warning.
    segment : ndarray of int (N,), optional
        Segment ids (velocities are not taken across seams).
    warn_units : bool
        Run the metres-as-mm check (False when the load stage already did).

    Raises
    ------
    RecordingError
        Fewer than 2 samples, NaN/inf.
    UnusableRecordingError
        No motion on the axis (an :class:`IdentificationError` too).

    Warns
    -----
    RapidIdentWarning
        Values that look like metres given as mm (likely factor 1000).
    """
    x_r = np.asarray(x_r, dtype=float)
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    if n == 0:
        raise RecordingError(f"axis {axis}: recording is empty (0 samples)")
    if n == 1:
        raise RecordingError(f"axis {axis}: recording has only 1 sample; identification needs a trajectory")
    check_finite(x_r, axis=axis, what="commanded position")
    check_finite(x, axis=axis, what="actual position")
    span = max(np.ptp(x_r), np.ptp(x))
    if span <= 1e-9:
        raise UnusableRecordingError(
            f"no motion on axis {axis}: commanded and actual position stay at {x[0]:.6g} mm"
        )
    if not warn_units:
        return
    if units is not None and units.strip().lower() in ("m", "meter", "meters", "metre", "metres"):
        warnings.warn(
            f"axis {axis}: positions are recorded in metres (units = {units!r}); "
            "identification expects mm — multiply by 1000",
            RapidIdentWarning,
            stacklevel=2,
        )
        return
    v_peak = 0.0
    for s in segment_slices(segment, n):
        if s.stop - s.start > 1:
            v_peak = max(v_peak, float(np.max(np.abs(np.diff(x_r[s])))) / Ts)
    # A CNC identification run moves at ≥ some mm/s; a sub-mm range crawled at < 1 mm/s is
    # what a metre-scaled recording of a normal run looks like (EMPS in m: 0.25 "mm" at
    # 0.12 "mm/s").  Warn only: slow tiny moves in mm are possible.
    if span < 1.0 and v_peak < 1.0:
        warnings.warn(
            f"axis {axis}: whole motion range is {span:.3g} mm at ≤ {v_peak:.3g} mm/s; "
            "the values look like metres given as mm (likely factor 1000)",
            RapidIdentWarning,
            stacklevel=2,
        )


def check_reversals(direction_signal: np.ndarray, *, axis: str = "X") -> None:
    """Raise :class:`UnusableRecordingError` unless the axis moves in both directions.

    The friction terms d0 (PV, ẋ > 0) and d1 (NV, ẋ < 0) of eq. 3.3 are only identifiable
    when both directions occur.

    Parameters
    ----------
    direction_signal : ndarray of int (N,)
        +1 / −1 / 0 per sample, from :func:`direction`.
    axis : str
        Axis name for messages.
    """
    d = np.asarray(direction_signal)
    n_pos, n_neg = int(np.count_nonzero(d > 0)), int(np.count_nonzero(d < 0))
    if n_pos == 0 or n_neg == 0:
        only = "in the positive direction only" if n_pos else ("in the negative direction only" if n_neg else
                                                                "too little to tell a direction")
        raise UnusableRecordingError(
            f"axis {axis} never reverses direction: it moves {only}; the friction of each direction "
            "(d0/d1) needs moves both ways, as agent generate's programs make"
        )


# --------------------------------------------------------------------------- signals


def shift_command(x_r: np.ndarray, shift: int, segment: np.ndarray | None = None) -> np.ndarray:
    """The commanded position shifted by ``shift`` samples within each segment (§4.3.2).

    ``shift > 0`` advances the command: sample k takes ``x_r[k + shift]`` (a preview, as the
    thesis's ZPETC drive shifted by 2 samples); ``shift < 0`` delays it (dead time in
    actuation or capture).  Samples that would come from outside the segment hold the
    segment's first/last value (the axis is at rest before and after a program); the
    regression drops them.

    Parameters
    ----------
    x_r : ndarray (N,)
        Commanded position, mm.
    shift : int
        Samples; positive = command earlier.
    segment : ndarray of int (N,), optional
        Segment ids; the shift never moves samples across a seam.
    """
    x_r = np.asarray(x_r, dtype=float)
    shift = int(shift)
    if shift == 0:
        return x_r.copy()
    out = np.empty_like(x_r)
    for s in segment_slices(segment, x_r.size):
        idx = np.clip(np.arange(s.start, s.stop) + shift, s.start, s.stop - 1)
        out[s] = x_r[idx]
    return out


def lowpass(
    x: np.ndarray,
    Ts: float,
    cutoff_hz: float,
    segment: np.ndarray | None = None,
    *,
    order: int = 2,
) -> np.ndarray:
    """Zero-phase Butterworth low-pass (``scipy.signal.filtfilt``) within each segment.

    Parameters
    ----------
    x : ndarray (N,)
        Signal (position, mm).
    Ts : float
        Sample period, s.
    cutoff_hz : float
        −3 dB frequency of each pass (−6 dB for the forward-backward pair), Hz; below
        Nyquist ``1/(2Ts)``.
    segment : ndarray of int (N,), optional
        Segment ids; each segment is filtered alone.  Segments too short for filtfilt's
        padding are left unfiltered.
    order : int
        Butterworth order of each pass.
    """
    nyq = 0.5 / Ts
    if not (0 < cutoff_hz < nyq):
        raise InputError(f"low-pass cutoff must be between 0 and Nyquist {nyq:.6g} Hz, got {cutoff_hz!r} Hz")
    from scipy import signal  # imported here: 0.5 s of start-up for an option that is off by default

    b, a = signal.butter(order, cutoff_hz / nyq)
    x = np.asarray(x, dtype=float)
    out = x.copy()
    padlen = 3 * max(len(a), len(b))
    for s in segment_slices(segment, x.size):
        if s.stop - s.start > padlen:
            out[s] = signal.filtfilt(b, a, x[s])
    return out


def central_derivatives(
    x: np.ndarray, Ts: float, segment: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration by the central differences of eq. 3.9, per segment.

    ``ẋ_k = (x_{k+1} − x_{k−1})/(2Ts)`` and ``ẍ_k = (ẋ_{k+1} − ẋ_{k−1})/(2Ts)``.  Where a
    difference would reach outside the segment the value is NaN (1 sample at each end for
    ẋ, 2 for ẍ): nothing is differentiated across a seam.

    Parameters
    ----------
    x : ndarray (N,)
        Position, mm.
    Ts : float
        Sample period, s.
    segment : ndarray of int (N,), optional
        Segment ids.

    Returns
    -------
    xd : ndarray (N,), mm/s
    xdd : ndarray (N,), mm/s²
    """
    x = np.asarray(x, dtype=float)
    xd = np.full_like(x, np.nan)
    xdd = np.full_like(x, np.nan)
    for s in segment_slices(segment, x.size):
        a, b = s.start, s.stop
        if b - a >= 3:
            xd[a + 1 : b - 1] = (x[a + 2 : b] - x[a : b - 2]) / (2.0 * Ts)
        if b - a >= 5:
            xdd[a + 2 : b - 2] = (xd[a + 3 : b - 1] - xd[a + 1 : b - 3]) / (2.0 * Ts)
    return xd, xdd


def integrated_error(
    x_r: np.ndarray,
    x: np.ndarray,
    Ts: float,
    segment: np.ndarray | None = None,
    *,
    rule: Literal["trapezoid", "rectangle"] = "trapezoid",
) -> np.ndarray:
    """Integrated tracking error e_i = ∫(x_r − x) dt from each segment's start, mm·s.

    ``rule="rectangle"`` is eq. 3.9's ``e_i,k = Ts·Σ_{m≤k}(x_r,m − x_m)``; the default
    trapezoid rule matches the continuous integral state of eq. 3.3 that the free-run
    simulator integrates (see the module docstring).  The integral restarts at 0 at every
    segment start.

    Parameters
    ----------
    x_r, x : ndarray (N,)
        Commanded (already shifted, if a shift is used) and actual position, mm.
    Ts : float
        Sample period, s.
    segment : ndarray of int (N,), optional
        Segment ids.
    rule : "trapezoid" | "rectangle"
    """
    e = np.asarray(x_r, dtype=float) - np.asarray(x, dtype=float)
    out = np.empty_like(e)
    for s in segment_slices(segment, e.size):
        c = np.cumsum(e[s])
        if rule == "trapezoid":
            c = c - 0.5 * (e[s][0] + e[s])
        elif rule != "rectangle":
            raise InputError(f"integral rule must be 'trapezoid' or 'rectangle', got {rule!r}")
        out[s] = Ts * c
    return out


def position_resolution(x: np.ndarray, segment: np.ndarray | None = None) -> float:
    """Encoder resolution q of a quantised position signal, mm; 0 if it is not quantised.

    q is the smallest step above 1e-9 mm (floating-point noise of unit conversions); the
    signal counts as quantised when at least 99 % of its nonzero steps are integer
    multiples of q (to 1 % of q).  Continuous (noisy or simulated) signals give 0.
    """
    x = np.asarray(x, dtype=float)
    steps = []
    for s in segment_slices(segment, x.size):
        d = np.abs(np.diff(x[s]))
        steps.append(d[d > 1e-9])
    d = np.concatenate(steps) if steps else np.empty(0)
    if d.size == 0:
        return 0.0
    q = float(d.min())
    ratio = d / q
    on_grid = np.abs(ratio - np.round(ratio)) < 0.01
    return q if on_grid.mean() >= 0.99 else 0.0


def velocity_threshold(x: np.ndarray, Ts: float, segment: np.ndarray | None = None) -> float:
    """A velocity threshold (mm/s) that measurement noise on ``x`` cannot cross.

    The position noise σ_x is estimated robustly from fourth differences
    (``x_{k+2} − 4x_{k+1} + 6x_k − 4x_{k−1} + x_{k−2}`` has variance 70σ_x² for white
    noise, while smooth motion contributes only x⁗·Ts⁴ — trapezoidal moves not even that,
    except at their corners — so the median absolute deviation reflects the noise), with
    the quantisation floor σ_q = q/√12 of an encoder of resolution q.  The
    central-difference velocity has noise σ_v = σ_x/(√2·Ts).  The threshold is the larger
    of 4·σ_v and one count per sample, q/Ts (a single count change between x_{k−1} and
    x_{k+1} gives q/(2Ts), so it can never flip the direction).

    Parameters
    ----------
    x : ndarray (N,)
        Actual position, mm.
    Ts : float
        Sample period, s.
    segment : ndarray of int (N,), optional
        Segment ids.
    """
    x = np.asarray(x, dtype=float)
    d4 = []
    for s in segment_slices(segment, x.size):
        if s.stop - s.start >= 5:
            xs = x[s]
            d4.append(xs[4:] - 4.0 * xs[3:-1] + 6.0 * xs[2:-2] - 4.0 * xs[1:-3] + xs[:-4])
    sigma_x = 0.0
    if d4:
        d4c = np.concatenate(d4)
        mad = float(np.median(np.abs(d4c - np.median(d4c))))
        sigma_x = 1.4826 * mad / np.sqrt(70.0)
    q = position_resolution(x, segment)
    sigma_x = max(sigma_x, q / np.sqrt(12.0))
    sigma_v = sigma_x / (np.sqrt(2.0) * Ts)
    return float(max(4.0 * sigma_v, q / Ts, 1e-9))


def direction(
    xd: np.ndarray,
    threshold: float,
    *,
    standstill: Literal["hold", "zero"] = "hold",
    segment: np.ndarray | None = None,
) -> np.ndarray:
    """Direction of motion +1/−1/0 per sample, the switch of PV/NV in eq. 3.2, with hysteresis.

    The direction becomes +1 when ẋ > threshold and −1 when ẋ < −threshold.  Inside the
    band it keeps the previous direction (``standstill="hold"``, a Schmitt trigger: noise
    inside ±threshold cannot flip it) or is 0 (``standstill="zero"``, PV = NV = 0).  Each
    segment starts at 0 until the first excursion; NaN velocities (segment edges) give 0.

    Parameters
    ----------
    xd : ndarray (N,)
        Velocity, mm/s.
    threshold : float
        mm/s, ≥ 0.
    standstill : "hold" | "zero"
    segment : ndarray of int (N,), optional
        Segment ids (the held direction restarts at each seam).
    """
    xd = np.asarray(xd, dtype=float)
    raw = np.zeros(xd.size, dtype=np.int8)
    with np.errstate(invalid="ignore"):
        raw[xd > threshold] = 1
        raw[xd < -threshold] = -1
    if standstill == "zero":
        return raw
    if standstill != "hold":
        raise InputError(f"standstill must be 'hold' or 'zero', got {standstill!r}")
    out = np.zeros_like(raw)
    for s in segment_slices(segment, xd.size):
        r = raw[s]
        idx = np.where(r != 0, np.arange(r.size), -1)
        last = np.maximum.accumulate(idx)  # index of the last excursion so far
        held = np.where(last >= 0, r[np.maximum(last, 0)], 0)
        out[s] = held
    return out


# --------------------------------------------------------------------------- recording level


def prepare_recording(rec: "Recording", *, jitter_tol: float = 0.01, gap_factor: float = 1.5,
                      check_units: bool = True) -> "Recording":
    """Check and regularise a :class:`core.recording.Recording` on load.

    Time is checked and regularised once for all axes (:func:`regularise_sampling`), each
    axis is checked for NaN/inf and units (:func:`check_motion`, warnings).  Motion and
    reversals are checked per identified axis by the regression (an idle axis of a
    multi-axis capture is not an error here).  ``check_units=False`` leaves the metres
    warnings to the caller (:func:`ident.plausibility.check_identifiable` refuses or
    converts metres on the identified axes).

    Returns a new Recording on the regular grid with renumbered segments.
    """
    from core.recording import AxisTrace, Recording

    n = rec.n_samples
    if n == 0:
        raise RecordingError("recording is empty (0 samples)")
    if n == 1:
        raise RecordingError("recording has only 1 sample; identification needs a trajectory")
    for name, tr in rec.axes.items():
        check_finite(tr.commanded, axis=name, what="commanded position", t=rec.t)
        check_finite(tr.actual, axis=name, what="actual position", t=rec.t)
    sig = {}
    for name, tr in rec.axes.items():
        sig[name + "\0c"] = tr.commanded
        sig[name + "\0a"] = tr.actual
    t, out, seg = regularise_sampling(
        rec.t, sig, rec.sample_period, rec.segment, jitter_tol=jitter_tol, gap_factor=gap_factor
    )
    axes = {name: AxisTrace(out[name + "\0c"], out[name + "\0a"]) for name in rec.axes}
    units = rec.metadata.get("units") if isinstance(rec.metadata, dict) else None
    for name, tr in axes.items():
        u = units.get(name) if isinstance(units, dict) else units  # per-axis or global units
        try:
            check_motion(tr.commanded, tr.actual, rec.sample_period, axis=name, units=u, segment=seg,
                         warn_units=check_units)
        except IdentificationError:
            # An idle axis in a multi-axis capture is fine until someone identifies it;
            # build_regression raises "no motion on axis …" then.
            pass
    return Recording(t=t, axes=axes, sample_period=rec.sample_period, segment=seg,
                     metadata=dict(rec.metadata))


#: The grid (mm) positions are kept on once a reference is removed: 1 nm, below any
#: drive's encoder and above the floating-point rounding of positions up to metres.
POSITION_GRID_MM = 1e-9


def remove_reference(rec: "Recording", reference: dict[str, float] | None = None) -> "Recording":
    """Positions relative to a reference position per axis, on the 1 nm grid.

    The identification and the diagnosis are the same whatever the origin of the
    positions: only differences of positions are physics (a cyclic error's phase, the one
    exception, is told back in absolute position).  Left in, a large absolute position
    rounds every sum differently from the same motion elsewhere, and the searches of the
    diagnosis read rounding (docs/diagnosis.md, "Determinism").  The reference is the
    first actual position of the identification recording — a point of the encoder grid,
    so the grid is kept — and the difference is rounded to ``POSITION_GRID_MM``: moving
    every position of a recording by a constant then gives the same arrays bit for bit
    (recordings written to 1 nm or coarser; finer ones to within a last-digit tie).

    Parameters
    ----------
    rec : Recording
        On the regular grid (:func:`prepare_recording`).
    reference : dict axis -> mm, optional
        The references to remove (the identification recording's, for its validation
        recording: both in one frame); default the first actual position of each axis.

    Returns a new Recording with ``metadata["reference_mm"]`` the reference of each axis.
    """
    from core.recording import AxisTrace, Recording

    ref = {name: float(tr.actual[0]) for name, tr in rec.axes.items()}
    ref.update({k: float(v) for k, v in (reference or {}).items() if k in rec.axes})

    def rel(v: np.ndarray, r: float) -> np.ndarray:
        return np.round((np.asarray(v, dtype=float) - r) / POSITION_GRID_MM) * POSITION_GRID_MM

    axes = {name: AxisTrace(rel(tr.commanded, ref[name]), rel(tr.actual, ref[name])) for name, tr in rec.axes.items()}
    return Recording(t=rec.t, axes=axes, sample_period=rec.sample_period, segment=rec.segment,
                     metadata={**rec.metadata, "reference_mm": ref})

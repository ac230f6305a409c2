"""The identification pipeline: :func:`identify` a :class:`Recording`, get an :class:`IdentifyResult`.

recording → preprocessing (sampling, gaps, plausibility) → regression (eq. 3.11, with
the preview shift) → constrained solver (exact / ga / ls) → output-error refinement →
free-run fits on identification and validation data → diagnosis → IdentifyResult.
Each stage is a function of ident/; this module only joins them and times them.
``agent identify`` is argument parsing and printing around :func:`identify`.
"""

from __future__ import annotations

import hashlib
import json
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Mapping, Sequence

import numpy as np

from core.errors import InputError, RapidIdentWarning, RecordingError
from core.reader import load_recording
from core.recording import Recording
from ident.axis_model import AxisModel
from ident.contour import contour_error
from ident.metrics import FitResult, fit_result
from ident.model import Bounds, DriveModel
from ident.plausibility import check_identifiable, never_moves
from ident.preprocessing import prepare_recording, remove_reference
from ident.refine import refine as refine_model
from ident.regression import build_regression
from ident.results import AxisResult, AxisTraces, ContourResult, IdentifyResult
from ident.simulation import FreeRun
from ident.preprocessing import segment_slices, shift_command
from ident.solvers import solve, solve_ls
from ident.uncertainty import Uncertainty, estimate_uncertainty, output_error_jacobian, stationary_point

if TYPE_CHECKING:  # the diagnosis is imported when used: it is most of ident's import time
    from ident.diagnosis.config import DiagnosisConfig

__all__ = ["identify", "load_models"]

SOLVERS = ("exact", "ga", "ls")


@dataclass(frozen=True)
class IdentifyOptions:
    """How :func:`identify` fits each axis (its keyword arguments, checked once)."""

    solver: str = "exact"  # exact | ga | ls
    bounds: Bounds = Bounds()  # pole constraints of eq. 3.8
    refine: bool = True  # output-error refinement after the equation-error solve
    diagnose: bool = True  # locate and explain the mismatch (ident.diagnosis)
    seed: int = 0  # of the genetic algorithm
    ga_population: int = 4000
    ga_generations: int = 500
    #: tunables of the diagnosis (``ident.diagnosis.config.DiagnosisConfig``); None: its defaults
    diagnosis_config: "DiagnosisConfig | None" = None

    def __post_init__(self) -> None:
        if self.solver not in SOLVERS:
            raise InputError.about("solver", f"solver {self.solver!r}: choose exact, ga or ls")
        if self.ga_population < 10 or self.ga_generations < 1:
            raise InputError("the GA needs a population of at least 10 and at least 1 generation")


def _name(rec: Recording, default: str) -> str:
    return str(rec.metadata.get("source") or default)


def _pick_axes(rec: Recording, wanted: Sequence[str] | None) -> list[str]:
    """The axes to identify: those ``wanted``, or by default every axis whose command moves.

    A capture often records every axis of the machine while the identification programs
    move one; an axis whose commanded position never changes is then left out with a
    warning, not refused (named with ``axes``, or when no axis moves, it is refused by
    :func:`ident.plausibility.check_identifiable`)."""
    if not wanted:
        still = [a for a in rec.axis_names if never_moves(rec.axes[a])]
        moving = [a for a in rec.axis_names if a not in still]
        if moving and still:
            warnings.warn(f"{_name(rec, 'the recording')}: axis {', '.join(still)} never moves (its commanded "
                          f"position stays at {', '.join(f'{rec.axes[a].commanded[0]:.6g}' for a in still)} mm): "
                          f"not identified", RapidIdentWarning, stacklevel=3)
        return moving or rec.axis_names
    out = []
    for a in wanted:
        a = a.strip().upper()
        if a not in rec.axes:
            raise InputError.about("axes", f"axis {a} is not in {_name(rec, 'the recording')} "
                                   f"(it has {', '.join(rec.axis_names)})")
        out.append(a)
    return out


def _free_run(model: AxisModel, rec: Recording, axis: str) -> np.ndarray:
    tr = rec.axes[axis]
    return model.simulate(tr.commanded, segment=rec.segment, x0=tr.actual)


def _fit_or_none(model: DriveModel, rec: Recording, axis: str, shift: int) -> FitResult | None:
    with np.errstate(all="ignore"):
        try:
            x_hat = _free_run(AxisModel(model, rec.sample_period, shift), rec, axis)
        except (FloatingPointError, ValueError, OverflowError):
            return None
    if not np.all(np.isfinite(x_hat)):
        return None
    tr = rec.axes[axis]
    return fit_result(tr.commanded - tr.actual, tr.commanded - x_hat)


def _ls_note(ls_model: DriveModel, bounds: Bounds, Ts: float, fit_ls: FitResult | None,
             fit_final: FitResult, duration_s: float, solver: str = "exact") -> str:
    violated = bounds.check(ls_model, Ts)
    poles = ", ".join(f"{f:.2f} Hz/ζ {d:.2f}" for f, d in ls_model.poles())
    run = ("its free-run simulation diverges" if fit_ls is None else
           f"its free-run tracking-error fit on this recording is {fit_ls.tracking_error_fit_pct:.1f} %")
    if solver == "ls":  # the model reported *is* this one: no constrained model to compare with
        if not violated:
            return f"Unconstrained least squares (solver ls): poles {poles}, inside the bounds; {run}."
        return (f"Unconstrained least squares (solver ls) applies no pole constraint: poles {poles}, outside the "
                f"allowed region ({', '.join(violated)}; poles up to {bounds.f_max_hz_for(Ts):g} Hz allowed); {run}. Such a model cannot be trusted on a longer part "
                f"program or in a virtual machine: use solver exact or ga for one inside the bounds of eq. 3.8.")
    if not violated:
        return (f"Unconstrained least squares gives poles {poles}, inside the bounds, and {run}; "
                f"the constraints are not active here.")
    roots = np.roots(ls_model.denominator)
    growth = float(np.max(roots.real))
    if growth > 0:
        tau = 1.0 / growth
        why = (f"an unstable model (a pole in the right half-plane, error growing e-fold every {tau:.3g} s"
               + (f", slower than this {duration_s:.0f} s recording shows" if tau > 0.3 * duration_s else "")
               + ")")
    else:
        why = "poles outside the allowed region (" + ", ".join(violated) + ")"
    return (f"Unconstrained least squares gives poles {poles}: {why}, and {run}. "
            f"Such a model cannot be trusted on a longer part program or used in a virtual machine; the "
            f"constraints of eq. 3.8 keep every pole at a stable, physically meaningful frequency and damping, "
            f"and the constrained model reaches {fit_final.tracking_error_fit_pct:.1f} %.")


def load_models(path: str | Path) -> dict[str, AxisModel]:
    """The per-axis models of an identification result JSON (``IdentifyResult.to_json``) as its virtual
    machine runs them (``virtual_model``): eq. 3.3 with the preview shift and sample period of that
    identification and the effects its diagnosis accepted."""
    from ident.virtual_machine import check_result_format

    name = Path(path).name
    try:
        doc = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise InputError.about("model", f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise InputError.about("model", f"{path}: not a result JSON ({str(exc).splitlines()[0]})") from None
    try:
        check_result_format(doc, name)
        out = {}
        for a, r in doc["axes"].items():
            out[str(a)] = AxisModel.from_dict(r["virtual_model"])
        return out
    except InputError as exc:
        raise InputError.about("model", str(exc)) from None
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError.about("model", f"{name}: a result JSON without a usable model ({type(exc).__name__}: "
                               f"{exc})") from None


def data_fingerprint(rec: Recording, axis: str) -> str:
    """SHA-256 of one axis's data as identified: sample period, segments, commanded and actual
    positions (relative to the first actual position, :func:`remove_reference`), float64."""
    h = hashlib.sha256()
    tr = rec.axes[axis]
    for a in (np.array([rec.sample_period]), np.asarray(rec.segment, dtype=np.int64), tr.commanded, tr.actual):
        h.update(np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<")).tobytes())
    return h.hexdigest()


def load_fingerprints(path: str | Path) -> dict[str, str]:
    """Per axis, :func:`data_fingerprint` of the data an identification result JSON's model was
    fitted to (``identified_on_sha256``; absent from older results and from a ``--model`` check)."""
    try:
        doc = json.loads(Path(path).read_text())
        return {str(a): str(r["identified_on_sha256"]) for a, r in doc["axes"].items() if r.get("identified_on_sha256")}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}  # load_models has said what is wrong with the file


def _axis(rec: Recording, axis: str, opts: IdentifyOptions, progress, val: Recording | None,
          against: Recording | None, prior: DriveModel | AxisModel | None,
          prior_source: str | None = None, prior_sha256: str | None = None) -> AxisResult:
    Ts = rec.sample_period
    tr = rec.axes[axis]
    sha = data_fingerprint(rec, axis)
    ref = rec.metadata.get("reference_mm", {}).get(axis, 0.0)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    reg = build_regression(tr.commanded, tr.actual, Ts, rec.segment, axis=axis)
    timings["regression"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    ls = solve_ls(reg.Phi, reg.Y, opts.bounds, sample_period=Ts)
    if opts.solver == "ls":
        constrained = ls
    elif opts.solver == "ga":
        constrained = solve(opts.solver, reg.Phi, reg.Y, opts.bounds, sample_period=Ts, seed=opts.seed,
                            population=opts.ga_population, generations=opts.ga_generations)
    else:
        constrained = solve(opts.solver, reg.Phi, reg.Y, opts.bounds, sample_period=Ts)
    timings["solver"] = time.perf_counter() - t0

    refined = None
    model = constrained.model
    shift = reg.shift
    if isinstance(prior, AxisModel):  # scored as it was saved: its own preview shift and effects
        if not np.isclose(prior.sample_period, Ts, rtol=1e-6):
            raise InputError.about("model", f"the model of axis {axis} was identified at a sample period of "
                                   f"{prior.sample_period * 1e3:g} ms, the recording's is {Ts * 1e3:g} ms")
        model, shift = prior.model, prior.shift
    elif prior is not None:
        model = prior
    elif opts.refine and opts.solver != "ls":
        t0 = time.perf_counter()
        refined = refine_model(constrained.model, tr.commanded, tr.actual, Ts, segment=rec.segment,
                               shift=reg.shift, bounds=opts.bounds, regression=reg)
        model = refined.model
        timings["refinement"] = time.perf_counter() - t0

    uncertainty = None
    if prior is None:
        t0 = time.perf_counter()
        model, uncertainty = _intervals(model, rec, axis, reg.shift, opts.bounds, polish=refined is not None)
        timings["intervals"] = time.perf_counter() - t0

    # what the fits score and the diagnosis starts from: a saved model with the effects it carries
    scored = prior if isinstance(prior, AxisModel) else AxisModel(model, Ts, shift)
    t0 = time.perf_counter()
    x_hat = _free_run(scored, rec, axis)
    fit_id = fit_result(tr.commanded - tr.actual, tr.commanded - x_hat)
    fit_eq = _fit_or_none(constrained.model, rec, axis, reg.shift) or FitResult(float("nan"), float("nan"))
    fit_ls = _fit_or_none(ls.model, rec, axis, reg.shift)
    val_traces = None
    fit_val = None
    if val is not None:
        vt = val.axes[axis]
        xv_hat = _free_run(scored, val, axis)
        fit_val = fit_result(vt.commanded - vt.actual, vt.commanded - xv_hat)
        val_traces = AxisTraces(val.t, vt.commanded + ref, vt.actual + ref, xv_hat + ref, val.segment)
    timings["fits"] = time.perf_counter() - t0

    diagnosis = None
    if opts.diagnose:
        t0 = time.perf_counter()
        diagnosis = _diagnose(rec, axis, scored, val, against,
                              (lambda msg: progress(f"axis {axis}: {msg}")) if progress else None,
                              opts.diagnosis_config)
        timings["diagnosis"] = time.perf_counter() - t0

    return AxisResult(
        axis=axis, model=model, constrained=constrained, unconstrained=ls, refined=refined,
        bounds=opts.bounds, sample_period=Ts, shift=shift,
        fit_identification=fit_id, fit_validation=fit_val, fit_constrained=fit_eq, fit_unconstrained=fit_ls,
        unconstrained_note=_ls_note(ls.model, opts.bounds, Ts, fit_ls, fit_id, rec.duration, opts.solver),
        diagnosis=diagnosis, timings=timings, uncertainty=uncertainty,
        traces=AxisTraces(rec.t, tr.commanded + ref, tr.actual + ref, x_hat + ref, rec.segment),
        validation_traces=val_traces, prior_source=prior_source if prior is not None else None,
        prior=prior if isinstance(prior, AxisModel) else None,
        data_sha256=sha, prior_on_its_own_data=prior is not None and prior_sha256 == sha,
    )


def _intervals(model: DriveModel, rec: Recording, axis: str, shift: int, bounds: Bounds,
               polish: bool) -> tuple[DriveModel, Uncertainty | None]:
    """95 % intervals of the model from its output-error Jacobian (:mod:`ident.uncertainty`).

    After the output-error refinement (``polish``) the model is first taken to the
    stationary point of the cost on every sample, where the covariance holds.  Without
    refinement the intervals are those of the output-error cost at the equation-error
    model.  None when the free run of the model is not finite (no interval can be given).
    """
    tr = rec.axes[axis]
    Ts = rec.sample_period
    free_run = FreeRun(shift_command(tr.commanded, shift, rec.segment), Ts, segment=rec.segment, x0=tr.actual)
    with np.errstate(all="ignore"):
        try:
            if polish:
                model, J, r = stationary_point(free_run, model, tr.actual, bounds=bounds, sample_period=Ts)
            else:
                J, r = output_error_jacobian(free_run, model, tr.actual)
        except (FloatingPointError, ValueError, OverflowError):
            return model, None
    if not (np.all(np.isfinite(J)) and np.all(np.isfinite(r))):
        return model, None
    # response to each segment's start position (the recorded one, noise included)
    h = 1e-4  # mm
    J_start = []
    for sl in segment_slices(rec.segment, tr.actual.size):
        x0 = tr.actual.copy()
        x0[sl.start] += h
        moved = FreeRun(free_run.x_r, Ts, segment=rec.segment, x0=x0)(model)
        J_start.append((moved - (r + tr.actual)) / h)
    u = estimate_uncertainty(model, J, r, bounds=bounds, sample_period=Ts, segment=rec.segment,
                             J_start=np.column_stack(J_start))
    if not polish:
        u = replace(u, method=u.method + "; at the equation-error model, which is not the output-error optimum "
                    "(no refinement): the intervals are indicative only")
    return model, u


def _diagnose(rec: Recording, axis: str, model: AxisModel, val: Recording | None, against: Recording | None,
              progress=None, config=None):
    """Run the diagnosis on the command *as recorded*.

    The preview shift of the identification is deliberately not applied: a dead time is
    one of the effects the diagnosis looks for, and a shift would hide it.  The diagnosis
    re-fits the base model in its own simulator before trying any effect; the effects
    ``model`` carries (a saved model's) stay in that base and are not tried again.
    """
    from ident.diagnosis import diagnose  # imported when used: it is most of ident's import time

    tr = rec.axes[axis]
    ref = rec.metadata.get("reference_mm", {}).get(axis, 0.0)
    validation = None
    if val is not None:
        vt = val.axes[axis]
        validation = (vt.commanded, vt.actual, val.segment)
    sim_actual = None
    if against is not None:
        if axis not in against.axes or against.n_samples != rec.n_samples:
            raise InputError.about("against", f"the simulated recording must hold axis {axis} with the same "
                                   f"{rec.n_samples} samples as the recording (it has {against.n_samples})")
        sim_actual = against.axes[axis].actual - ref
    return diagnose(tr.commanded, tr.actual, rec.sample_period, model, progress=progress,
                    segment=rec.segment, validation=validation, against=sim_actual, config=config, reference=ref)


def _contour(results: dict[str, AxisResult], rec: Recording, val: Recording | None) -> ContourResult | None:
    names = list(results)
    for source, which in ((val, "validation"), (rec, "identification")):
        if source is None:
            continue
        axes = [a for a in names if a in source.axes]
        if len(axes) < 2:
            continue
        ax, ay = axes[:2]
        traces = {a: (results[a].validation_traces if which == "validation" else results[a].traces) for a in (ax, ay)}
        tx, ty = traces[ax], traces[ay]
        if tx is None or ty is None:
            continue
        measured = contour_error(tx.commanded, ty.commanded, tx.actual, ty.actual)
        predicted = contour_error(tx.commanded, ty.commanded, tx.simulated, ty.simulated)
        return ContourResult((ax, ay), which, tx.t, measured, predicted)
    return None


def _as_recording(rec: Recording | str | Path, what: str) -> Recording:
    if isinstance(rec, Recording):
        return rec
    if isinstance(rec, (str, Path)):
        return load_recording(rec)
    raise InputError.about(what, f"expected a Recording or a path to a .mcap/.csv file, got {type(rec).__name__}")


def identify(
    recording: Recording | str | Path,
    axes: Sequence[str] | None = None,
    solver: str = "exact",
    validate: Recording | str | Path | None = None,
    diagnose: bool = True,
    *,
    against: Recording | str | Path | None = None,
    prior: Mapping[str, DriveModel | AxisModel] | None = None,
    prior_source: str | None = None,
    prior_sha256: Mapping[str, str] | None = None,
    bounds: Bounds = Bounds(),
    refine: bool = True,
    seed: int = 0,
    ga_population: int = 4000,
    ga_generations: int = 500,
    progress: Callable[[str], None] | None = None,
    diagnosis_config: "DiagnosisConfig | None" = None,
    units: str = "auto",
) -> IdentifyResult:
    """Identify the drive model of every (or each chosen) axis of a recording.

    Parameters
    ----------
    recording : a :class:`Recording` (e.g. ``Recording.from_arrays``) or a path to one.
    axes : axis names to identify; default every axis of the recording.
    solver : ``exact`` (certified constrained optimum), ``ga`` (thesis §4.2) or ``ls``
        (unconstrained eq. 3.12).
    validate : another recording of the same axes to score the model on (free run).
    diagnose : locate and explain the mismatch (ident.diagnosis).
    against : a simulated recording of the same program; the diagnosis then compares
        virtual and real machine.
    prior : per-axis models to check instead of identifying anew (see :func:`load_models`); an
        :class:`AxisModel` is scored as it was saved (its own preview shift and effects) on
        ``recording``, which is then held-out data, and the diagnosis looks for what it lacks.
    prior_source : where ``prior`` came from (a file name), for the summary and the JSON.
    prior_sha256 : per axis, :func:`data_fingerprint` of the data ``prior`` was fitted to
        (:func:`load_fingerprints`): on those very data its fit is not called held out.
    bounds : pole constraints of eq. 3.8 (SPEC §5 defaults).
    refine : output-error refinement after the equation-error solve.
    seed, ga_population, ga_generations : of the genetic algorithm (``solver="ga"``).
    progress : called with a short description of each diagnosis stage (a progress line).
    diagnosis_config : an :class:`ident.diagnosis.config.DiagnosisConfig` (its tunables, e.g.
        for a benchmark's sweep); default its documented values.
    units : positions in "mm", in "m" (converted), or "auto": metres recorded in the metadata
        are converted, values that only look like metres are refused
        (:func:`ident.plausibility.check_identifiable`, which every recording passes first).

    Returns
    -------
    IdentifyResult
        Per axis: the model, the equation-error and unconstrained solutions, the fits
        (SPEC §5 metric) and the diagnosis; ``to_json()`` gives SPEC §6, ``report(path)``
        the HTML report.
    """
    from threadpoolctl import threadpool_limits

    opts = IdentifyOptions(solver=solver, bounds=bounds, refine=refine, diagnose=diagnose, seed=seed,
                           ga_population=ga_population, ga_generations=ga_generations,
                           diagnosis_config=diagnosis_config)
    t_start = time.perf_counter()
    # The fits solve thousands of 3x3..9x9 systems: a multi-threaded BLAS would spend
    # more on hand-offs between threads than on the arithmetic.
    with threadpool_limits(limits=1, user_api="blas"):
        rec = prepare_recording(_as_recording(recording, "recording"), check_units=False)
        names = _pick_axes(rec, axes)
        # positions relative to the recording's first actual position (bit for bit the same
        # arrays wherever the axis's origin lies), after the checks that read absolute positions
        # (units); the traces and a cyclic error's phase are told back in absolute position
        rec = remove_reference(check_identifiable(rec, names, units=units))
        val = prepare_recording(_as_recording(validate, "validate"), check_units=False) if validate is not None else None
        if val is not None:
            missing = [a for a in names if a not in val.axes]
            if missing:
                raise InputError.about("validate", f"validation recording {_name(val, '')}: axis {missing[0]} "
                                       f"is not in it (it has {', '.join(val.axis_names)})")
            if not np.isclose(val.sample_period, rec.sample_period, rtol=1e-6):
                raise RecordingError.about(
                    "validate", f"validation recording {_name(val, '')}: sample period {val.sample_period * 1e3:.4g} "
                    f"ms differs from the recording's {rec.sample_period * 1e3:.4g} ms")
            val = remove_reference(check_identifiable(val, names, units=units), rec.metadata["reference_mm"])
        sim = _as_recording(against, "against") if against is not None else None
        priors = dict(prior or {})
        for a in names:
            if priors and a not in priors:
                raise InputError.about("model", f"the given models have none for axis {a}")
        results = {a: _axis(rec, a, opts, progress, val, sim, priors.get(a), prior_source,
                            (prior_sha256 or {}).get(a)) for a in names}
        contour = _contour(results, rec, val)
    meta = {k: v for k, v in rec.metadata.items() if k not in ("events", "counter", "source")}
    return IdentifyResult(_name(rec, "<in memory>"), _name(val, "<in memory>") if val is not None else None,
                          results, contour, time.perf_counter() - t_start, meta)

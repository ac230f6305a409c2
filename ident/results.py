"""What `agent identify` found, per axis, as frozen dataclasses; the JSON of SPEC §6 comes from here."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ident.axis_model import BASE_KEYS, AxisModel
from ident.metrics import FitResult
from ident.model import Bounds, DriveModel
from ident.refine import RefineResult
from ident.solvers.common import SolverResult
from ident.uncertainty import Uncertainty

__all__ = ["AxisTraces", "AxisResult", "ContourResult", "IdentifyResult", "RESULT_FORMAT"]

#: ``format`` of the result JSON; version 2 carries each axis's ``virtual_model``.
RESULT_FORMAT = "rapid-ident-result/2"


@dataclass(frozen=True)
class AxisTraces:
    """Arrays the report plots (not in the JSON): time s, positions mm, shape (N,)."""

    t: np.ndarray
    commanded: np.ndarray
    actual: np.ndarray
    simulated: np.ndarray
    segment: np.ndarray


@dataclass(frozen=True)
class AxisResult:
    """Identification of one axis.

    ``model`` is the final model (refined by output error unless refinement was off);
    ``constrained`` the equation-error solution of the chosen solver; ``unconstrained``
    the plain least-squares solution of eq. 3.12 kept for comparison.
    """

    axis: str
    model: DriveModel
    constrained: SolverResult
    unconstrained: SolverResult
    refined: RefineResult | None
    bounds: Bounds
    sample_period: float
    shift: int
    fit_identification: FitResult
    fit_validation: FitResult | None
    fit_constrained: FitResult
    fit_unconstrained: FitResult | None
    unconstrained_note: str
    diagnosis: Any | None = None
    timings: dict[str, float] = field(default_factory=dict)
    traces: AxisTraces | None = None
    validation_traces: AxisTraces | None = None
    #: 95 % intervals of the final model (None for a model given with ``--model``)
    uncertainty: Uncertainty | None = None
    #: the file of an earlier identification whose model this scores (``--model``); None: identified here
    prior_source: str | None = None
    #: that saved model as its virtual machine runs it (``model`` and ``shift`` are its own), effects included
    prior: AxisModel | None = None
    #: fingerprint of this axis's data (:func:`ident.pipeline.data_fingerprint`): an identification
    #: result says which data its model was fitted to
    data_sha256: str = ""
    #: ``--model`` scored on the very data its model was fitted to: no held-out figure
    prior_on_its_own_data: bool = False

    @property
    def base_model(self) -> AxisModel:
        """What the fit figures score: the identified eq. 3.3 with its preview shift, or the
        saved model given with ``--model`` with the effects it carries."""
        return self.prior if self.prior is not None else AxisModel(self.model, self.sample_period, self.shift)

    @property
    def refit_predicts_better(self) -> bool:
        """Whether the diagnosis's re-fit of the model, without any effect added, predicts the
        validation recording better than the identified model does.

        The diagnosis re-fits eq. 3.3 in free run on the command as recorded, on the control
        law that fits best (continuous, or sampled and held as a digital drive computes it),
        and scores that reference on the validation recording; the identified model is
        scored on the same recording.  A drive whose control law is sampled (a P-PI cascade
        in a digital drive) can be predicted many times better by the re-fit (0.13 µm rms
        against 2.95 µm on the virtual CNC's fadal-ppi).  Only with a validation recording:
        a cross-validated figure is not comparable with the identification's fit.
        """
        d = self.diagnosis
        aug = getattr(d, "augmented_model", None) or {}
        if self.prior is not None or aug.get("effects") or aug.get("held_out") != "validation recording":
            return False
        fv = self.fit_validation
        return fv is not None and math.isfinite(d.fit_after_pct) and d.fit_after_pct > fv.tracking_error_fit_pct

    @property
    def runs_refit(self) -> bool:
        """Whether the virtual machine runs the diagnosis's model (:attr:`virtual_model`), not the
        model the fit figures score."""
        aug = getattr(self.diagnosis, "augmented_model", None) or {}
        added = set(aug.get("effects") or ()) - set(self.prior.effects if self.prior else ())
        return bool(added) or self.refit_predicts_better

    @property
    def virtual_model(self) -> AxisModel:
        """What the virtual machine runs: the model that predicts held-out data best.

        The diagnosed model with its accepted effects, if any: the diagnosis re-fits the base
        parameters together with the effects (on the command as recorded, no preview
        shift).  Without an added effect (to those a saved model carries), the diagnosis's
        re-fit where it predicts the validation recording better
        (:attr:`refit_predicts_better`), else the model the fit figures score.
        """
        if self.runs_refit:
            aug = self.diagnosis.augmented_model
            base = aug["base"]
            return AxisModel(DriveModel(**{k: float(base[k]) for k in BASE_KEYS}), self.sample_period, 0,
                             {e: dict(p) for e, p in aug["effects"].items()}, aug.get("controller", "continuous"))
        return self.base_model

    def predict(self, x_r: np.ndarray, *, segment: np.ndarray | None = None,
                x0: float | np.ndarray | None = None) -> np.ndarray:
        """Free-run actual position (mm) the identified model predicts for the commanded ``x_r`` (mm).

        Applies the identification's preview shift (§4.3.2) so the prediction matches
        the fit figures; ``segment`` and ``x0`` as in :meth:`AxisModel.simulate`.
        """
        return self.base_model.simulate(x_r, segment=segment, x0=x0)

    @property
    def active_constraints(self) -> tuple[str, ...]:
        if self.refined is not None:
            return tuple(self.refined.active_constraints)
        return tuple(self.constrained.active_constraints)

    def to_dict(self) -> dict[str, Any]:
        out = self.model.to_dict(self.bounds, self.sample_period)
        if self.uncertainty is not None:
            _add_intervals(out, self.uncertainty)
        out["solver"] = self.constrained.solver
        out["refined"] = self.refined is not None
        out["active_constraints"] = list(self.active_constraints)
        out["bounds"] = self.bounds.with_sample_period(self.sample_period).to_dict()
        out["preview_shift_samples"] = self.shift
        if self.prior_source is not None:
            out["model_from"] = self.prior_source
            out["model_identified_on_this_recording"] = self.prior_on_its_own_data
        else:
            out["identified_on_sha256"] = self.data_sha256
        out["fit"] = {"identification": self.fit_identification.to_dict(),
                      "validation": self.fit_validation.to_dict() if self.fit_validation else None}
        eq = self.constrained.model.to_dict(self.bounds, self.sample_period)
        out["equation_error"] = {
            "model": eq["model"], "poles": eq["poles"], "zeros": eq["zeros"],
            "search_variables": eq["search_variables"],
            "active_constraints": list(self.constrained.active_constraints),
            "cost": float(self.constrained.cost),
            "condition_number": float(self.constrained.condition_number),
            "fit": {"identification": self.fit_constrained.to_dict()},
            "certificate": _jsonable(self.constrained.details.get("certificate")),
        }
        ls = self.unconstrained.model.to_dict(None, self.sample_period)
        out["unconstrained_ls"] = {
            "model": ls["model"], "poles": ls["poles"], "zeros": ls["zeros"],
            "violated_constraints": self.bounds.check(self.unconstrained.model, self.sample_period),
            "fit": {"identification": self.fit_unconstrained.to_dict() if self.fit_unconstrained else None},
            "condition_number": float(self.unconstrained.condition_number),
            "note": self.unconstrained_note,
        }
        if self.refined is not None:
            out["refinement"] = {"fit_before": self.refined.fit_before.to_dict(),
                                 "fit_after": self.refined.fit_after.to_dict(),
                                 "nfev": int(self.refined.nfev), "improved": bool(self.refined.improved)}
        if self.diagnosis is not None:
            out["diagnosis"] = self.diagnosis.to_dict()
        out["virtual_model"] = self.virtual_model.to_dict()
        if self.traces is not None:
            out["virtual_model"]["identified_range"] = _identified_range(self.traces)
        out["timings_s"] = {k: round(float(v), 4) for k, v in self.timings.items()}
        return out


@dataclass(frozen=True)
class ContourResult:
    """Predicted vs measured contour error of a two-axis recording, mm."""

    axes: tuple[str, str]
    source: str
    t: np.ndarray
    measured: np.ndarray
    predicted: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        def stats(e):
            return {"max_abs_mm": float(np.max(np.abs(e))), "rms_mm": float(np.sqrt(np.mean(e ** 2)))}
        diff = self.measured - self.predicted
        return {"axes": list(self.axes), "source": self.source, "measured": stats(self.measured),
                "predicted": stats(self.predicted), "prediction_error": stats(diff)}


@dataclass(frozen=True)
class IdentifyResult:
    """What :func:`ident.identify` found: one :class:`AxisResult` per axis, and the contour check.

    ``to_json()`` is the SPEC §6 document ``agent identify --json`` writes;
    ``report(path)`` writes the self-contained HTML report.
    """

    source: str
    validation_source: str | None
    axes: dict[str, AxisResult]
    contour: ContourResult | None
    elapsed_s: float
    metadata: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": RESULT_FORMAT,
            "source": self.source,
            "validation_source": self.validation_source,
            "axes": {name: r.to_dict() for name, r in self.axes.items()},
            "contour": self.contour.to_dict() if self.contour else None,
            "elapsed_s": round(self.elapsed_s, 4),
            "recording": _jsonable(self.metadata),
        }

    def to_json(self, indent: int | None = 2) -> str:
        """The SPEC §6 JSON document (strict JSON: no NaN)."""
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False, default=_json_default)

    def report(self, path: str | Path) -> Path:
        """Write the self-contained HTML report to ``path``."""
        from ident.report import write_report

        return write_report(self, path)

    @property
    def models(self) -> dict[str, DriveModel]:
        """The final drive model of each axis."""
        return {name: r.model for name, r in self.axes.items()}


def _add_intervals(out: dict[str, Any], u: Uncertainty) -> None:
    """Intervals beside SPEC's keys: ``model_interval95`` etc., and per pole/zero entries.

    The SPEC keys ("model", "poles", "zeros", "search_variables") keep their meaning; each
    pole and zero dict gains ``freq_hz_interval95``, ``damping_interval95``, ``at_bound``
    and ``undetermined`` (same order as :meth:`DriveModel.poles`).
    """
    d = u.to_dict()
    for key in ("poles", "zeros"):
        extra = d.pop(key)
        if len(extra) == len(out[key]):
            out[key] = [{**base, **{k: v for k, v in e.items() if k not in ("freq_hz", "damping")}}
                        for base, e in zip(out[key], extra)]
    out["intervals"] = {k: d.pop(k) for k in ("method", "samples", "residual_rms_mm", "standard_error",
                                                "weak_directions")}
    out.update(d)


def _identified_range(tr: AxisTraces) -> dict[str, Any]:
    """Speed and travel the model was identified over: where the virtual machine interpolates."""
    x = np.asarray(tr.commanded, dtype=float)
    same = np.diff(tr.segment) == 0
    dt = np.diff(tr.t)
    v = np.abs(np.diff(x))[same] / dt[same] if x.size > 1 else np.zeros(1)
    return {"max_speed_mm_s": float(np.max(v, initial=0.0)), "travel_mm": [float(x.min()), float(x.max())]}


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist() if obj.size <= 64 else f"<array of {obj.size}>"
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj

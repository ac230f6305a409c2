"""Fit metrics of SPEC §5: how well a simulated tracking error matches the recorded one.

The tracking error is ``e = x_r - x`` (commanded minus actual, as recorded, mm) and its
prediction ``ê = x_r - x̂`` where ``x̂`` is the model's free-run response to the
commanded trajectory alone (``ident.simulation.simulate``), never a one-step
prediction.  One metric is used everywhere::

    tracking-error fit % = 100 · (1 − ‖e − ê‖ / ‖e − mean(e)‖)

100 % is a perfect prediction, 0 % is as good as predicting the mean error, and it is
negative when the model is worse than that.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ident.fixed_order import norm

__all__ = ["FitResult", "tracking_error_fit_pct", "tracking_error_rms", "fit_result"]


@dataclass(frozen=True)
class FitResult:
    """Fit of a simulated tracking error to the recorded one.

    Attributes
    ----------
    tracking_error_fit_pct : float
        100·(1 − ‖e − ê‖/‖e − mean(e)‖), %.
    tracking_error_rms_mm : float
        RMS of the prediction error ``e − ê``, mm.
    """

    tracking_error_fit_pct: float
    tracking_error_rms_mm: float

    def to_dict(self) -> dict[str, float]:
        """The JSON form of SPEC §6 (``{"tracking_error_fit_pct": …, "tracking_error_rms_mm": …}``)."""
        return {k: float(v) for k, v in asdict(self).items()}


def _pair(e: np.ndarray, e_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    e = np.asarray(e, dtype=float).ravel()
    e_hat = np.asarray(e_hat, dtype=float).ravel()
    if e.shape != e_hat.shape:
        raise ValueError(f"e has {e.size} samples but e_hat has {e_hat.size}")
    if e.size == 0:
        raise ValueError("cannot score an empty tracking error")
    return e, e_hat


def tracking_error_fit_pct(e: np.ndarray, e_hat: np.ndarray) -> float:
    """Tracking-error fit in % (SPEC §5): ``100·(1 − ‖e − ê‖/‖e − mean(e)‖)``.

    Parameters
    ----------
    e : ndarray (N,)
        Recorded tracking error x_r − x, mm.
    e_hat : ndarray (N,)
        Simulated tracking error x_r − x̂, mm.

    Returns ``-inf`` when the recorded error is constant and the prediction is not
    exact, 100.0 when both are equal.
    """
    e, e_hat = _pair(e, e_hat)
    # in a fixed order (np.linalg.norm is a BLAS dot, whose order depends on the machine):
    # refine.py keeps a model on comparing two of these figures
    num = norm(e - e_hat)
    den = norm(e - e.mean())
    if den == 0.0:
        return 100.0 if num == 0.0 else float("-inf")
    return 100.0 * (1.0 - num / den)


def tracking_error_rms(e: np.ndarray, e_hat: np.ndarray) -> float:
    """RMS of the tracking-error prediction error ``e − ê``, mm."""
    e, e_hat = _pair(e, e_hat)
    return float(np.sqrt(np.mean((e - e_hat) ** 2)))


def fit_result(e: np.ndarray, e_hat: np.ndarray) -> FitResult:
    """Both figures of SPEC §5 as a :class:`FitResult` (e, ê in mm)."""
    return FitResult(tracking_error_fit_pct(e, e_hat), tracking_error_rms(e, e_hat))

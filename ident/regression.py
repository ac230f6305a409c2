"""The linear regression of eq. 3.11: Y = Φ·θ + residual, built from commanded and actual position.

Eq. 3.9 predicts the axis position from measured signals::

    x̂_k = α_i·e_i,k − α_1·ẋ_k − α_2·ẍ_k + β_0·x_r,k + β_1·ẋ_r,k + β_2·ẍ_r,k
          − PV(ẋ_k)·δ⁺ − NV(ẋ_k)·δ⁻

so with ``θ = [α_i, α_1, α_2, β_0, β_1, β_2, δ⁺, δ⁻]`` (eq. 3.10: the eq. 3.3 parameters
normalised by a2) the rows of Φ are (eq. 3.11)::

    [e_i, −ẋ, −ẍ, x_r, ẋ_r, ẍ_r, −PV(ẋ), −NV(ẋ)]

and Y = x.  The solvers (``ident.solvers``) minimise ½‖Y − Φθ‖² (eq. 3.12) with or
without the pole constraints of eq. 3.8.

Preprocessing (see :mod:`ident.preprocessing`): optional zero-phase low-pass of x and x_r
alike; central differences (eq. 3.9) and the integrated error per segment; 2 samples
dropped at each segment end (where ẍ is undefined) plus the samples a command shift
fills; segments joined by stacking their rows (§4.3.3) — nothing spans a seam.

The integer **preview shift** (§4.3.2) between command and measurement is chosen, when
``shift="auto"``, as the one in ``−max_shift … +max_shift`` samples whose unconstrained LS
cost per kept sample is lowest (all candidates compared on the same samples).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from core.errors import IdentificationError, InputError
from ident import preprocessing as pp
from ident.fixed_order import lstsq, matvec, sum_squares, unit_columns

__all__ = ["Regression", "build_regression", "lstsq_scaled", "COLUMNS"]

#: Column names of Φ in eq. 3.11 order, and the θ entry each one multiplies.
COLUMNS = ("e_i", "-xd", "-xdd", "x_r", "xd_r", "xdd_r", "-PV", "-NV")


@dataclass(frozen=True)
class Regression:
    """The regression problem of eq. 3.11 for one axis.

    Attributes
    ----------
    Phi : ndarray (M, 8)
        Regressor, columns ``[e_i (mm·s), −ẋ (mm/s), −ẍ (mm/s²), x_r (mm), ẋ_r (mm/s),
        ẍ_r (mm/s²), −PV, −NV]``.
    Y : ndarray (M,)
        Actual position x at the kept samples, mm.
    index : ndarray of int (M,)
        Which input samples the rows are (indices into the arrays given to
        :func:`build_regression`).
    shift : int
        Preview shift applied to the command, samples (positive = command earlier).
    Ts : float
        Sample period, s.
    vel_threshold : float
        PV/NV velocity threshold used, mm/s.
    lowpass_hz : float or None
        Zero-phase low-pass cutoff used, Hz.
    command : ndarray (N,)
        The full shifted (unfiltered) command, mm: the input the identified model must be
        simulated with (:func:`ident.simulation.simulate`).
    segment : ndarray of int (N,)
        Segment ids of all input samples.
    shift_costs : dict[int, float]
        LS cost per kept sample (mm²) for each shift tried (empty for a fixed shift).
    """

    Phi: np.ndarray
    Y: np.ndarray
    index: np.ndarray
    shift: int
    Ts: float
    vel_threshold: float
    lowpass_hz: float | None
    command: np.ndarray
    segment: np.ndarray
    shift_costs: dict[int, float] = field(default_factory=dict)

    @property
    def n_rows(self) -> int:
        return int(self.Y.shape[0])


def lstsq_scaled(Phi: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, float]:
    """Unconstrained LS of eq. 3.12 with unit-norm column scaling; returns (θ, ½‖Y − Φθ‖²)."""
    Phi_s, scale = unit_columns(Phi)
    theta = lstsq(Phi_s, Y) / scale
    return theta, 0.5 * sum_squares(Y - matvec(Phi, theta))


def _shift_cost(Phi: np.ndarray, Y: np.ndarray, mask: np.ndarray) -> float:
    """½‖Y − Φθ‖² of the LS solution on the masked rows, for comparing command shifts.

    Normal equations on the column-scaled Gram matrix (8×8; ``einsum`` without BLAS, whose
    threading costs more than the arithmetic on a loaded machine); the residual is then
    summed explicitly, so the cost — stationary in θ — is accurate even where θ is not.
    """
    P = Phi[mask]
    y = Y[mask]
    A = np.einsum("ki,kj->ij", P, P)
    b = np.einsum("ki,k->i", P, y)
    d = np.sqrt(np.diag(A))
    d[d == 0] = 1.0
    As = A / np.outer(d, d)
    theta = lstsq(As, b / d) / d
    r = y - np.einsum("ki,i->k", P, theta)
    return 0.5 * float(np.einsum("k,k->", r, r))


def _phi(x_r_s, x_f, xd, xdd, dirn, Ts, segment, rule):
    xrd, xrdd = pp.central_derivatives(x_r_s, Ts, segment)
    e_i = pp.integrated_error(x_r_s, x_f, Ts, segment, rule=rule)
    pv = (dirn > 0).astype(float)
    nv = (dirn < 0).astype(float)
    return np.column_stack([e_i, -xd, -xdd, x_r_s, xrd, xrdd, -pv, -nv])


def build_regression(
    x_r: np.ndarray,
    x: np.ndarray,
    Ts: float,
    segment: np.ndarray | None = None,
    *,
    shift: int | Literal["auto"] = "auto",
    max_shift: int = 5,
    vel_threshold: float | Literal["auto"] = "auto",
    lowpass_hz: float | None = None,
    standstill: Literal["hold", "zero", "drop"] = "drop",
    integral_rule: Literal["trapezoid", "rectangle"] = "trapezoid",
    axis: str = "X",
) -> Regression:
    """Build Φ and Y of eq. 3.11 from commanded and actual position on a regular grid.

    Parameters
    ----------
    x_r, x : ndarray (N,)
        Commanded and actual position, mm, sampled every ``Ts`` (regularise first with
        :func:`ident.preprocessing.regularise_sampling`).
    Ts : float
        Sample period, s.
    segment : ndarray of int (N,), optional
        Segment ids (low-/high-speed sets, pieces between gaps); ``None`` = one segment.
    shift : int or "auto"
        Preview shift of the command in samples (positive = command earlier, §4.3.2);
        ``"auto"`` picks the LS-optimal one in ``±max_shift``.
    max_shift : int
        Search range for ``shift="auto"``, samples.
    vel_threshold : float or "auto"
        PV/NV threshold on ẋ, mm/s; ``"auto"`` estimates it from the noise of x
        (:func:`ident.preprocessing.velocity_threshold`).
    lowpass_hz : float or None
        Zero-phase Butterworth cutoff applied to x and x_r before differentiation, Hz;
        None (default) = no filter.
    standstill : "drop" | "hold" | "zero"
        Samples with |ẋ| inside the velocity band: leave the rows out (default — while
        the axis sticks its friction is anywhere in [d1, d0], which eq. 3.9 cannot
        express), keep the last direction, or set PV = NV = 0.
    integral_rule : "trapezoid" | "rectangle"
        How e_i integrates (rectangle = eq. 3.9 literally).
    axis : str
        Axis name for error messages.

    Raises
    ------
    RecordingError
        NaN/inf, too few samples.
    IdentificationError
        No motion, no reversals, too few samples left after dropping segment edges.
    """
    x_r = np.asarray(x_r, dtype=float)
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    if x_r.shape != (n,):
        raise ValueError(f"x_r has shape {x_r.shape} but x has {x.shape}")
    segment = pp._segment_array(segment, n)
    pp.check_motion(x_r, x, Ts, axis=axis, segment=segment, warn_units=False)  # units: on load

    x_f, x_r_f = x, x_r
    if lowpass_hz is not None:
        x_f = pp.lowpass(x, Ts, lowpass_hz, segment)
        x_r_f = pp.lowpass(x_r, Ts, lowpass_hz, segment)
    xd, xdd = pp.central_derivatives(x_f, Ts, segment)
    thr = pp.velocity_threshold(x, Ts, segment) if vel_threshold == "auto" else float(vel_threshold)
    if standstill not in ("hold", "zero", "drop"):
        raise InputError(f"standstill must be 'hold', 'zero' or 'drop', got {standstill!r}")
    dirn = pp.direction(xd, thr, standstill="zero" if standstill == "zero" else "hold", segment=segment)
    moving = np.abs(np.nan_to_num(xd)) > thr
    pp.check_reversals(dirn[np.isfinite(xd)], axis=axis)

    costs: dict[int, float] = {}
    if shift == "auto":
        mask = pp.interior_mask(segment, n, head=max_shift, tail=max_shift)
        if standstill == "drop":
            mask &= moving
        if mask.sum() < 8:
            raise IdentificationError(
                f"axis {axis}: only {int(mask.sum())} usable samples after dropping segment edges"
            )
        for s in range(-max_shift, max_shift + 1):
            Phi = _phi(pp.shift_command(x_r_f, s, segment), x_f, xd, xdd, dirn, Ts, segment, integral_rule)
            costs[s] = _shift_cost(Phi, x_f, mask) / mask.sum()
        shift_used = min(costs, key=costs.__getitem__)
    elif isinstance(shift, (int, np.integer)) and not isinstance(shift, bool):
        shift_used = int(shift)
    else:
        raise InputError(f"shift must be an integer number of samples or 'auto', got {shift!r}")

    mask = pp.interior_mask(segment, n, head=max(0, -shift_used), tail=max(0, shift_used))
    if standstill == "drop":
        mask &= moving
    if mask.sum() < 8:
        raise IdentificationError(
            f"axis {axis}: only {int(mask.sum())} usable samples after dropping segment edges"
        )
    Phi = _phi(pp.shift_command(x_r_f, shift_used, segment), x_f, xd, xdd, dirn, Ts, segment, integral_rule)
    index = np.flatnonzero(mask)
    return Regression(
        Phi=Phi[index],
        Y=x_f[index].copy(),
        index=index,
        shift=shift_used,
        Ts=float(Ts),
        vel_threshold=thr,
        lowpass_hz=lowpass_hz,
        command=pp.shift_command(x_r, shift_used, segment),
        segment=np.asarray(segment).copy(),
        shift_costs=costs,
    )

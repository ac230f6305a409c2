"""Free-run simulation of the closed-loop drive model of eq. 3.3 from the commanded trajectory.

Eq. 3.3 in the time domain, with the integral state ``z = ∫(x_r − x) dt``::

    ẍ = b0·ẍ_r + b1·ẋ_r + b2·x_r  − a1·ẋ − a2·x + a3·z − f,      ż = x_r − x
    f = d0 if ẋ > 0,  d1 if ẋ < 0,  stick (see below) if ẋ = 0            (eq. 3.2)

State ``s = [z, x, ẋ]`` (mm·s, mm, mm/s), inputs ``w = [x_r, u, f]`` with the command
drive ``u = b0·ẍ_r + b1·ẋ_r + b2·x_r`` (mm/s²).  ``ẋ_r`` and ``ẍ_r`` are the central
differences of eq. 3.9 (one-sided at segment ends), the same signals the regression of
eq. 3.11 uses, so the simulated model is the identified one.

**Integration**: the one simulator kernel of the identified model
(:func:`ident.kernel._kernel_many`, with no effect and the continuous
controller): exact discretisation of the linear part for inputs that are linear between
samples (first-order hold of x_r and u) and friction held over a sub-step — the blocks of
the matrix exponential of ``[[A, B, 0], [0, 0, I], [0, 0, 0]]·h``
(:mod:`ident.discretisation`) give ``s(t+h) = Φ·s + Γ0·w + Γ1·ẇ``, exact for any pole
location (no stiffness limit).  Each sample period is split into ``substeps`` sub-steps so
that friction switches within a period are resolved to Ts/substeps.

**Friction** (Karnopp stick rule, no chattering): while moving the friction is d0 (ẋ>0)
or d1 (ẋ<0).  When ẋ crosses zero inside a sub-step the crossing instant is interpolated;
if the net drive ``F = u − a2·x + a3·z`` (the acceleration at ẋ = 0 without friction)
still exceeds the friction of the new direction the axis reverses (the state is corrected
for the friction change over the rest of the sub-step), otherwise it sticks.  While stuck,
ẋ = 0 and x is constant — the friction supplies exactly F, which is possible while
d1 ≤ F ≤ d0 — and the axis breaks away when F leaves that band, at the instant
interpolated inside the sub-step (so x̂ depends continuously on the parameters, which the
output-error refinement's finite differences need).  For d0 = d1 = 0 this
reduces to the linear model exactly.

**Segments**: the state restarts at each segment start (no integration across a seam):
z = 0 (consistent with the regression's e_i, see :mod:`ident.preprocessing`), x from
``x0`` (the recorded actual position) or the command, ẋ = ẋ_r (the kernel's
``start_rule`` 1; the diagnosis starts at rest with the integral at equilibrium).
``at_rest`` starts a prediction from rest instead: ẋ = 0 and z at its equilibrium
z = (a2·x − b2·x_r)/a3.  z = 0 is rest only at the origin when b2 ≠ a2 (an equivalent
model, e.g. of a P-PI cascade); elsewhere it is a force the model does not hold, and
the axis drifts (0.5 mm from 7 mm on an identified fadal-ppi, tests/test_axis_model.py) and
recovers at its slowest pole.

A 25 000-sample run takes a few ms after the first (numba-compiled, cached) call; see
``benchmarks/bench_model_simulation.py``.
"""

from __future__ import annotations

import numpy as np

from ident.discretisation import foh_blocks
from ident.kernel import EFFECTS, N_EP, N_MODES, _many
from ident.model import base_vector
from ident.preprocessing import segment_slices

__all__ = ["simulate", "FreeRun", "command_drive", "discretise", "DEFAULT_SUBSTEPS"]

#: Sub-steps per sample period for the friction switching (exact linear part regardless).
DEFAULT_SUBSTEPS = 8


def _params(model) -> tuple[float, ...]:
    """The eight parameters of eq. 3.3 (:data:`ident.model.BASE_KEYS`) from a DriveModel-like object."""
    return tuple(base_vector(model))


def _gradient(x: np.ndarray, Ts: float) -> np.ndarray:
    """Central differences inside, one-sided at the ends (eq. 3.9); zeros for < 2 samples."""
    if x.size < 2:
        return np.zeros_like(x)
    return np.gradient(x, Ts)


def command_drive(model, x_r: np.ndarray, Ts: float, segment: np.ndarray | None = None) -> np.ndarray:
    """The command drive ``u = b0·ẍ_r + b1·ẋ_r + b2·x_r`` (mm/s²) per segment.

    Parameters
    ----------
    model : DriveModel-like (a1 … d1 of eq. 3.3)
    x_r : ndarray (N,)
        Commanded position, mm.
    Ts : float
        Sample period, s.
    segment : ndarray of int (N,), optional
        Segment ids; derivatives are taken within each segment only.
    """
    _, _, _, b0, b1, b2, _, _ = _params(model)
    fr = FreeRun(x_r, Ts, segment=segment)
    return b0 * fr.xr_ddot + b1 * fr.xr_dot + b2 * fr.x_r


def discretise(model, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact first-order-hold discretisation of eq. 3.3's linear part over a step ``h`` (s).

    Returns ``Φ`` (3×3), ``Γ0`` (3×3), ``Γ1`` (3×3) such that for inputs
    ``w(t+τ) = w + τ·ẇ`` (``w = [x_r, u, f]``) the state ``[z, x, ẋ]`` advances as
    ``s(t+h) = Φ s(t) + Γ0 w + Γ1 ẇ``: the blocks of ``exp([[A, B, 0], [0, 0, I], [0, 0, 0]]·h)``.
    """
    a1, a2, a3, *_ = _params(model)
    Phi, G0, G1 = foh_blocks(float(a1), float(a2), float(a3), float(h))
    # f enters as −u does (ẍ = … + u − f)
    return Phi, np.column_stack([G0, -G0[:, 1]]), np.column_stack([G1, -G1[:, 1]])


class FreeRun:
    """The free-run simulation of one commanded trajectory, for many models.

    Everything that depends only on the command — segment bounds, start states, the
    central-difference ẋ_r and ẍ_r — is computed once; calling the object with a model
    only forms ``u = b0·ẍ_r + b1·ẋ_r + b2·x_r``, discretises and runs the recursion.
    The output-error refinement calls it hundreds of times.  Parameters as
    :func:`simulate`.
    """

    def __init__(
        self,
        x_r: np.ndarray,
        Ts: float,
        *,
        segment: np.ndarray | None = None,
        x0: float | np.ndarray | None = None,
        substeps: int = DEFAULT_SUBSTEPS,
        at_rest: bool = False,
    ) -> None:
        x_r = np.ascontiguousarray(x_r, dtype=float)
        if x_r.ndim != 1:
            raise ValueError(f"x_r must be 1-D (N,), got shape {x_r.shape}")
        if not (np.isfinite(Ts) and Ts > 0):
            raise ValueError(f"Ts must be a positive sample period in s, got {Ts!r}")
        n = x_r.size
        slices = segment_slices(segment, n)
        starts = np.array([s.start for s in slices], dtype=np.int64)
        stops = np.array([s.stop for s in slices], dtype=np.int64)
        if x0 is None:
            x_init = x_r[starts].copy()
        elif np.ndim(x0) == 0:
            if len(slices) != 1:
                raise ValueError("a scalar x0 is ambiguous with several segments; pass the recorded positions (N,)")
            x_init = np.array([float(x0)])
        else:
            x0 = np.asarray(x0, dtype=float)
            if x0.shape != (n,):
                raise ValueError(f"x0 has shape {x0.shape}, expected () or ({n},)")
            x_init = x0[starts].copy()
        xr_dot = np.empty_like(x_r)
        xr_ddot = np.empty_like(x_r)
        for sl in slices:
            xr_dot[sl] = _gradient(x_r[sl], Ts)
            xr_ddot[sl] = _gradient(xr_dot[sl], Ts)
        self.x_r, self.Ts, self.n = x_r, float(Ts), n
        self.starts, self.stops, self.x_init = starts, stops, x_init
        self.v_init = xr_dot[starts].copy()
        self.seg_starts = np.zeros(n, dtype=np.bool_)
        self.seg_starts[starts] = True
        self.x_start = np.zeros(n)
        self.x_start[starts] = x_init
        self.xr_dot, self.xr_ddot = xr_dot, xr_ddot
        self.substeps = max(int(substeps), 1)
        self.start_rule = 0 if at_rest else 1

    def __call__(self, model, disturbance: np.ndarray | None = None) -> np.ndarray:
        """Simulated actual position x̂ (N,), mm, of ``model`` (DriveModel-like).

        ``disturbance`` (N,), mm/s², is an extra acceleration entering where ``u`` does
        (a load; see :mod:`ident.diagnosis.disturbance`), held linear between samples.
        """
        if self.n == 0:
            return np.empty(0)
        # The one simulator kernel with no effect, the continuous controller and the
        # identification's start rule.
        theta = np.array(_params(model), dtype=float)
        return _many(self.x_r, self.x_start, self.Ts, theta, np.zeros(N_EP), float,
                     np.zeros(len(EFFECTS), dtype=np.int64), np.zeros(N_MODES, dtype=np.int64), self.seg_starts,
                     (self.xr_dot, self.xr_ddot), self.substeps, None, load=disturbance,
                     start_rule=self.start_rule)[0]


def simulate(
    model,
    x_r: np.ndarray,
    Ts: float,
    *,
    segment: np.ndarray | None = None,
    x0: float | np.ndarray | None = None,
    substeps: int = DEFAULT_SUBSTEPS,
    disturbance: np.ndarray | None = None,
    at_rest: bool = False,
) -> np.ndarray:
    """Free-run response x̂ (mm) of eq. 3.3 to the commanded trajectory alone.

    Parameters
    ----------
    model : DriveModel-like
        Anything with float attributes a1 (1/s), a2 (1/s²), a3 (1/s³), b0 (–), b1 (1/s),
        b2 (1/s²), d0, d1 (mm/s²).
    x_r : ndarray (N,)
        Commanded position, mm — already shifted if the identification used a preview
        shift (:func:`ident.preprocessing.shift_command`).
    Ts : float
        Sample period, s.
    segment : ndarray of int (N,), optional
        Segment ids; the state restarts at each segment start.
    x0 : float, ndarray (N,) or None
        Start position, mm: ``None`` → the command at each segment start; an array (N,)
        (the recorded actual position) → its value at each segment start; a float → the
        start of a single-segment recording.
    substeps : int
        Sub-steps per sample for resolving friction switching (the linear part is exact).
    disturbance : ndarray (N,), optional
        Extra acceleration input, mm/s² (an external load), added to the command drive.
    at_rest : bool
        False: each segment starts as the identification fits (z = 0, ẋ = ẋ_r); True: at
        rest, the integral at its equilibrium (a prediction from a standing machine, the
        same wherever it stands; module docstring).

    Returns
    -------
    ndarray (N,)
        Simulated actual position at the sample instants, mm.
    """
    return FreeRun(x_r, Ts, segment=segment, x0=x0, substeps=substeps, at_rest=at_rest)(model, disturbance)

"""Free-run simulation of the identified closed-loop drive model of eq. 3.3 from the commanded trajectory.

Eq. 3.3 in the time domain, with the integral state ``z = ∫(x_r − x) dt``::

    ẍ = b0·ẍ_r + b1·ẋ_r + b2·x_r  − a1·ẋ − a2·x + a3·z − f,      ż = x_r − x
    f = d0 if ẋ > 0,  d1 if ẋ < 0,  Karnopp stick band [d1, d0] if ẋ = 0       (eq. 3.2)

``ẋ_r`` and ``ẍ_r`` are the central differences of eq. 3.9 (one-sided at segment ends,
:func:`ident.diagnosis.augmented.command_derivatives`), the same signals the regression of
eq. 3.11 uses, so the simulated model is the identified one.

**One kernel.**  This module is the identification's view of the one simulator of the
identified model, :func:`ident.diagnosis.augmented.simulate_augmented` with no effect and
the continuous control law: the output-error refinement (:mod:`ident.refine`), the
intervals (:mod:`ident.uncertainty`), plain predictions (:class:`ident.axis_model.AxisModel`)
and the diagnosis's external-force check all run that kernel through :class:`FreeRun`.
Two things are the identification's own, and are given to the kernel as its inputs:

* the feed-forward ``b0·ẍ_r + b1·ẋ_r`` (plus an optional ``disturbance``) enters as one
  signal interpolated linearly between samples (the kernel's commanded-velocity input with
  b0 = 0, b1 = 1), where the diagnosis's own base holds ẍ_r over a sample;
* each segment starts at the recorded (or commanded) position with ``z = 0`` and ẋ = ẋ_r
  (consistent with the regression's e_i, see :mod:`ident.preprocessing`), written as the
  kernel's warm start — the diagnosis starts at rest with the integral at equilibrium.

**Integration**: the kernel's semi-implicit Euler with Karnopp friction (an axis at rest
sticks while the net drive lies within [d1, d0]; a velocity reaching zero inside a sub-step
restarts from rest for the rest of it, so x̂ depends continuously on the parameters), run
twice, on n and 2n sub-steps per sample, and extrapolated (Richardson): the scheme's error
is c·h + O(h²), so ``2·x̂(2n) − x̂(n)`` is second order.  n is ``substeps``, raised so the
fastest pole turns at most 1.5 rad a sub-step (the scheme's stability; :data:`_STEP_RAD`).
Its accuracy and run time are printed by ``benchmarks/bench_model_simulation.py``: the
friction-free model against ``scipy.signal.lsim`` of G_track, and with friction against
64 sub-steps, as a fraction of the tracking error's spread; a 25 000-sample run costs 3n
sub-steps of the kernel after the first (numba-compiled, cached) call.
"""

from __future__ import annotations

import numpy as np

from ident.model import base_vector
from ident.preprocessing import segment_slices

__all__ = ["simulate", "FreeRun", "command_drive", "DEFAULT_SUBSTEPS"]

#: Sub-steps per sample (fewer are raised to the model's own need).
DEFAULT_SUBSTEPS = 4
#: Largest turn of the fastest pole per sub-step, rad (stability: < 2).
_STEP_RAD = 1.5


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
    _, _, _, b0, b1, b2, _, _ = base_vector(model)
    fr = FreeRun(x_r, Ts, segment=segment)
    return b0 * fr.xr_ddot + b1 * fr.xr_dot + b2 * fr.x_r


def _least_substeps(theta: np.ndarray, Ts: float) -> int:
    """Fewest sub-steps per sample for which the kernel's semi-implicit Euler is stable on ``theta``.

    The scheme is stable while h·|λ| < 2 for the fastest closed-loop pole λ and h·a1 < 2 for
    the damping it takes explicitly; :data:`_STEP_RAD` keeps a margin.  Accuracy is the
    extrapolation's (:meth:`FreeRun.__call__`), not this bound's.
    """
    lam = max(float(np.max(np.abs(np.roots([1.0, theta[0], theta[1], theta[2]])))), abs(float(theta[0])))
    return max(int(np.ceil(Ts * lam / _STEP_RAD)), 1)


class FreeRun:
    """The free-run simulation of one commanded trajectory, for many models.

    Everything that depends only on the command — segment starts, start positions, the
    central-difference ẋ_r and ẍ_r — is computed once; calling the object with a model
    forms the feed-forward and the start states and runs the kernel.  The output-error
    refinement calls it hundreds of times.  Parameters as :func:`simulate`.
    """

    def __init__(
        self,
        x_r: np.ndarray,
        Ts: float,
        *,
        segment: np.ndarray | None = None,
        x0: float | np.ndarray | None = None,
        substeps: int = DEFAULT_SUBSTEPS,
    ) -> None:
        from ident.diagnosis.augmented import command_derivatives, segment_starts

        x_r = np.ascontiguousarray(x_r, dtype=float)
        if x_r.ndim != 1:
            raise ValueError(f"x_r must be 1-D (N,), got shape {x_r.shape}")
        if not (np.isfinite(Ts) and Ts > 0):
            raise ValueError(f"Ts must be a positive sample period in s, got {Ts!r}")
        n = x_r.size
        if x0 is None:
            x_start = x_r.copy()
        elif np.ndim(x0) == 0:
            if len(segment_slices(segment, n)) != 1:
                raise ValueError("a scalar x0 is ambiguous with several segments; pass the recorded positions (N,)")
            x_start = np.full(n, float(x0))
        else:
            x_start = np.ascontiguousarray(x0, dtype=float)
            if x_start.shape != (n,):
                raise ValueError(f"x0 has shape {x_start.shape}, expected () or ({n},)")
        self.x_r, self.Ts, self.n = x_r, float(Ts), n
        self.starts = segment_starts(n, segment)
        self.x_start = x_start
        self.xr_dot, self.xr_ddot = command_derivatives(x_r, self.Ts, self.starts)
        self.substeps = max(int(substeps), 1)

    def __call__(self, model, disturbance: np.ndarray | None = None) -> np.ndarray:
        """Simulated actual position x̂ (N,), mm, of ``model`` (DriveModel-like).

        ``disturbance`` (N,), mm/s², is an extra acceleration entering where ``u`` does
        (a load; see :mod:`ident.diagnosis.disturbance`), held linear between samples.
        """
        theta = base_vector(model)
        if self.n == 0:
            return np.empty(0)
        n = max(self.substeps, _least_substeps(theta, self.Ts)) if np.all(np.isfinite(theta)) else self.substeps
        feed = theta[3] * self.xr_ddot + theta[4] * self.xr_dot
        if disturbance is not None:
            feed = feed + np.asarray(disturbance, dtype=float)
        # Richardson extrapolation of the first-order scheme: its error is c·h + O(h²), so
        # 2·x̂(h/2) − x̂(h) is second order.
        return 2.0 * self._run(theta, feed, 2 * n) - self._run(theta, feed, n)

    def _run(self, theta: np.ndarray, feed: np.ndarray, nsub: int) -> np.ndarray:
        """One free run of the kernel on ``nsub`` sub-steps, feed-forward ``feed`` (mm/s²)."""
        from ident.diagnosis.augmented import simulate_augmented

        a1, a2, _, _, _, b2, d0, d1 = theta
        # The start state z = 0, ẋ = ẋ_r as the kernel's warm start: the acceleration at the
        # start whose force balance leaves its integral at zero (its velocity lives half a
        # sub-step back, ẋ_r − a·h/2, and its damping term reads that one).
        v = self.xr_dot
        friction = np.where(v > 0.0, d0, np.where(v < 0.0, d1, 0.0))
        h = self.Ts / nsub
        with np.errstate(all="ignore"):
            a = (feed + b2 * self.x_r - a2 * self.x_start - a1 * v - friction) / (1.0 - 0.5 * h * a1)
        kernel_theta = theta.copy()
        kernel_theta[3:5] = 0.0, 1.0  # u's feed-forward is `feed`, given as the velocity input
        return simulate_augmented(self.x_r, self.x_start, self.Ts, kernel_theta, starts=self.starts,
                                  derivs=(feed, np.zeros(self.n)), nsub=nsub, warm=(self.starts, v, a))


def simulate(
    model,
    x_r: np.ndarray,
    Ts: float,
    *,
    segment: np.ndarray | None = None,
    x0: float | np.ndarray | None = None,
    substeps: int = DEFAULT_SUBSTEPS,
    disturbance: np.ndarray | None = None,
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
        Sub-steps per sample (raised to the model's need, see the module docstring).
    disturbance : ndarray (N,), optional
        Extra acceleration input, mm/s² (an external load), added to the command drive.

    Returns
    -------
    ndarray (N,)
        Simulated actual position at the sample instants, mm.
    """
    return FreeRun(x_r, Ts, segment=segment, x0=x0, substeps=substeps)(model, disturbance)

"""The augmented drive model: thesis eq. 3.3 plus the physics of SPEC §7, simulated in free run.

The base model (eq. 3.3) written as the closed loop it stands for::

    e_i' = x_r − x_fb                                      (integrated tracking error)
    u    = b0·ẍ_r + b1·ẋ_r + b2·x_r + a3·e_i − a2·x_fb − a1·ẋ   (control-equivalent acceleration, mm/s²)
    ẍ    = u − d(ẋ),   d = d0·PV(ẋ) + d1·NV(ẋ)              (eq. 3.2, Coulomb friction, mm/s²)

Coulomb friction is simulated with a stick phase (Karnopp): an axis at rest stays at rest
while ``d1·r ≤ u ≤ d0·r`` (r = 1 for the base model).  Each effect adds its own
parameters (index into the effect-parameter vector ``ep`` in brackets):

==============  =========================================================================
backlash        dead band of width ``gap_mm`` [0] between motor (x) and table.  Mode 0
                (semi-closed loop): the loop and the friction act on the motor, the table
                position is recorded.  Mode 1 (full-closed loop, as most CNC axes): two
                masses, motor (share ``motor_fraction`` [11] of the inertia, read by the
                velocity term) and table (carries the friction, read by the position loop
                and recorded), coupled by a stiff contact across the gap
                (:data:`CONTACT_HZ`, :data:`CONTACT_DAMPING`).  The position
                term reads ``(1 − ψ)·x_table + ψ·x_motor``, ψ = position_motor_share [12]
                (0: PID on the scale; ≈ 0.8: P-PI cascade, whose velocity integral is the
                motor position); the integral term always reads the table.  Mode 2
                (semi-closed loop with the table's inertia): the two masses of mode 1,
                every loop term reading the motor, the table recorded — the table crosses
                the gap when the force it needs changes sign (it coasts ahead into the gap
                when the motor brakes harder than its friction can), not at the motor's
                reversal as the massless table of mode 0 does
stribeck        breakaway friction ``r·d`` at rest falling to Coulomb ``d`` with speed,
                ``d(v) = d·(1 + (r − 1)·exp(−(v/v_s)²))``; r = static_to_coulomb_ratio [1],
                v_s = stribeck_velocity_mm_s [2]
resonance       a lightly damped pole pair, freq_hz [3], damping ζ [4]: mode 0 a filter on the
                recorded position ``q̈ + 2ζω q̇ + ω² q = −κ·ẍ``, recorded x + q, gain κ [5];
                mode 1 the two-mass drive above with a spring-damper of that free-free mode;
                mode 2 the same drive semi-closed: every loop term reads the motor, the
                table is recorded (a table scale read beside a motor-encoder loop);
                mode 3 semi-closed with the motor recorded (a controller's scope of a
                motor-encoder loop): the mode shows only through the table's reaction
time_delay      dead time ``delay_s`` [6] on the recorded position (mode 0: capture/transport)
                or on the control-equivalent acceleration inside the loop (mode 1)
cyclic_error    ``c_s·sin(2πx/P) + c_c·cos(2πx/P)``, period_mm P [7], c_s [8], c_c [9]; an error
                of the recorded position in mm (mode 0) or a disturbance in mm/s² (mode 1)
saturation      ``u`` clipped to ``±limit − c·ẋ`` mm/s², limit [10], c = limit_slope [13]
                (1/s): the drive clips its own output, ``u + c·ẋ``, which carries the
                plant's viscous share of the speed term eq. 3.3 folds into a1.  Mode 0:
                integral frozen while it would wind up (conditional integration: over a
                step it takes the share of its increment that puts the output on the
                limit, so the run is continuous in the parameters); with
                ψ [12] > 0 the position term's motor share is the integral of the motor
                velocity and freezes with it (P-PI: the velocity integral stops).  Mode 1:
                no anti-windup — the integral runs on while the output is clipped, as in
                many drives' PI velocity loops, and overshoots once the limit lets go
==============  =========================================================================

Sampled controller (``modes[4] = 1`` or ``2``): ``u`` is computed once per sample from the
positions read at t_k — velocity by backward difference of the motor position, integral as a
rectangular sum including the current error — and held over the sample (ZOH), like the
virtual CNC's digital loop; the plant is still integrated on sub-steps.  The feed-forward
terms read the command's derivatives at t_k: with ``modes[4] = 1`` as given ahead by an
interpolator (central differences, :func:`command_derivatives`); with ``modes[4] = 2`` as a
drive that only sees the commands received so far takes them (causal backward differences,
``ẋ_r,k = (x_r,k − x_r,k−1)/Ts``, ``ẍ_r,k = (ẋ_r,k − ẋ_r,k−1)/Ts``, zero at a segment's first
sample), half a sample late in velocity and a whole sample in acceleration — the HAL ``pid``
component's and most servo amplifiers' feed-forward.  Otherwise the loop is continuous (eq.
3.3 as written).

Integration: ``nsub`` sub-steps per sample, ``nsub`` chosen so that the fastest pole moves at
most 0.15 rad per sub-step (see :func:`substeps`).  A single mass on the continuous
controller (no two-mass variant) is stepped exactly: the linear part of eq. 3.3, state
[e_i, x, ẋ], by the first-order-hold blocks of :func:`ident.discretisation.foh_blocks` —
the commanded position and the command drive ``b0·ẍ_r + b1·ẋ_r + b2·x_r`` linear between
samples, as :mod:`ident.simulation` takes them — with friction (Coulomb, Stribeck at the
current speed; Karnopp, the reversal and breakaway instants interpolated inside the
sub-step) and every effect acting on the mass held over the sub-step as an input: the
saturation clip, the in-loop delay and the cyclic force as the applied u less the linear
law's, the ψ-share ``−a2·ψ·(x_w − x)``, the anti-windup freeze as an input on ė_i cancelling
``x_r − x`` (exact for the linear part, first order in the nonlinearity: an exponential-Euler
step).  The output-side effects (capture delay, cyclic position error, the semi-closed
gap of backlash mode 0, the filter of resonance mode 0 driven by the sub-step's mean
acceleration, held, and advanced by its flow — exact for that input) act on that run.
This is the simulator of the identified model too (:class:`ident.simulation.FreeRun`: no
effect, ``start_rule`` 1).  A two-mass mode (resonance modes 1–3, no gap) under the
sampled controller is stepped exactly too: the controller's output is held over the
sample, so between samples the drive is linear but for the table's friction — the centre
of mass a double integrator under u less friction, the deflection the free-free mode, each
advanced by its flow, the motor on the spring to a table that friction holds by the
locked-table flow — with the table's reversal and breakaway instants located inside the
sub-step (:func:`ident.kernel._two_mass_step`); its frequency then sets no sub-step.  The
other two-mass drives (a mode under the continuous controller, the backlash variants on
either) take kick-and-drift (leapfrog) sub-steps with every force read at the kick's
instant — the velocities a half step on from the last kick's, a gap's contact as its mean
push over the kick's span centred there, on the continuous controller the command's
position, velocity and acceleration linear between samples (as on the exact step) and the
integral by the midpoint of the feedback's move, a half kick after every restart — second
order in the sub-step.  The sampled controller's single mass takes the same kicks and
drifts with the output held (exact for a force held over the sub-step on a double
integrator).
Velocities live at half sub-steps in this scheme, so on the sampled controller the first
sub-step of a sample, which straddles the switch of the held ``u``, gets the mean of the
old and new value: without it the model leads the digital loop by half a sub-step (0.25 ms
at nsub = 2 on a PID drive), and a fitted dead time would take that up.
Every contiguous segment restarts at rest at the recorded actual position, or, at a warm
start (a window cut out of a longer recording, ``warm``), on the recorded state mid-move.

One compiled kernel (:func:`ident.kernel._kernel_many`) simulates one parameter set
(:func:`simulate_augmented`) or several in lockstep (:func:`simulate_augmented_many`, the
columns of a difference Jacobian): each set's free run is the same bit for bit either way,
and several at once run about twice the simulations per second.  The kernel is generic in
its number type: in complex128 it gives the exact parameter sensitivities by the complex
step (:func:`sensitivities`); every branch is decided on the real part, so the float64 run
is the one it always was and the derivative is that of the branch the real run takes.
"""

from __future__ import annotations

import math

import numpy as np

from ident.axis_model import CONTROLLERS  # noqa: F401  (re-exported)
from ident.kernel import (  # noqa: F401  (re-exported: the kernel's layout is this module's vocabulary)
    _FL_BACKLASH, _FL_RESONANCE, _FREQ, _MD_BACKLASH, _MD_RESONANCE, CONTACT_DAMPING, CONTACT_HZ, EFFECTS,
    EP_INDEX, MODE_SLOTS, N_EP, N_MODES, _exact_steps, _many, _padded_modes, _runnable)

__all__ = [
    "restart_sensitivities",
    "EFFECTS",
    "EP_INDEX",
    "N_EP",
    "MODE_SLOTS",
    "N_MODES",
    "CONTROLLERS",
    "command_derivatives",
    "segment_starts",
    "substeps",
    "model_substeps",
    "simulate_augmented",
    "simulate_augmented_many",
    "sensitivities",
    "COMPLEX_STEP",
]
# CONTROLLERS (re-exported): the control law's variants by their value in the controller slot
# (``modes[4]``).

#: Largest turn of the contact per sub-step, rad.  The contact's frequency is a stand-in
#: for "stiff", not a fitted value, so it needs less than the 0.15 rad a fitted mode gets;
#: but a full-closed loop hunting across the gap bounces off it, and the hunt's size is
#: what the gap is fitted to.  At 0.4 rad (7 sub-steps a sample at 1 kHz) the kernel's
#: kick-and-drift step, the contact's push averaged over the kick's span
#: (:func:`ident.kernel._contact_push`), gives a full-closed gap's run within 3–5 % of what
#: the gap changes of the run at 32 times the sub-steps (tests/test_kernel_contact_events.py).
CONTACT_STEP_RAD = 0.4


def segment_starts(n: int, segment: np.ndarray | None) -> np.ndarray:
    """Boolean (n,) mask, True at the first sample of every contiguous segment."""
    starts = np.zeros(n, dtype=np.bool_)
    if n:
        starts[0] = True
    if segment is not None and n > 1:
        seg = np.asarray(segment)
        starts[1:] |= seg[1:] != seg[:-1]
    return starts


def command_derivatives(x_r: np.ndarray, Ts: float, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Commanded velocity (mm/s) and acceleration (mm/s²) by central differences inside segments.

    As in thesis §3.2: ``ẋ_k = (x_{k+1} − x_{k−1})/(2 Ts)``; one-sided at segment ends so
    nothing is differentiated across a change of segment.
    """
    v = np.empty_like(x_r)
    a = np.empty_like(x_r)
    bounds = np.append(np.flatnonzero(starts), x_r.size)
    for s, e in zip(bounds[:-1], bounds[1:]):
        seg = x_r[s:e]
        if seg.size < 3:
            v[s:e] = 0.0
            a[s:e] = 0.0
            continue
        vs = np.gradient(seg, Ts)
        v[s:e] = vs
        a[s:e] = np.gradient(vs, Ts)
    return v, a


def substeps(theta: np.ndarray, Ts: float, freq_hz: float = 0.0) -> int:
    """Sub-steps per sample so the fastest pole (and resonance) turns ≤ 0.15 rad per sub-step."""
    a1, a2, a3 = float(theta[0]), float(theta[1]), float(theta[2])
    try:
        lam = float(np.max(np.abs(np.roots([1.0, a1, a2, a3]))))
    except (np.linalg.LinAlgError, ValueError):
        lam = abs(a1) + math.sqrt(abs(a2))
    if not np.isfinite(lam):
        lam = 1e4
    lam = max(lam, 2.0 * math.pi * freq_hz, abs(a1))
    return int(min(max(math.ceil(Ts * lam / 0.15), 1), 16))


def model_substeps(theta: np.ndarray, Ts: float, flags: np.ndarray, ep: np.ndarray, modes: np.ndarray) -> int:
    """Sub-steps per sample for the augmented model: :func:`substeps` with its fastest mode.

    A resonance's mode at 1.5 × its frequency (a damped mode's closed-loop poles sit above
    the free one) — but where the kernel steps the mode exactly
    (:func:`ident.kernel._exact_steps`): a two-mass mode under the sampled controller and
    the filter of mode 0 on the continuous controller's exact step.  The stiff contact of a
    two-mass backlash variant (:data:`CONTACT_HZ`) needs stability only, not phase accuracy:
    its frequency is a stand-in for "stiff", not a fitted value, so its sub-step turns at
    most :data:`CONTACT_STEP_RAD`.
    """
    two_mode = flags[_FL_RESONANCE] and modes[_MD_RESONANCE] >= 1
    gap_two = flags[_FL_BACKLASH] and modes[_MD_BACKLASH] >= 1
    exact, two_exact = _exact_steps(np.asarray(flags, dtype=np.int64), _padded_modes(modes))
    f = ep[_FREQ] if flags[_FL_RESONANCE] and not (two_exact or exact) else 0.0
    n = substeps(theta, Ts, 1.5 * f)
    if gap_two and not two_mode:
        n = max(n, math.ceil(Ts * 2.0 * math.pi * CONTACT_HZ / CONTACT_STEP_RAD))
    return n


def simulate_augmented(
    x_r: np.ndarray,
    x0: np.ndarray,
    Ts: float,
    theta: np.ndarray,
    *,
    flags: np.ndarray | None = None,
    ep: np.ndarray | None = None,
    modes: np.ndarray | None = None,
    starts: np.ndarray | None = None,
    derivs: tuple[np.ndarray, np.ndarray] | None = None,
    nsub: int | None = None,
    u_out: np.ndarray | None = None,
    warm: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Free-run recorded position x̂ (mm) of the augmented model for the command ``x_r`` (mm).

    Parameters
    ----------
    x_r : ndarray (N,)
        Commanded position, mm.
    x0 : ndarray (N,)
        Recorded actual position, mm; only read at segment starts (initial state).
    Ts : float
        Sample period, s.
    theta : ndarray (8,)
        Base parameters a1 (1/s), a2 (1/s²), a3 (1/s³), b0 (–), b1 (1/s), b2 (1/s²),
        d0, d1 (mm/s²) of eq. 3.3.
    flags : ndarray of int (6,)
        1 for each effect of :data:`EFFECTS` that is switched on.
    ep : ndarray (N_EP,)
        Effect parameters laid out as :data:`EP_INDEX`.
    modes : ndarray of int (6,)
        Variant of backlash (0 semi-closed loop, 1 two-mass full-closed loop, 2 two-mass
        semi-closed loop), time delay
        (0 capture, 1 actuation), cyclic error (0 position error, 1 disturbance),
        resonance (0 filter on the recorded position, 1 two-mass mode inside the loop, 2 the
        same semi-closed with the table recorded, 3 semi-closed with the motor recorded),
        controller (0 continuous, 1 sampled with zero-order hold, 2 the same with causal
        feed-forward differences) and saturation (0
        anti-windup, 1 none), slots :data:`MODE_SLOTS`; shorter arrays are padded with zeros.
    starts : ndarray of bool (N,)
        First sample of each segment (see :func:`segment_starts`); default one segment.
    derivs : (ẋ_r, ẍ_r), optional
        Precomputed :func:`command_derivatives`, mm/s and mm/s².
    nsub : int, optional
        Sub-steps per sample; default from :func:`substeps`.
    u_out : ndarray (N,), optional
        Filled with the control-equivalent acceleration u (mm/s²) applied at each sample
        (NaN if the parameters are no model to simulate).
    warm : (mask, v, a), optional
        Segment starts that restart mid-move (``mask``, bool (N,): a window cut out of a
        longer recording, :meth:`~ident.diagnosis.spec.Chunk.windows`) and the recorded
        velocity and acceleration there (mm/s, mm/s², read at those starts only): the model
        starts at the recorded position and velocity, a gap's far side leading the way the
        command moves, the integral holding the force of the recorded acceleration against
        friction — the base model's state exactly.  A velocity of exactly 0 restarts at
        rest: the acceleration given is then the force friction holds there (mm/s², the
        integral holding it; :meth:`~ident.diagnosis.spec.Chunk.rests`).  Default none:
        every segment starts at rest with the integral at equilibrium.
    """
    x_r = np.ascontiguousarray(x_r, dtype=float)
    n = x_r.size
    if starts is None:
        starts = segment_starts(n, None)
    if derivs is None:
        derivs = command_derivatives(x_r, Ts, starts)
    th = np.ascontiguousarray(theta, dtype=float)
    fl = np.zeros(len(EFFECTS), dtype=np.int64) if flags is None else np.ascontiguousarray(flags, dtype=np.int64)
    e = np.zeros(N_EP) if ep is None else np.ascontiguousarray(ep, dtype=float)
    md = np.zeros(N_MODES, dtype=np.int64) if modes is None else _padded_modes(modes)
    if not _runnable(th.reshape(1, 8), e.reshape(1, N_EP))[0]:
        if u_out is not None:  # no force applied either, whatever the buffer held
            u_out[:] = np.nan
        return np.full(n, np.nan)  # no model to simulate (a diverged fit step)
    if nsub is None:
        nsub = model_substeps(th, Ts, fl, e, md)
    return _many(x_r, x0, Ts, th, e, float, fl, md, starts, derivs, nsub, warm, u_out)[0]


def simulate_augmented_many(
    x_r: np.ndarray,
    x0: np.ndarray,
    Ts: float,
    thetas: np.ndarray,
    eps: np.ndarray,
    *,
    flags: np.ndarray,
    modes: np.ndarray,
    starts: np.ndarray,
    derivs: tuple[np.ndarray, np.ndarray],
    nsub: int,
    warm: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """:func:`simulate_augmented` of several parameter sets at once, (P, N): row p is bit for bit
    ``simulate_augmented(..., thetas[p], ep=eps[p], ...)`` with the given ``nsub``.

    For the columns of a finite-difference Jacobian: the same effects, variants and
    sub-steps, parameters differing (rows of ``thetas`` (P, 8) and ``eps`` (P, N_EP)).  The
    sets are simulated in lockstep in one pass (:func:`ident.kernel._kernel_many`), which is faster than
    one after the other: a single free run waits on its own chain of dependent operations.
    """
    return _many(x_r, x0, Ts, thetas, eps, float, flags, modes, starts, derivs, nsub, warm)


#: Imaginary step of the complex-step derivative: the real part's rounding never sees it, and
#: no difference is taken, so there is no step to choose (Squire & Trapp 1998).
COMPLEX_STEP = 1e-30


def sensitivities(
    x_r: np.ndarray,
    x0: np.ndarray,
    Ts: float,
    theta: np.ndarray,
    ep: np.ndarray,
    d_theta: np.ndarray,
    d_ep: np.ndarray,
    *,
    flags: np.ndarray,
    modes: np.ndarray,
    starts: np.ndarray,
    derivs: tuple[np.ndarray, np.ndarray],
    nsub: int,
    warm: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Exact directional derivatives of the free run, (P, N): row p is ∂x̂/∂s at s = 0 of
    :func:`simulate_augmented` at ``(theta + s·d_theta[p], ep + s·d_ep[p])``, mm per unit of s.

    The complex-step derivative (Squire & Trapp 1998; Martins, Sturdza & Alonso 2003): the
    kernel runs in complex128 with the parameters ``p + i·h·d`` (h = :data:`COMPLEX_STEP`),
    and ``Im x̂ / h`` is the derivative to the precision of the real part — no difference is
    taken, so no rounding cancels and no step size is chosen.  The directions run in lockstep
    like :func:`simulate_augmented_many`'s sets, and every branch of the kernel is decided on
    the real part, so the derivative is that of the branch the real run takes: at a Coulomb
    switch, a backlash contact or a saturation clip the discrete simulator is piecewise
    smooth, and this is its slope on the piece the estimate sits on (a difference across
    the switch would read the jump instead).
    """
    th = np.asarray(theta, dtype=float).reshape(1, 8)
    e = np.asarray(ep, dtype=float).reshape(1, N_EP)
    TH = th + 1j * COMPLEX_STEP * np.asarray(d_theta, dtype=float).reshape(-1, 8)
    E = e + 1j * COMPLEX_STEP * np.asarray(d_ep, dtype=float).reshape(-1, N_EP)
    return _many(x_r, x0, Ts, TH, E, complex, flags, modes, starts, derivs, nsub, warm).imag / COMPLEX_STEP


def restart_sensitivities(
    x_r: np.ndarray,
    x0: np.ndarray,
    Ts: float,
    theta: np.ndarray,
    ep: np.ndarray,
    *,
    flags: np.ndarray,
    modes: np.ndarray,
    starts: np.ndarray,
    derivs: tuple[np.ndarray, np.ndarray],
    nsub: int,
    warm: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> np.ndarray:
    """Exact derivatives of the free run to the state every warm restart reads, (3, N):
    ∂x̂/∂ of an offset added at every warm start (``warm[0]``) to the recorded position (mm),
    velocity (mm/s) and acceleration (mm/s²) the restart takes.

    The complex-step derivative as :func:`sensitivities`, the offset the imaginary part of
    the restart's state: the directions a multiple-shooting window's error takes when its
    restart misreads the state.
    """
    on, v, a = (np.asarray(w) for w in warm)
    th = np.asarray(theta, dtype=float).reshape(1, 8).astype(complex)
    e = np.asarray(ep, dtype=float).reshape(1, N_EP).astype(complex)
    step = 1j * COMPLEX_STEP * on
    runs = ((x0 + step, (on, v, a)), (x0, (on, v + step, a)), (x0, (on, v, a + step)))
    return np.stack([_many(x_r, x, Ts, th, e, complex, flags, modes, starts, derivs, nsub, w)[0].imag
                     for x, w in runs]) / COMPLEX_STEP

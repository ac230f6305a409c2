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
saturation      ``u`` clipped to ``±limit`` mm/s² [10].  Mode 0: integral frozen while it would
                wind up (conditional integration); with ψ [12] > 0 the position term's
                motor share is the integral of the motor velocity and freezes with it
                (P-PI: the velocity integral stops).  Mode 1: no anti-windup — the
                integral runs on while the output is clipped, as in many drives' PI
                velocity loops, and overshoots once the limit lets go
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

Integration: semi-implicit Euler on ``nsub`` sub-steps per sample, ``nsub`` chosen so that
the fastest pole moves at most 0.15 rad per sub-step (see :func:`substeps`); commanded
position and velocity are interpolated linearly inside a sample, acceleration is held.
Velocities live at half sub-steps in this scheme, so on the sampled controller the first
sub-step of a sample, which straddles the switch of the held ``u``, gets the mean of the
old and new value: without it the model leads the digital loop by half a sub-step (0.25 ms
at nsub = 2 on a PID drive), and a fitted dead time would take that up.
Every contiguous segment restarts at rest at the recorded actual position, or, at a warm
start (a window cut out of a longer recording, ``warm``), on the recorded state mid-move.

One compiled kernel (:func:`_kernel_many`) simulates one parameter set
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
from numba import njit

from ident.axis_model import CONTROLLERS, EFFECT_NAMES
from ident.complex_step import cos, div, exp, sin

__all__ = [
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

#: The effects of SPEC §7 in a fixed order; the flag vector follows it (the axis model's
#: vocabulary, one list for the model and its simulator).
EFFECTS: tuple[str, ...] = EFFECT_NAMES
#: Index of each effect parameter in the effect-parameter vector ``ep``.
EP_INDEX: dict[str, int] = {
    "gap_mm": 0,
    "static_to_coulomb_ratio": 1,
    "stribeck_velocity_mm_s": 2,
    "freq_hz": 3,
    "damping": 4,
    "gain": 5,
    "delay_s": 6,
    "period_mm": 7,
    "amplitude_sin": 8,
    "amplitude_cos": 9,
    "limit": 10,
    "motor_fraction": 11,
    "position_motor_share": 12,
}
N_EP = 13
#: Variant slots of the ``modes`` vector: backlash, time_delay, cyclic_error, resonance,
#: controller (0 continuous, 1 sampled, 2 sampled with causal feed-forward differences),
#: saturation (0 anti-windup, 1 none).
MODE_SLOTS: dict[str, int] = {"backlash": 0, "time_delay": 1, "cyclic_error": 2, "resonance": 3,
                              "controller": 4, "saturation": 5}
N_MODES = 6
# CONTROLLERS (imported above, re-exported): the control law's variants by their value in
# the controller slot (``modes[4]``).
#: Frequency and damping ratio of the motor–table contact of a backlash gap in the two-mass
#: variants, Hz and –.
CONTACT_HZ = 400.0
CONTACT_DAMPING = 0.5
#: Largest turn of the contact per sub-step, rad.  The contact's frequency is a stand-in
#: for "stiff", not a fitted value, so it needs less than the 0.15 rad a fitted mode gets;
#: but a full-closed loop hunting across the gap bounces off it, and the hunt's size is
#: what the gap is fitted to.  The kernel's semi-implicit Euler with the damping taken
#: explicitly is stable on a ζ = 0.5 oscillator up to ω·h ≈ 1.25; at 0.8 rad (4 sub-steps
#: at 1 kHz) the drivers/sim battery's fitted gaps were 13.5 % off (median) against 4.8 %
#: with 16 sub-steps, at 0.4 rad (7 sub-steps) 8.1 %, all nine within ±25 % as with 16.
CONTACT_STEP_RAD = 0.4

# The kernel's slots by name (numba reads module-level ints as compile-time constants).
_FL_BACKLASH, _FL_STRIBECK, _FL_RESONANCE, _FL_DELAY, _FL_CYCLIC, _FL_SATURATION = (
    EFFECTS.index(e) for e in ("backlash", "stribeck", "resonance", "time_delay", "cyclic_error", "saturation"))
_MD_BACKLASH, _MD_DELAY, _MD_CYCLIC, _MD_RESONANCE, _MD_CONTROLLER, _MD_SATURATION = (
    MODE_SLOTS[k] for k in ("backlash", "time_delay", "cyclic_error", "resonance", "controller", "saturation"))
_GAP, _RATIO, _VS, _FREQ, _DAMPING, _GAIN, _DELAY, _PERIOD, _SIN, _COS, _LIMIT, _MOTOR, _PSI = (
    EP_INDEX[k] for k in ("gap_mm", "static_to_coulomb_ratio", "stribeck_velocity_mm_s", "freq_hz", "damping", "gain",
                          "delay_s", "period_mm", "amplitude_sin", "amplitude_cos", "limit", "motor_fraction",
                          "position_motor_share"))


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
    the free one).  The stiff contact of a two-mass backlash variant (:data:`CONTACT_HZ`)
    needs stability only, not phase accuracy: its frequency is a stand-in for "stiff", not
    a fitted value, so its sub-step turns at most :data:`CONTACT_STEP_RAD`.
    """
    f = ep[_FREQ] if flags[_FL_RESONANCE] else 0.0
    n = substeps(theta, Ts, 1.5 * f)
    if flags[_FL_BACKLASH] and modes[_MD_BACKLASH] >= 1 and not (flags[_FL_RESONANCE] and modes[_MD_RESONANCE] >= 1):
        n = max(n, math.ceil(Ts * 2.0 * math.pi * CONTACT_HZ / CONTACT_STEP_RAD))
    return n


@njit(cache=True, nogil=True)
def _friction_step(v: float, F: float, h: float, m: float, d0: float, d1: float, rs: float, on_st: bool,
                   vs: float) -> float:
    """Velocity after one sub-step of a mass share ``m`` under force ``F`` and friction (eq. 3.2).

    Coulomb levels d0 (moving +) and d1 (moving −, negative), Stribeck curve when ``on_st``,
    breakaway at ``rs``·d from rest (Karnopp stick phase).  When the velocity reaches zero
    inside the sub-step, the rest of the sub-step starts from rest — stick, or break away the
    other way: stopping for the whole sub-step would delay every reversal by up to one
    sub-step (0.5 ms at 2 per sample), which a fitted dead time would take up.
    """
    rest = h
    if v.real != 0.0:
        d = d0 if v.real > 0.0 else d1
        q = div(v, vs)
        lvl = d * (1.0 + (rs - 1.0) * exp(-(q * q))) if on_st else d
        vn = v + div(h * (F - lvl), m)
        if vn.real * v.real > 0.0:
            return vn
        rest = h * (1.0 - div(v, v - vn))
    if F.real > (d0 * rs).real:
        return div(rest * (F - d0 * rs), m)
    if F.real < (d1 * rs).real:
        return div(rest * (F - d1 * rs), m)
    return 0.0


@njit(cache=True, nogil=True)
def _delay_output(out, starts, tau, Ts):
    """``out`` (recorded positions) delayed by ``tau`` s in place, fractionally, inside segments."""
    n = out.size
    sh = tau / Ts
    ip = int(sh.real)
    fr = sh - ip
    res = out.copy()
    s0 = 0
    for k in range(n):
        if starts[k]:
            s0 = k
        i0 = k - ip
        i1 = k - ip - 1
        if i0 < s0:
            i0 = s0
        if i1 < s0:
            i1 = s0
        res[k] = (1.0 - fr) * out[i0] + fr * out[i1]
    for k in range(n):
        out[k] = res[k]


@njit(cache=True, nogil=True)
def _kernel_many(xr, vr, ar, x0, starts, warm, vw, aw, Ts, nsub, TH, flags, EP, modes, OUT, OUT_U):
    """The free run of eq. 3.3 and the effects of :data:`EFFECTS` for P parameter sets in lockstep.

    Rows of ``TH`` (P, 8) and ``EP`` (P, 13) are the sets, rows of ``OUT`` and ``OUT_U`` (P, N)
    their recorded positions and the u applied at each sample (``OUT_U`` of no columns: not
    wanted); flags, variants and sub-steps
    are common (a Jacobian's columns).  Generic in the number type of ``TH``/``EP`` (and of
    ``OUT``, ``OUT_U``): float64, or complex128 for :func:`sensitivities` — every comparison
    reads ``.real``, so both take the same branches.  Each set's arithmetic is the same,
    in the same order, whatever the other sets, so a row is bit for bit that set's free
    run alone (P = 1, :func:`simulate_augmented`).  Why several at once: one free run is a
    chain of dependent operations (semi-implicit Euler: every sub-step waits for the last),
    so the processor idles on latencies; the sets' chains are independent and interleave
    (about twice the simulations per second for 6–12 sets).
    """
    P = TH.shape[0]
    n = xr.size
    want_u = OUT_U.shape[1] == n
    h = Ts / nsub
    on_bl = flags[_FL_BACKLASH] != 0
    on_st = flags[_FL_STRIBECK] != 0
    on_rs = flags[_FL_RESONANCE] != 0
    on_td = flags[_FL_DELAY] != 0
    on_cy = flags[_FL_CYCLIC] != 0
    on_sa = flags[_FL_SATURATION] != 0
    sa_windup = on_sa and modes[_MD_SATURATION] == 1
    bl_loop = on_bl and modes[_MD_BACKLASH] >= 1
    rs_two = on_rs and modes[_MD_RESONANCE] >= 1
    fb_motor = (rs_two and modes[_MD_RESONANCE] >= 2) or (bl_loop and modes[_MD_BACKLASH] == 2)
    rec_motor = rs_two and modes[_MD_RESONANCE] == 3
    two = bl_loop or rs_two
    td_loop = on_td and modes[_MD_DELAY] == 1
    cy_force = on_cy and modes[_MD_CYCLIC] == 1
    sampled = modes[_MD_CONTROLLER] != 0
    causal = modes[_MD_CONTROLLER] == 2
    a1 = TH[:, 0].copy()
    a2 = TH[:, 1].copy()
    a3 = TH[:, 2].copy()
    b0 = TH[:, 3].copy()
    b1 = TH[:, 4].copy()
    b2 = TH[:, 5].copy()
    d0 = TH[:, 6].copy()
    d1 = TH[:, 7].copy()
    half = np.empty_like(a1)
    rs = np.empty_like(a1)
    vs = np.empty_like(a1)
    wr = np.empty_like(a1)
    zr = np.empty_like(a1)
    kr = np.empty_like(a1)
    tau = np.empty_like(a1)
    tw = np.empty_like(a1)
    cs = np.empty_like(a1)
    cc = np.empty_like(a1)
    lim = np.empty_like(a1)
    mu = np.empty_like(a1)
    psi = np.empty_like(a1)
    kc = np.empty_like(a1)
    cdmp = np.empty_like(a1)
    half_c = np.empty_like(a1)
    dsteps = np.empty_like(a1)
    nbuf = np.empty(P, dtype=np.int64)
    for p in range(P):
        ep = EP[p]
        half[p] = 0.5 * ep[_GAP]
        rs[p] = ep[_RATIO] if on_st else 1.0
        vs[p] = ep[_VS] if ep[_VS].real > 1e-9 else 1e-9
        wr[p] = 2.0 * math.pi * ep[_FREQ]
        zr[p] = ep[_DAMPING]
        kr[p] = ep[_GAIN]
        tau[p] = ep[_DELAY] if on_td else 0.0
        per = ep[_PERIOD] if ep[_PERIOD].real > 1e-9 else 1e-9
        tw[p] = 2.0 * math.pi / per
        cs[p] = ep[_SIN]
        cc[p] = ep[_COS]
        lim[p] = ep[_LIMIT]
        m_ = ep[_MOTOR] if ep[_MOTOR].real > 0.0 else 1.0
        psi[p] = ep[_PSI]
        if two:
            if m_.real <= 0.0 or m_.real >= 1.0:
                m_ = 0.8
            wc = wr[p] if rs_two else 2.0 * math.pi * CONTACT_HZ
            zc = zr[p] if rs_two else CONTACT_DAMPING
            mred = m_ * (1.0 - m_)
            kc[p] = wc * wc * mred
            cdmp[p] = 2.0 * zc * wc * mred
            half_c[p] = half[p] if bl_loop else 0.0
        else:
            kc[p] = 0.0
            cdmp[p] = 0.0
            half_c[p] = 0.0
        mu[p] = m_
        dsteps[p] = tau[p] / h if td_loop else 0.0
        nbuf[p] = int(dsteps[p].real) + 3
    buf = np.zeros((P, int(np.max(nbuf))), dtype=TH.dtype)
    bi = np.zeros(P, dtype=np.int64)
    xm = np.zeros_like(a1)
    v = np.zeros_like(a1)
    xt = np.zeros_like(a1)
    vt = np.zeros_like(a1)
    q = np.zeros_like(a1)
    qd = np.zeros_like(a1)
    ei = np.zeros_like(a1)
    vb = np.zeros_like(a1)
    vb_prev = np.zeros_like(a1)
    xm_prev = np.zeros_like(a1)
    xw = np.zeros_like(a1)
    wind_x = np.ones(P, dtype=np.bool_)
    wind_h = np.ones(P, dtype=np.bool_)
    first = np.ones(P, dtype=np.bool_)
    u_h = np.zeros_like(a1)
    u_last = np.zeros_like(a1)
    for k in range(n):
        last = k == n - 1 or starts[k + 1]
        for p in range(P):
            if starts[k]:
                first[p] = True
                xm[p] = x0[k]
                xw[p] = xm[p]
                xt[p] = xm[p]
                v[p] = 0.0
                vt[p] = 0.0
                q[p] = 0.0
                qd[p] = 0.0
                ei[p] = (a2[p] * xm[p] - b2[p] * xr[k]) / a3[p] if a3[p].real != 0.0 else 0.0
                vb[p] = 0.0
                vb_prev[p] = 0.0
                u0 = 0.0
                if warm[k]:
                    vk = vw[k]
                    ak = aw[k]
                    # a velocity of exactly 0 is a restart at rest: ak is then the force
                    # friction holds (the integral holds it), not an acceleration
                    at_rest = vk.real == 0.0
                    if on_td and not td_loop and not at_rest:
                        xm[p] += tau[p] * (vk + 0.5 * tau[p] * ak)
                        vk += tau[p] * ak
                        xt[p] = xm[p]
                    if on_cy and not cy_force:
                        xm[p] -= cs[p] * sin(tw[p] * xm[p]) + cc[p] * cos(tw[p] * xm[p])
                        xt[p] = xm[p]
                    v[p] = 0.0 if at_rest else vk - 0.5 * h * ak
                    vt[p] = v[p]
                    lvl = 0.0
                    if vk.real != 0.0:
                        lvl = d0[p] if vk.real > 0.0 else d1[p]
                        if on_st:
                            sv_ = div(vk, vs[p])
                            lvl *= 1.0 + (rs[p] - 1.0) * exp(-(sv_ * sv_))
                    u0 = ak + lvl
                    if cy_force:
                        u0 += cs[p] * sin(tw[p] * xm[p]) + cc[p] * cos(tw[p] * xm[p])
                    if two:
                        fc = ak if at_rest else (1.0 - mu[p]) * ak + lvl
                        if fc.real != 0.0 and rec_motor:
                            xt[p] = xm[p] - div(fc, kc[p])  # the recorded state is the motor's
                        elif fc.real != 0.0:
                            xm[p] = xt[p] + div(fc, kc[p]) + (half_c[p] if fc.real > 0.0 else -half_c[p])
                    elif on_bl:
                        sv = vr[k] if vr[k] != 0.0 else vk
                        if sv.real != 0.0:
                            xm[p] = xt[p] + (half[p] if sv.real > 0.0 else -half[p])
                    xw[p] = xm[p]
                    xfb = xt[p] if (two and not fb_motor) else xm[p]
                    vf = v[p]
                    e_int = 0.0
                    ff = b0[p] * ar[k] + b1[p] * vr[k]
                    if sampled:
                        vf = 0.0 if at_rest else vk - 0.5 * Ts * ak
                        xm_prev[p] = xm[p] - vf * Ts
                        e_int = Ts * (xr[k] - xfb)
                        vb[p] = vr[k] - 1.5 * ar[k] * Ts
                        if causal:
                            ff = b0[p] * ar[k] + b1[p] * (vr[k] - 0.5 * ar[k] * Ts)
                        u_last[p] = u0
                        u_h[p] = u0
                        first[p] = False
                    if a3[p].real != 0.0:
                        ei[p] = (u0 - ff - b2[p] * xr[k] + a2[p] * ((1.0 - psi[p]) * xfb + psi[p] * xw[p])
                                 + a1[p] * vf) / a3[p] - e_int
                for i in range(nbuf[p]):
                    buf[p, i] = u0
                bi[p] = 0
            y = xt[p] if (on_bl or two) and not rec_motor else xm[p]
            if on_rs and not rs_two:
                y += q[p]
            if on_cy and not cy_force:
                y += cs[p] * sin(tw[p] * xm[p]) + cc[p] * cos(tw[p] * xm[p])
            OUT[p, k] = y
            if want_u:
                OUT_U[p, k] = 0.0
        if last:
            continue
        for j in range(nsub):
            f = j / nsub
            xrj = xr[k] + f * (xr[k + 1] - xr[k])
            vrj = vr[k] + f * (vr[k + 1] - vr[k])
            for p in range(P):
                xfb = xt[p] if (two and not fb_motor) else xm[p]
                xp = (1.0 - psi[p]) * xfb + psi[p] * xw[p]
                if sampled:
                    if j == 0:
                        vfb = div(xm[p] - xm_prev[p], Ts) if not first[p] else 0.0
                        xm_prev[p] = xm[p]
                        ei_new = ei[p] + Ts * (xr[k] - xfb)
                        if causal:
                            vb_prev[p] = vb[p]
                            if not starts[k]:
                                vb[p] = (xr[k] - xr[k - 1]) / Ts
                            else:
                                vb[p] = vr[k] - 0.5 * ar[k] * Ts if warm[k] else 0.0
                            uh = div(b0[p] * (vb[p] - vb_prev[p]), Ts) + b1[p] * vb[p]
                        else:
                            uh = b0[p] * ar[k] + b1[p] * vr[k]
                        uh += b2[p] * xr[k] + a3[p] * ei_new - a2[p] * xp - a1[p] * vfb
                        wh = True
                        if on_sa:
                            ig = (xr[k] - xfb if psi[p].real == 0.0
                                  else a3[p] * (xr[k] - xfb) - psi[p] * a2[p] * vfb)
                            if uh.real > lim[p].real:
                                uh = lim[p]
                                wh = sa_windup or ig.real <= 0.0
                            elif uh.real < -lim[p].real:
                                uh = -lim[p]
                                wh = sa_windup or ig.real >= 0.0
                        if wh:
                            ei[p] = ei_new
                        u = uh if first[p] else 0.5 * (u_last[p] + uh)
                        u_last[p] = uh
                        u_h[p] = uh
                        wind_h[p] = wh
                        first[p] = False
                    else:
                        u = u_h[p]
                    wind = False
                    wind_x[p] = wind_h[p]
                else:
                    u = b0[p] * ar[k] + b1[p] * vrj + b2[p] * xrj + a3[p] * ei[p] - a2[p] * xp - a1[p] * v[p]
                    wind = True
                    wind_x[p] = True
                    if on_sa:
                        ig = xrj - xfb if psi[p].real == 0.0 else a3[p] * (xrj - xfb) - psi[p] * a2[p] * v[p]
                        if u.real > lim[p].real:
                            u = lim[p]
                            wind = sa_windup or ig.real <= 0.0
                        elif u.real < -lim[p].real:
                            u = -lim[p]
                            wind = sa_windup or ig.real >= 0.0
                        wind_x[p] = wind
                if want_u and j == 0:
                    OUT_U[p, k] = u
                if td_loop:
                    nb = nbuf[p]
                    buf[p, bi[p]] = u
                    ip = int(dsteps[p].real)
                    fr = dsteps[p] - ip
                    i0 = (bi[p] - ip) % nb
                    i1 = (bi[p] - ip - 1) % nb
                    u = (1.0 - fr) * buf[p, i0] + fr * buf[p, i1]
                    bi[p] = (bi[p] + 1) % nb
                if cy_force:
                    u -= cs[p] * sin(tw[p] * xm[p]) + cc[p] * cos(tw[p] * xm[p])
                if two:
                    dl = xm[p] - xt[p]
                    ddl = v[p] - vt[p]
                    hc = half_c[p]
                    if hc.real > 0.0:
                        if dl.real > hc.real:
                            fc = kc[p] * (dl - hc) + cdmp[p] * ddl
                            if fc.real < 0.0:
                                fc = 0.0
                        elif dl.real < -hc.real:
                            fc = kc[p] * (dl + hc) + cdmp[p] * ddl
                            if fc.real > 0.0:
                                fc = 0.0
                        else:
                            fc = 0.0
                    else:
                        fc = kc[p] * dl + cdmp[p] * ddl
                    vn = v[p] + div(h * (u - fc), mu[p])
                    mt = 1.0 - mu[p]
                    vtn = _friction_step(vt[p], fc, h, mt, d0[p], d1[p], rs[p], on_st, vs[p])
                    v[p] = vn
                    vt[p] = vtn
                    xm[p] += h * vn
                    xt[p] += h * vtn
                    if wind:
                        ei[p] += h * (xrj - xfb)
                    if wind_x[p]:
                        xw[p] += h * vn
                    continue
                vn = _friction_step(v[p], u, h, 1.0, d0[p], d1[p], rs[p], on_st, vs[p])
                acc = div(vn - v[p], h)
                v[p] = vn
                xm[p] += h * vn
                if wind:
                    ei[p] += h * (xrj - xfb)
                if wind_x[p]:
                    xw[p] += h * vn
                if on_bl:
                    if (xm[p] - xt[p]).real > half[p].real:
                        xt[p] = xm[p] - half[p]
                    elif (xm[p] - xt[p]).real < -half[p].real:
                        xt[p] = xm[p] + half[p]
                if on_rs:
                    qdd = -2.0 * zr[p] * wr[p] * qd[p] - wr[p] * wr[p] * q[p] - kr[p] * acc
                    qd[p] += h * qdd
                    q[p] += h * qd[p]
    if on_td and not td_loop:
        for p in range(P):
            if tau[p].real > 0.0:
                _delay_output(OUT[p], starts, tau[p], Ts)


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
    ep : ndarray (13,)
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
        Filled with the control-equivalent acceleration u (mm/s²) applied at each sample.
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
    sub-steps, parameters differing (rows of ``thetas`` (P, 8) and ``eps`` (P, 13)).  The
    sets are simulated in lockstep in one pass (:func:`_kernel_many`), which is faster than
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


def _padded_modes(modes: np.ndarray) -> np.ndarray:
    """``modes`` as the kernel's int64 array of :data:`N_MODES` slots (a shorter one padded with zeros)."""
    md = np.ascontiguousarray(modes, dtype=np.int64)
    if md.size < N_MODES:
        md = np.concatenate([md, np.zeros(N_MODES - md.size, dtype=np.int64)])
    return md


def _runnable(TH: np.ndarray, E: np.ndarray) -> np.ndarray:
    """Per row, whether the parameters are a model to simulate: finite, the dead time in [0, 1] s
    (a diverged fit step is not)."""
    delay = E[:, _DELAY].real
    return np.isfinite(TH).all(axis=1) & np.isfinite(E).all(axis=1) & (delay >= 0.0) & (delay <= 1.0)


def _many(x_r, x0, Ts, thetas, eps, dtype, flags, modes, starts, derivs, nsub, warm,
          u_out: np.ndarray | None = None) -> np.ndarray:
    """:func:`_kernel_many` on P sets of parameters of number type ``dtype`` (float or complex);
    rows that are no model to simulate (:func:`_runnable`) are NaN.  ``u_out`` (N,), one set
    only: filled with the u the set applied."""
    x_r = np.ascontiguousarray(x_r, dtype=float)
    n = x_r.size
    TH = np.ascontiguousarray(thetas, dtype=dtype).reshape(-1, 8)
    E = np.ascontiguousarray(eps, dtype=dtype).reshape(-1, N_EP)
    ok = _runnable(TH, E)
    y = np.empty((int(np.count_nonzero(ok)), n), dtype=dtype)
    out_u = np.empty((y.shape[0], n) if u_out is not None else (0, 0), dtype=dtype)
    if y.shape[0]:
        _kernel_many(x_r, np.ascontiguousarray(derivs[0], dtype=float), np.ascontiguousarray(derivs[1], dtype=float),
                     np.ascontiguousarray(x0, dtype=float), np.ascontiguousarray(starts, dtype=np.bool_),
                     *_warm_arrays(warm, n), float(Ts), int(nsub), np.ascontiguousarray(TH[ok]),
                     np.ascontiguousarray(flags, dtype=np.int64), np.ascontiguousarray(E[ok]), _padded_modes(modes),
                     y, out_u)
        if u_out is not None:
            u_out[:] = out_u[0]
    if ok.all():
        return y
    out = np.full((TH.shape[0], n), np.nan, dtype=dtype)
    out[ok] = y
    return out


def _warm_arrays(warm: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
                 n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The kernel's (mask, v, a) of warm restarts: none when ``warm`` is None (v, a never read then)."""
    if warm is None:
        unused = np.zeros(n)
        return np.zeros(n, dtype=np.bool_), unused, unused
    return (np.ascontiguousarray(warm[0], dtype=np.bool_), np.ascontiguousarray(warm[1], dtype=float),
            np.ascontiguousarray(warm[2], dtype=float))

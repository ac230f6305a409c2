"""The one simulator kernel of the identified model: eq. 3.3 and every effect of SPEC §7.

:func:`_kernel_many` is the free run behind :mod:`ident.simulation` (the identified model,
no effect: the output-error refinement, predictions, the virtual machine) and
:mod:`ident.diagnosis.augmented` (the diagnosis's models, their lockstep Jacobian columns and
complex-step sensitivities); the model, its effects, variants and integration are described
there.  It lives outside the diagnosis package so that simulating the identified model does
not import the diagnosis.

The helpers a sub-step calls are compiled ``inline="always"``: numba compiles every njit
function on its own, and a call per sub-step cost as much as the sub-step's arithmetic
(inlined, the sampled and two-mass steps take 20–30 % less time, bit for bit the same run).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from core.effects import EFFECT_NAMES
from ident.complex_step import cos, div, exp, sin
from ident.discretisation import balanced, foh_blocks

__all__ = ["EFFECTS", "EP_INDEX", "N_EP", "MODE_SLOTS", "N_MODES", "CONTACT_HZ", "CONTACT_DAMPING",
           "compiled_in_this_process"]

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
    "limit_slope": 13,
}
N_EP = 14
#: Variant slots of the ``modes`` vector: backlash, time_delay, cyclic_error, resonance,
#: controller (0 continuous, 1 sampled, 2 sampled with causal feed-forward differences),
#: saturation (0 anti-windup, 1 none).
MODE_SLOTS: dict[str, int] = {"backlash": 0, "time_delay": 1, "cyclic_error": 2, "resonance": 3,
                              "controller": 4, "saturation": 5}
N_MODES = 6
#: Frequency and damping ratio of the motor–table contact of a backlash gap in the two-mass
#: variants, Hz and –.
CONTACT_HZ = 400.0
CONTACT_DAMPING = 0.5

# The kernel's slots by name (numba reads module-level ints as compile-time constants).
_FL_BACKLASH, _FL_STRIBECK, _FL_RESONANCE, _FL_DELAY, _FL_CYCLIC, _FL_SATURATION = (
    EFFECTS.index(e) for e in ("backlash", "stribeck", "resonance", "time_delay", "cyclic_error", "saturation"))
_MD_BACKLASH, _MD_DELAY, _MD_CYCLIC, _MD_RESONANCE, _MD_CONTROLLER, _MD_SATURATION = (
    MODE_SLOTS[k] for k in ("backlash", "time_delay", "cyclic_error", "resonance", "controller", "saturation"))
_GAP, _RATIO, _VS, _FREQ, _DAMPING, _GAIN, _DELAY, _PERIOD, _SIN, _COS, _LIMIT, _MOTOR, _PSI, _LSLOPE = (
    EP_INDEX[k] for k in ("gap_mm", "static_to_coulomb_ratio", "stribeck_velocity_mm_s", "freq_hz", "damping", "gain",
                          "delay_s", "period_mm", "amplitude_sin", "amplitude_cos", "limit", "motor_fraction",
                          "position_motor_share", "limit_slope"))


@njit(cache=True, nogil=True, inline="always")
def _friction_level(d, v, rs, on_st, vs):
    """Eq. 3.2's friction level ``d`` (signed, of the direction moved) at the speed ``v``:
    Coulomb, or with ``on_st`` on the Stribeck curve ``d·(1 + (r − 1)·exp(−(v/v_s)²))``."""
    if not on_st:
        return d
    q = div(v, vs)
    q2 = q * q
    if q2.real > 80.0:  # (r − 1)·e^(−q²) below the rounding of 1 (r < 1e18): the Coulomb level, bit for bit
        return d * (1.0 + 0.0 * q2)
    return d * (1.0 + (rs - 1.0) * exp(-q2))


@njit(cache=True, nogil=True, inline="always")
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
        lvl = _friction_level(d0 if v.real > 0.0 else d1, v, rs, on_st, vs)
        vn = v + div(h * (F - lvl), m)
        if vn.real * v.real > 0.0:
            return vn
        rest = h * (1.0 - div(v, v - vn))
    if F.real > (d0 * rs).real:
        return div(rest * (F - d0 * rs), m)
    if F.real < (d1 * rs).real:
        return div(rest * (F - d1 * rs), m)
    return 0.0


@njit(cache=True, nogil=True, inline="always")
def _contact_push(a, b, kc, cd, h):
    """The sub-step's mean push of one side of the backlash contact (two-mass variants).

    ``a`` the penetration past the side's edge at the sub-step's start (mm, negative: apart),
    ``b`` its rate (mm/s), ``kc``/``cd`` the contact's stiffness and damping (per unit mass),
    ``h`` the sub-step.  In contact the push is the spring-damper ``kc·a + cd·b``, never a
    pull: it starts at the edge with the damper's ``cd·b`` and ends where ``kc·a + cd·b``
    reaches zero (a separating contact lets go before the edge).  The penetration is
    extrapolated over the sub-step at the rate ``b`` and the push averaged over the part of
    the sub-step in contact — the whole sub-step, or the fraction after an entry or before
    a release.  The push is then continuous in the state and the free run in the
    parameters: a push switched on or off for whole sub-steps moves the run by a jump
    whenever a parameter moves a contact instant across a sub-step boundary, and the exact
    slope of such a run is that of one step of its staircase, not of its trend
    (benchmarks/bench_cost_ripple.py).  Averaging the spring over the sub-step in contact
    as well as at an entry keeps the slope continuous when an entry crosses a sub-step
    boundary (the spring's push at the start of the sub-step would not), at the price of a
    little numerical damping of the contact (ω·h ≈ 0.36 at 7 sub-steps a sample: about
    ζ 0.1 on the contact's 0.5; the contact's stiffness stands for "stiff", it is not fitted).
    """
    if b.real > 0.0:
        f0 = cd * b  # the damper's push at the edge
        g0 = a
    else:
        f0 = 0.0 * b
        g0 = a + div(cd * b, kc)  # past the release: kc·a + cd·b > 0
    g1 = g0 + b * h
    if g0.real > 0.0:
        if g1.real >= 0.0:
            return kc * 0.5 * (g0 + g1) + f0
        return 0.5 * kc * g0 * div(g0, g0 - g1)  # released at the fraction g0/(g0 − g1)
    if g1.real > 0.0:
        return (0.5 * kc * g1 + f0) * div(g1, g1 - g0)  # entered after the fraction −g0/(g1 − g0)
    return 0.0 * b


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


@njit(cache=True, nogil=True, inline="always")
def _clip(u, lim, slope, v):
    """``u`` clipped to ``±lim − slope·v`` (saturation).  The drive clips its own output
    ``u + slope·v``, which carries the plant's viscous share of the speed term eq. 3.3 folds
    into a1: the limit of u falls with speed in the direction it pushes."""
    hi = lim - slope * v
    lo = -lim - slope * v
    if u.real > hi.real:
        return hi
    if u.real < lo.real:
        return lo
    return u


@njit(cache=True, nogil=True, inline="always")
def _integral_share(u0, du, lim, slope, v, windup):
    """The share in [0, 1] of its increment over a step that the integral takes (conditional
    integration, a step of the sampled controller or of a sub-step): all of it with
    ``windup``, or where the loop's output ``u0`` (before the increment) moved by the
    increment's part ``du`` stays inside the clip (:func:`_clip`) or moves back towards it;
    else the share that ends the step with the output on the limit — none where ``u0`` lies
    beyond it already.  Continuous in the parameters, as the exact step's sliding on the
    limit is (:func:`_sliding_phase`): a freeze of the whole increment at once jumps by it
    wherever the output grazes the limit, and the cost ripples at every such step
    (benchmarks/bench_cost_ripple.py)."""
    one = 1.0 + 0.0 * du
    if windup:
        return one
    c = _side(u0 + du, lim, slope, v)
    if c == 0 or c * du.real <= 0.0:
        return one
    al = div(c * lim - slope * v - u0, du)
    if al.real < 0.0:
        return 0.0 * al
    if al.real > 1.0:
        return one
    return al


@njit(cache=True, nogil=True, inline="always")
def _free_phase(z, x, vv, md, s, Ph, Ga, Gb, xa, ua, sr, suc, g, a1, a2, a3, d0, d1, rs, on_st, vs):
    """``(z, x, ẋ, direction)`` after ``s`` seconds of the exact step with the loop's law acting
    (eq. 3.3's linear part by the first-order-hold blocks ``Ph``, ``Ga``, ``Gb`` of length ``s``;
    command ``xa`` and drive ``ua`` at the phase's start, slopes ``sr``, ``suc``; ``g`` the
    effects' held acceleration) and Karnopp friction (eq. 3.2).

    Moving, the level of the current direction (the Stribeck curve at the current speed); when
    ẋ reaches zero inside the phase the instant is interpolated and the axis reverses if the
    drive beats the breakaway level of the other side, else it sticks; stuck, it breaks away at
    the instant, interpolated inside the phase, the drive leaves the breakaway band.  Both
    instants are interpolated so x̂ is continuous in the parameters.
    """
    up = d0 * rs  # breakaway levels (Coulomb without Stribeck)
    dn = d1 * rs
    frictional = up.real != 0.0 or dn.real != 0.0
    if md == 0 and frictional:
        F = (ua + a3 * z - a2 * x - a1 * vv) + g  # the drive at rest, without friction
        go_up = F.real > up.real
        go_dn = F.real < dn.real
        if go_up and go_dn:  # only if d1 > d0 (unphysical friction): the stronger side wins
            if (F - up).real >= (dn - F).real:
                go_dn = False
            else:
                go_up = False
        if go_up:
            md = 1
        elif go_dn:
            md = -1
        else:  # stuck: friction balances F, x and ẋ = 0 held, z integrates
            z = z + s * (xa + 0.5 * sr * s) - s * x
            vv = 0.0 * vv
            Fb = (ua + suc * s) - a2 * x + a3 * z + g
            if Fb.real > up.real or Fb.real < dn.real:
                fb = up if Fb.real > up.real else dn
                dF = Fb - F
                tc = div(fb - F, dF) if dF.real != 0.0 else 1.0 + 0.0 * dF
                if tc.real < 0.0:
                    tc = 0.0 * tc
                elif tc.real > 1.0:
                    tc = 1.0 + 0.0 * tc
                r = (1.0 - tc) * s
                acc = Fb - fb  # net acceleration, ramping up from 0 over r
                vv = 0.5 * acc * r
                x = x + acc * r * r / 6.0
                md = 1 if Fb.real > up.real else -1
            return z, x, vv, md
    lvl = _friction_level(d0 if md == 1 else d1, vv, rs, on_st, vs)
    gin = ua + g - lvl
    zn = Ph[0, 0] * z + Ph[0, 1] * x + Ph[0, 2] * vv + Ga[0, 0] * xa + Ga[0, 1] * gin + Gb[0, 0] * sr + Gb[0, 1] * suc
    xn = Ph[1, 0] * z + Ph[1, 1] * x + Ph[1, 2] * vv + Ga[1, 0] * xa + Ga[1, 1] * gin + Gb[1, 0] * sr + Gb[1, 1] * suc
    vn = Ph[2, 0] * z + Ph[2, 1] * x + Ph[2, 2] * vv + Ga[2, 0] * xa + Ga[2, 1] * gin + Gb[2, 0] * sr + Gb[2, 1] * suc
    if md * vn.real <= 0.0 and frictional:
        # ẋ reached zero inside the phase: interpolate the instant, then reverse (if the drive
        # beats the other side's breakaway level) or stick.  Without friction nothing sticks:
        # the linear model exactly.
        dv = vv - vn
        tc = div(vv, dv) if dv.real != 0.0 else 1.0 + 0.0 * dv
        if tc.real < 0.0:
            tc = 0.0 * tc
        elif tc.real > 1.0:
            tc = 1.0 + 0.0 * tc
        r = (1.0 - tc) * s
        F = (ua + suc * s) + g - a2 * xn + a3 * zn
        if md == 1:
            rev = F.real < dn.real
            f_new = dn
        else:
            rev = F.real > up.real
            f_new = up
        if rev:
            df = f_new - lvl  # friction change over the remaining r seconds
            vn = vn - df * r
            xn = xn - 0.5 * df * r * r
            if md * vn.real < 0.0:
                md = -md
            else:
                vn = 0.0 * vn
                md = 0
        else:
            xn = xn - 0.5 * vn * r  # undo the overshoot past the stop
            vn = 0.0 * vn
            md = 0
    return zn, xn, vn, md


@njit(cache=True, nogil=True)
def _part_blocks(a1, a2, a3, s):
    """:func:`ident.discretisation.foh_blocks` over a part ``s`` of a sub-step (a clip's switch
    inside it), cheaply: only the three rows of the exponential the blocks take, by its Taylor
    series on the same balanced matrix — the part's balanced norm is at most a few tenths, so
    24 terms are exact to rounding without squarings; ``foh_blocks`` itself beyond that."""
    M, S = balanced(a1, a2, a3, s)
    if S[2] * abs(s.real) > 0.25:  # ω·s
        return foh_blocks(a1, a2, a3, s)
    E = np.zeros((3, 7)) + 0.0 * s
    T = np.zeros((3, 7)) + 0.0 * s
    U = np.zeros((3, 7)) + 0.0 * s
    for i in range(3):
        E[i, i] = 1.0
        T[i, i] = 1.0
    for k in range(1, 25):
        for i in range(3):
            for j in range(7):
                acc = 0.0 * s
                for r in range(7):
                    acc += T[i, r] * M[r, j]
                U[i, j] = acc / k
        for i in range(3):
            for j in range(7):
                T[i, j] = U[i, j]
                E[i, j] += U[i, j]
    for i in range(3):
        for j in range(7):
            E[i, j] = E[i, j] * (S[i] / S[j])
    return E[:, :3].copy(), E[:, 3:5].copy(), E[:, 5:7].copy()


@njit(cache=True, nogil=True, inline="always")
def _drive(ua, z, x, vv, xw, a1, a2, a3, psi):
    """The loop's output before the clip: eq. 3.3's law (command drive ``ua``) with the ψ-share."""
    return ua + a3 * z - a2 * x - a1 * vv - a2 * psi * (xw - x)


@njit(cache=True, nogil=True, inline="always")
def _beyond(u, c, lim, slope, vv):
    """How far the drive output ``u`` lies beyond the clip of side ``c`` (±1; ``c·lim − slope·v``,
    :func:`_clip`): positive when that side clips it."""
    return c * u - lim + c * slope * vv


@njit(cache=True, nogil=True, inline="always")
def _side(u, lim, slope, vv):
    """The side (1, −1) whose clip holds ``u``, 0 if none (decided on the real part)."""
    if _beyond(u, 1, lim, slope, vv).real > 0.0:
        return 1
    if _beyond(u, -1, lim, slope, vv).real > 0.0:
        return -1
    return 0


@njit(cache=True, nogil=True, inline="always")
def _direction(v):
    """The Karnopp state of a mass moving at ``v`` after a held-force step: 1 moving +, −1
    moving −, 0 at rest (decided on the real part)."""
    return 1 if v.real > 0.0 else (-1 if v.real < 0.0 else 0)


@njit(cache=True, nogil=True)
def _fraction(b0, b1):
    """Where in [0, 1] a quantity linear from ``b0`` to ``b1`` crosses zero (the real part decides
    the clamp, complex arithmetic elsewhere)."""
    db = b0 - b1
    tc = div(b0, db) if db.real != 0.0 else 1.0 + 0.0 * db
    if tc.real < 0.0:
        return 0.0 * tc
    if tc.real > 1.0:
        return 1.0 + 0.0 * tc
    return tc


@njit(cache=True, nogil=True)
def _held_phase(z, x, vv, xw, s, c, f, xa, sr, a2, a3, psi, windup, d0, d1, rs, on_st, vs):
    """``(z, x, ẋ, x_w)`` after ``s`` seconds with the drive clipped on side ``c``: the mass under
    the held force ``f`` (the clip less any cyclic force; friction and its Karnopp stop as
    :func:`_friction_step`), the integral by the trapezoid over the part of the phase where it
    runs on — always with ``windup``, else while its error would not wind the clip up
    (conditional integration, :func:`_integral_share`), the instant its error changes sign
    interpolated — and ``x_w`` following x over that part."""
    vn = _friction_step(vv, f, s, 1.0, d0, d1, rs, on_st, vs)
    xn = x + 0.5 * s * (vv + vn)
    e0 = xa - x
    e1 = xa + sr * s - xn
    p0 = 0.0 * s
    p1 = 1.0 + 0.0 * s
    if not windup:
        ig0 = e0 if psi.real == 0.0 else a3 * e0 - psi * a2 * vv
        ig1 = e1 if psi.real == 0.0 else a3 * e1 - psi * a2 * vn
        on0 = c * ig0.real <= 0.0
        on1 = c * ig1.real <= 0.0
        if not (on0 or on1):
            return z, xn, vn, xw
        if on0 != on1:
            tc = _fraction(ig0, ig1)
            if on0:
                p1 = tc
            else:
                p0 = tc
    ea = e0 + p0 * (e1 - e0)
    eb = e0 + p1 * (e1 - e0)
    return z + 0.5 * s * (p1 - p0) * (ea + eb), xn, vn, xw + (p1 - p0) * (xn - x)


@njit(cache=True, nogil=True)
def _sliding_phase(z, x, vv, xw, s, c, cyc, xa, sr, ua1, a1, a2, a3, psi, lim, slope, d0, d1, rs, on_st, vs):
    """``(z, x, ẋ, x_w)`` after ``s`` seconds on the clip's edge of side ``c`` (conditional
    integration): clipped the loop's output falls back inside the limit, free it rises beyond
    it, so the output stays at the limit (a Filippov sliding motion) — the mass under the
    held clip, the integral (and x_w) running on the fraction of its rate, in [0, 1], that ends
    the phase with the output ``ua1 + …`` at the limit."""
    vn = _friction_step(vv, c * lim - slope * vv - cyc, s, 1.0, d0, d1, rs, on_st, vs)
    xn = x + 0.5 * s * (vv + vn)
    dz = 0.5 * s * ((xa - x) + (xa + sr * s - xn))
    dxw = xn - x
    slope_al = a3 * dz - a2 * psi * dxw
    miss = c * lim - slope * vn - _drive(ua1, z, xn, vn, xw, a1, a2, a3, psi)
    if slope_al.real == 0.0:
        al = 0.0 * miss
    else:
        al = div(miss, slope_al)
        if al.real < 0.0:
            al = 0.0 * al
        elif al.real > 1.0:
            al = 1.0 + 0.0 * al
    return z + al * dz, xn, vn, xw + al * dxw


@njit(cache=True, nogil=True, inline="always")
def _saturated_step(z, x, vv, md, xw, h, Ph, Ga, Gb, xa, ua, sr, suc, cyc, a1, a2, a3, psi, lim, slope, windup,
                    d0, d1, rs, on_st, vs):
    """``(z, x, ẋ, direction, x_w)`` after one sub-step of the exact path with a saturation.

    The clip's onset and release (and with them the integral's freeze) are located inside the
    sub-step, as the friction's reversal and breakaway are: the sub-step is stepped in the
    state of its start (free, :func:`_free_phase`; clipped, :func:`_held_phase`); if the loop's
    output ends it on the other side of the limit, the instant it crossed is interpolated
    linearly between the two ends (on the output's distance beyond the limit, :func:`_beyond`)
    and the sub-step is stepped again: the part before in the state of the start, the part
    after in the other (the exact step's blocks of the part's length).  Should the part after
    cross back by its end, the output slides on the limit (:func:`_sliding_phase`).  Every
    switch then moves continuously with the parameters, so x̂ is continuous in them and the
    complex-step slope is the cost's trend, not one ripple of sub-step switches.  ``cyc``: a
    cyclic force, held; ``Ph``, ``Ga``, ``Gb``: the blocks of a whole sub-step ``h``.
    """
    ua1 = ua + suc * h
    u0 = _drive(ua, z, x, vv, xw, a1, a2, a3, psi)
    c0 = _side(u0, lim, slope, vv)
    g = -a2 * psi * (xw - x) - cyc
    if c0 == 0:
        z1, x1, v1, md1 = _free_phase(z, x, vv, md, h, Ph, Ga, Gb, xa, ua, sr, suc, g, a1, a2, a3, d0, d1, rs, on_st, vs)
        xw1 = xw + (x1 - x)
        u1 = _drive(ua1, z1, x1, v1, xw1, a1, a2, a3, psi)
        c = _side(u1, lim, slope, v1)
        if c == 0:
            return z1, x1, v1, md1, xw1
        tc = _fraction(_beyond(u0, c, lim, slope, vv), _beyond(u1, c, lim, slope, v1))
        s = tc * h
        P1, G1, H1 = _part_blocks(a1, a2, a3, s)
        z2, x2, v2, md = _free_phase(z, x, vv, md, s, P1, G1, H1, xa, ua, sr, suc, g, a1, a2, a3, d0, d1, rs, on_st, vs)
        xw2 = xw + (x2 - x)
        xa2 = xa + sr * s
        r = h - s
        z3, x3, v3, xw3 = _held_phase(z2, x2, v2, xw2, r, c, c * lim - slope * v2 - cyc, xa2, sr, a2, a3, psi, windup,
                                      d0, d1, rs, on_st, vs)
        if not windup and _beyond(_drive(ua1, z3, x3, v3, xw3, a1, a2, a3, psi), c, lim, slope, v3).real <= 0.0:
            z3, x3, v3, xw3 = _sliding_phase(z2, x2, v2, xw2, r, c, cyc, xa2, sr, ua1, a1, a2, a3, psi, lim, slope,
                                             d0, d1, rs, on_st, vs)
    else:
        c = c0
        z1, x1, v1, xw1 = _held_phase(z, x, vv, xw, h, c, c * lim - slope * vv - cyc, xa, sr, a2, a3, psi, windup,
                                      d0, d1, rs, on_st, vs)
        b1 = _beyond(_drive(ua1, z1, x1, v1, xw1, a1, a2, a3, psi), c, lim, slope, v1)
        if b1.real > 0.0:
            return z1, x1, v1, _direction(v1), xw1
        tc = _fraction(_beyond(u0, c, lim, slope, vv), b1)
        s = tc * h
        z2, x2, v2, xw2 = _held_phase(z, x, vv, xw, s, c, c * lim - slope * vv - cyc, xa, sr, a2, a3, psi, windup,
                                      d0, d1, rs, on_st, vs)
        md = _direction(v2)
        xa2 = xa + sr * s
        r = h - s
        P2, G2, H2 = _part_blocks(a1, a2, a3, r)
        g2 = -a2 * psi * (xw2 - x2) - cyc
        z3, x3, v3, md = _free_phase(z2, x2, v2, md, r, P2, G2, H2, xa2, ua + suc * s, sr, suc, g2, a1, a2,
                                     a3, d0, d1, rs, on_st, vs)
        xw3 = xw2 + (x3 - x2)
        if not windup and _beyond(_drive(ua1, z3, x3, v3, xw3, a1, a2, a3, psi), c, lim, slope, v3).real > 0.0:
            z3, x3, v3, xw3 = _sliding_phase(z2, x2, v2, xw2, r, c, cyc, xa2, sr, ua1, a1, a2, a3, psi, lim, slope,
                                             d0, d1, rs, on_st, vs)
    return z3, x3, v3, _direction(v3), xw3


@njit(cache=True, nogil=True)
def _pair_flow(w2, c, t):
    """``exp([[0, 1], [−w2, −c]]·t)`` as (Φ00, Φ01, Φ10, Φ11): the flow of ë + c·ė + w2·e = 0
    over ``t``, in closed form (the number type of ``w2``; branches on the real part).
    With ω_d² = w2 − c²/4 and s(t) = sin(ω_d t)/ω_d (sinh when ω_d² < 0, t at ω_d = 0):
    Φ = e^(−ct/2)·[[cos + (c/2)·s, s], [−w2·s, cos − (c/2)·s]]."""
    q = w2 - 0.25 * c * c
    g = exp(-0.5 * c * t)
    if abs(q.real) * t.real * t.real < 1e-8:  # near critical damping: the series of cos and s
        x2 = q * t * t
        cs = 1.0 - 0.5 * x2 + x2 * x2 / 24.0
        sn = t * (1.0 - x2 / 6.0 + x2 * x2 / 120.0)
    elif q.real > 0.0:
        wd = np.sqrt(q)
        cs = cos(wd * t)
        sn = div(sin(wd * t), wd)
    else:
        wo = np.sqrt(-q)
        ep, em = exp(wo * t), exp(-wo * t)
        cs = 0.5 * (ep + em)
        sn = div(0.5 * (ep - em), wo)
    return g * (cs + 0.5 * c * sn), g * sn, -g * w2 * sn, g * (cs - 0.5 * c * sn)


@njit(cache=True, nogil=True, inline="always")
def _pair(F, e, de, g):
    """The oscillator ë + c·ė + w2·e = w2·g (``g`` held) advanced by its flow ``F``
    (:func:`_pair_flow`): the deviation from the static deflection ``g`` decays along the
    free flow."""
    a = e - g
    return F[0] * a + F[1] * de + g, F[2] * a + F[3] * de


@njit(cache=True, nogil=True)
def _two_mass_flows(mu, kc, cd, h):
    """The per-set constants of :func:`_two_mass_step` over a sub-step ``h``: the flows
    (:func:`_pair_flow`) of the free-free mode and of the motor on the spring to a held
    table, their w2 and c, and 1/kc."""
    mred = mu * (1.0 - mu)
    w2f, cf = div(kc, mred), div(cd, mred)
    w2a, ca = div(kc, mu), div(cd, mu)
    fr = _pair_flow(w2f, cf, h)
    fa = _pair_flow(w2a, ca, h)
    return (fr[0], fr[1], fr[2], fr[3], fa[0], fa[1], fa[2], fa[3], w2f, cf, w2a, ca, div(1.0 + 0.0 * kc, kc))


@njit(cache=True, nogil=True, inline="always")
def _two_mass_phase(xm, vm, xt, vt, u, t, ff, stuck, mu, F, ikc):
    """Motor (share μ) and table (1 − μ) coupled by a spring-damper over ``t`` under the
    held drive force ``u`` on the motor and the held friction ``ff`` on the table, exactly:
    the centre of mass as a double integrator under u − ff, the deflection as the free-free
    mode (``F`` its flow over ``t``; static deflection (μ_t·u + μ·ff)/kc); ``stuck``: the
    table held by friction, the motor on the spring to it (``F`` the locked-table flow,
    static deflection u/kc)."""
    if stuck:
        x, v = _pair(F, xm - xt, vm, u * ikc)
        return xt + x, v, xt, 0.0 * vt
    mt = 1.0 - mu
    a = u - ff
    X = mu * xm + mt * xt + t * (mu * vm + mt * vt) + 0.5 * t * t * a
    V = mu * vm + mt * vt + t * a
    dl, ddl = _pair(F, xm - xt, vm - vt, (mt * u + mu * ff) * ikc)
    return X + mt * dl, V + mt * ddl, X - mu * dl, V - mu * ddl


@njit(cache=True, nogil=True, inline="always")
def _two_mass_step(xm, vm, xt, vt, u, h, mu, kc, cd, C, d0, d1, rs, on_st, vs):
    """One sub-step of the two-mass drive under a drive force ``u`` held over it (the
    sampled controller's output), exact for the linear part (:func:`_two_mass_phase`;
    ``C`` the set's :func:`_two_mass_flows` over ``h``), the table's friction (eq. 3.2,
    Stribeck at the phase's starting speed) held per phase with Karnopp's stick: a table
    that reverses inside the sub-step stops at the interpolated instant, and one at rest
    breaks away at the interpolated instant its spring force passes the breakaway level —
    so the run is continuous in the parameters, as the single mass's exact step is.  The
    phases after an event take their flow over the rest of the sub-step."""
    FR = (C[0], C[1], C[2], C[3])
    FA = (C[4], C[5], C[6], C[7])
    ikc = C[12]
    t = h
    broke = False
    lvl = d0 * rs  # the breakaway level once ``broke``
    for _ in range(4):
        if t.real <= 0.0:
            break
        whole = t.real == h.real
        if vt.real != 0.0 or broke:
            if vt.real != 0.0:
                ff = _friction_level(d0 if vt.real > 0.0 else d1, vt, rs, on_st, vs)
            else:  # breaking away, at the level of the side of the stick band the spring force left
                ff = lvl
            F = FR if whole else _pair_flow(C[8], C[9], t)
            xm1, vm1, xt1, vt1 = _two_mass_phase(xm, vm, xt, vt, u, t, ff, False, mu, F, ikc)
            if vt.real == 0.0 or vt1.real * vt.real > 0.0:
                return xm1, vm1, xt1, vt1
            # the table stops inside: slide to the interpolated instant, then from rest
            tau = t * div(vt, vt - vt1)
            xm, vm, xt, vt = _two_mass_phase(xm, vm, xt, vt, u, tau, ff, False, mu, _pair_flow(C[8], C[9], tau), ikc)
            vt = 0.0 * vt
            t = t - tau
            broke = False
            continue
        fc0 = kc * (xm - xt) + cd * vm
        if fc0.real > (d0 * rs).real or fc0.real < (d1 * rs).real:
            lvl = d0 * rs if fc0.real > (d0 * rs).real else d1 * rs
            broke = True
            continue
        F = FA if whole else _pair_flow(C[10], C[11], t)
        xm1, vm1, xt1, vt1 = _two_mass_phase(xm, vm, xt, vt, u, t, 0.0 * u, True, mu, F, ikc)
        fc1 = kc * (xm1 - xt1) + cd * vm1
        if fc1.real > (d0 * rs).real:
            lvl = d0 * rs
        elif fc1.real < (d1 * rs).real:
            lvl = d1 * rs
        else:
            return xm1, vm1, xt1, vt1
        # the spring force passes the breakaway level inside: held to the interpolated instant
        tau = t * div(lvl - fc0, fc1 - fc0)
        xm, vm, xt, vt = _two_mass_phase(xm, vm, xt, vt, u, tau, 0.0 * u, True, mu, _pair_flow(C[10], C[11], tau), ikc)
        t = t - tau
        broke = True
    return xm, vm, xt, vt


@njit(cache=True, nogil=True)
def _exact_steps(flags, modes):
    """Which of the kernel's steps are exact for the linear part: ``(exact, two_exact)`` —
    the single mass on the continuous controller, and a two-mass mode (no gap) under the
    sampled controller (:func:`_two_mass_step`).  A mode stepped exactly (``two_exact``, or
    the filter of resonance mode 0 on the exact step) sets no sub-step
    (:func:`ident.diagnosis.augmented.model_substeps`)."""
    bl_loop = flags[_FL_BACKLASH] != 0 and modes[_MD_BACKLASH] >= 1
    rs_two = flags[_FL_RESONANCE] != 0 and modes[_MD_RESONANCE] >= 1
    sampled = modes[_MD_CONTROLLER] != 0
    return not (bl_loop or rs_two) and not sampled, sampled and rs_two and not bl_loop


@njit(cache=True, nogil=True, inline="always")
def _loop_delayed(buf, bi, p, u, dsteps, nb):
    """``u`` into set ``p``'s ring buffer of sub-step values and, out of it, the u of ``dsteps``
    sub-steps ago (linear between sub-steps): the dead time inside the loop."""
    buf[p, bi[p]] = u
    ip = int(dsteps.real)
    fr = dsteps - ip
    i0 = (bi[p] - ip) % nb
    i1 = (bi[p] - ip - 1) % nb
    bi[p] = (bi[p] + 1) % nb
    return (1.0 - fr) * buf[p, i0] + fr * buf[p, i1]


@njit(cache=True, nogil=True)
def _kernel_many(xr, vr, ar, x0, starts, warm, vw, aw, Ts, nsub, TH, flags, EP, modes, OUT, OUT_U, load,
                 start_rule):
    """The free run of eq. 3.3 and the effects of :data:`EFFECTS` for P parameter sets in lockstep.

    Rows of ``TH`` (P, 8) and ``EP`` (P, N_EP) are the sets, rows of ``OUT`` and ``OUT_U`` (P, N)
    their recorded positions and the u applied at each sample (``OUT_U`` of no columns: not
    wanted); flags, variants and sub-steps
    are common (a Jacobian's columns).  Generic in the number type of ``TH``/``EP`` (and of
    ``OUT``, ``OUT_U``): float64, or complex128 for :func:`sensitivities` — every comparison
    reads ``.real``, so both take the same branches.  Each set's arithmetic is the same,
    in the same order, whatever the other sets, so a row is bit for bit that set's free
    run alone (P = 1, :func:`simulate_augmented`).  Why several at once: one free run is a
    chain of dependent operations (every sub-step waits for the last), so the processor
    idles on latencies; the sets' chains are independent and interleave (about twice the
    simulations per second for 6–12 sets on the Euler step).  ``load`` (N,), mm/s²: an
    external acceleration linear between samples (exact step only: the identification's
    disturbance input; empty: none); ``warm`` (N,) the warm restarts' mask with their ``vw``,
    ``aw`` (empty: none); ``start_rule`` 1: segments start as :mod:`ident.simulation` starts
    them (integral at zero, ẋ = ẋ_r) instead of at rest.
    """
    P = TH.shape[0]
    n = xr.size
    want_u = OUT_U.shape[1] == n
    has_load = load.size == n  # none given: an empty array, read as zero
    has_warm = warm.size == n  # no warm restarts: an empty mask
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
    # the clip's onset and release located inside the exact step (not behind an in-loop delay)
    sa_events = on_sa and not td_loop
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
    lsl = np.empty_like(a1)
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
        lsl[p] = ep[_LSLOPE]
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
    # The two-mass drives' kick-and-drift sub-steps (all but a mode under the sampled
    # controller, stepped exactly): the last kicks' accelerations of motor and table, to
    # read the velocities at the kick's instant (second order), and whether the next kick is
    # the half kick after a restart.
    am = np.zeros_like(a1)
    at = np.zeros_like(a1)
    hk = np.zeros(P, dtype=np.bool_)
    xm_prev = np.zeros_like(a1)
    xw = np.zeros_like(a1)
    wind_x = np.ones_like(a1)  # the share of its increment the integral takes (_integral_share)
    wind_h = np.ones_like(a1)
    first = np.ones(P, dtype=np.bool_)
    u_h = np.zeros_like(a1)
    u_last = np.zeros_like(a1)
    # The exact step (single mass, continuous controller): per set the first-order-hold blocks
    # of eq. 3.3's linear part over a sub-step, the Karnopp state (1 moving +, −1 moving −,
    # 0 stuck), the command drive at the sample and its slope, and whether any effect adds a
    # held input.
    exact, two_exact = _exact_steps(flags, modes)
    # A two-mass mode (no gap) under the sampled controller's held output: the sub-step is
    # exact for its linear part (:func:`_two_mass_step`), per set the flows of the free-free
    # mode and of the motor on the spring to a table held by friction.
    two_mid = two and not two_exact
    # On the exact step the filter of resonance mode 0 on the recorded position is driven by
    # the mass's mean acceleration over each sub-step, held, and advanced by its flow — exact
    # for that input, so its frequency sets no sub-step.
    QF = np.zeros((P, 4), dtype=TH.dtype)
    qg = np.zeros(P, dtype=TH.dtype)
    if on_rs and not rs_two and exact:
        for p in range(P):
            QF[p, :] = _pair_flow(wr[p] * wr[p], 2.0 * zr[p] * wr[p], h + 0.0 * a1[p])
            qg[p] = div(-kr[p], wr[p] * wr[p])  # static deflection per mm/s² of acceleration
    TM = np.zeros((P, 13), dtype=TH.dtype)
    if two_exact:
        for p in range(P):
            TM[p, :] = _two_mass_flows(mu[p], kc[p], cdmp[p], h + 0.0 * a1[p])
    PH = np.zeros((P, 3, 3), dtype=TH.dtype)
    GA = np.zeros((P, 3, 2), dtype=TH.dtype)
    GB = np.zeros((P, 3, 2), dtype=TH.dtype)
    dir_ = np.zeros(P, dtype=np.int64)
    extra = np.zeros(P, dtype=np.bool_)
    if exact:
        for p in range(P):
            Phi_, G0_, G1_ = foh_blocks(a1[p], a2[p], a3[p], h)
            PH[p] = Phi_
            GA[p] = G0_
            GB[p] = G1_
            extra[p] = on_sa or td_loop or cy_force or psi[p].real != 0.0
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
                am[p] = 0.0
                at[p] = 0.0
                hk[p] = two_mid
                q[p] = 0.0
                qd[p] = 0.0
                ei[p] = (a2[p] * xm[p] - b2[p] * xr[k]) / a3[p] if a3[p].real != 0.0 else 0.0
                dir_[p] = 0
                vb[p] = 0.0
                vb_prev[p] = 0.0
                u0 = 0.0
                if has_warm and warm[k]:
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
                    # The sampled single mass's velocities live at half sub-steps (its first kick is
                    # whole); every other step's at the sub-step.
                    v[p] = vk - 0.5 * h * ak if sampled and not two and not at_rest else vk
                    vt[p] = v[p]
                    if exact and vk.real != 0.0:
                        dir_[p] = 1 if vk.real > 0.0 else -1
                    lvl = 0.0
                    if vk.real != 0.0:
                        lvl = _friction_level(d0[p] if vk.real > 0.0 else d1[p], vk, rs[p], on_st, vs[p])
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
                    vf = vk  # the velocity the loop reads at the restart
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
                if start_rule == 1:  # the identification's start (ident.simulation): z = 0, ẋ = ẋ_r
                    ei[p] = 0.0
                    v[p] = vr[k]
                    dir_[p] = 1 if vr[k] > 0.0 else (-1 if vr[k] < 0.0 else 0)
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
        sr = (xr[k + 1] - xr[k]) / Ts  # first-order hold of the command, mm/s
        if exact:
            # The exact step: one sub-step of the single mass on the continuous controller (eq. 3.3, 3.2).
            # The linear part of eq. 3.3 advances exactly (:func:`ident.discretisation.foh_blocks`):
            # the command position ``xa`` and drive ``ua`` linear over the sub-step (slopes ``sr``,
            # ``suc``), friction and every effect's input held at their values at the sub-step's
            # start — the in-loop delay and the cyclic force as the applied u less the linear law's,
            # the ψ-share as ``−a2·ψ·(x_w − x)`` (exact for the linear part, first order in the
            # nonlinearity: an exponential-Euler step).  Friction follows Karnopp (:func:`_free_phase`),
            # its reversal and breakaway instants interpolated inside the sub-step; a saturation's
            # clip onset and release (and the integral's freeze) are located inside it the same way
            # (:func:`_saturated_step`), so x̂ is continuous in the parameters.
            # A set's sub-steps run one after the other with its state in registers (the lockstep
            # over sets is per sample here): the chain of one sub-step is short.
            for p in range(P):
                uck = b0[p] * ar[k] + b1[p] * vr[k] + b2[p] * xr[k] + (load[k] if has_load else 0.0)
                suc = (b0[p] * ar[k + 1] + b1[p] * vr[k + 1] + b2[p] * xr[k + 1] + (load[k + 1] if has_load else 0.0)
                       - uck) / Ts
                z = ei[p]
                x = xm[p]
                vv = v[p]
                md = dir_[p]
                for j in range(nsub):
                    xa = xr[k] + sr * (j * h)
                    ua = uck + suc * (j * h)
                    v_old = vv
                    x_old = x
                    if sa_events:
                        # the clip's onset and release located inside the sub-step
                        cyc = cs[p] * sin(tw[p] * x) + cc[p] * cos(tw[p] * x) if cy_force else 0.0 * ua
                        if want_u and j == 0:
                            u0 = _drive(ua, z, x, vv, xw[p], a1[p], a2[p], a3[p], psi[p])
                            c0 = _side(u0, lim[p], lsl[p], vv)
                            OUT_U[p, k] = u0 if c0 == 0 else c0 * lim[p] - lsl[p] * vv
                        z, x, vv, md, xw[p] = _saturated_step(
                            z, x, vv, md, xw[p], h, PH[p], GA[p], GB[p], xa, ua, sr, suc, cyc, a1[p], a2[p], a3[p],
                            psi[p], lim[p], lsl[p], sa_windup, d0[p], d1[p], rs[p], on_st, vs[p])
                        wx = 0.0 * ua  # x_w moved with the step
                    else:
                        ulin = ua + a3[p] * z - a2[p] * x - a1[p] * vv
                        g = 0.0 * ua  # the effects' acceleration, held
                        wx = 1.0 + 0.0 * ua  # the share of the integral's increment taken (_integral_share)
                        held = False  # the drive's output clipped: the loop does not act inside the sub-step
                        if extra[p]:
                            u = ulin - a2[p] * psi[p] * (xw[p] - x)
                            if on_sa:
                                du = h * (a3[p] * (xa - x) - psi[p] * a2[p] * vv)
                                wx = _integral_share(u, du, lim[p], lsl[p], vv, sa_windup)
                                u_free = u
                                u = _clip(u, lim[p], lsl[p], vv)
                                held = u.real != u_free.real
                            if want_u and j == 0:
                                OUT_U[p, k] = u
                            if td_loop:
                                # the drive applies what its loop computed a dead time ago: the
                                # loop's law does not act inside the sub-step either
                                u = _loop_delayed(buf, bi, p, u, dsteps[p], nbuf[p])
                                held = True
                            if cy_force:
                                u -= cs[p] * sin(tw[p] * x) + cc[p] * cos(tw[p] * x)
                            g = u - ulin
                        elif want_u and j == 0:
                            OUT_U[p, k] = ulin
                        if held:
                            # Clipped, or a dead time in the loop, the drive applies a force its
                            # loop's present state does not set: the held-input correction of the
                            # exponential step would let the loop's law act inside the sub-step (a
                            # clipped integral wound up by a3·h·(x_r − x) per sub-step, as large
                            # as the limit itself; a delay shortened by the feedback acting at
                            # once).  The mass under the held force, exact for a force held over
                            # the sub-step (friction and its Karnopp stop as _friction_step), the
                            # integral by the trapezoid.
                            vn = _friction_step(vv, u, h, 1.0, d0[p], d1[p], rs[p], on_st, vs[p])
                            xn = x + 0.5 * h * (vv + vn)
                            z = z + wx * (h * (xa + 0.5 * sr * h) - 0.5 * h * (x + xn))
                            x = xn
                            vv = vn
                            md = _direction(vn)
                        else:
                            z, x, vv, md = _free_phase(z, x, vv, md, h, PH[p], GA[p], GB[p], xa, ua, sr, suc, g,
                                                       a1[p], a2[p], a3[p], d0[p], d1[p], rs[p], on_st, vs[p])
                    xw[p] += wx * (x - x_old)
                    if on_bl:
                        if (x - xt[p]).real > half[p].real:
                            xt[p] = x - half[p]
                        elif (x - xt[p]).real < -half[p].real:
                            xt[p] = x + half[p]
                    if on_rs:
                        q[p], qd[p] = _pair((QF[p, 0], QF[p, 1], QF[p, 2], QF[p, 3]), q[p], qd[p],
                                            qg[p] * div(vv - v_old, h))
                ei[p] = z
                xm[p] = x
                v[p] = vv
                dir_[p] = md
            continue
        for j in range(nsub):
            f = j / nsub
            xrj = xr[k] + f * (xr[k + 1] - xr[k])
            vrj = vr[k] + f * (vr[k + 1] - vr[k])
            # the command's acceleration linear between samples too, as on the exact step
            # (held, its step at every sample costs the kick scheme its second order)
            arj = ar[k] + f * (ar[k + 1] - ar[k])
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
                                vb[p] = vr[k] - 0.5 * ar[k] * Ts if has_warm and warm[k] else 0.0
                            uh = div(b0[p] * (vb[p] - vb_prev[p]), Ts) + b1[p] * vb[p]
                        else:
                            uh = b0[p] * ar[k] + b1[p] * vr[k]
                        uh += b2[p] * xr[k] + a3[p] * ei_new - a2[p] * xp - a1[p] * vfb
                        wh = 1.0 + 0.0 * uh
                        if on_sa:
                            # conditional integration: the share of the increment that keeps the
                            # output inside the clip (its velocity share: x_w over the sample)
                            de = Ts * (xr[k] - xfb)
                            u0 = uh - a3[p] * de
                            wh = _integral_share(u0, a3[p] * de - Ts * psi[p] * a2[p] * vfb, lim[p], lsl[p], vfb,
                                                 sa_windup)
                            ei_new = ei[p] + wh * de
                            uh = _clip(u0 + wh * a3[p] * de, lim[p], lsl[p], vfb)
                        ei[p] = ei_new
                        u = uh if first[p] or two_exact else 0.5 * (u_last[p] + uh)
                        u_last[p] = uh
                        u_h[p] = uh
                        wind_h[p] = wh
                        first[p] = False
                    else:
                        u = u_h[p]
                    wind = 0.0 * u
                    wind_x[p] = wind_h[p]
                else:  # (continuous and not exact: a two-mass drive) the velocity at the kick's instant
                    vk_ = v[p] + 0.5 * h * am[p]
                    u = b0[p] * arj + b1[p] * vrj + b2[p] * xrj + a3[p] * ei[p] - a2[p] * xp - a1[p] * vk_
                    wind = 1.0 + 0.0 * u
                    if on_sa:
                        wind = _integral_share(u, h * (a3[p] * (xrj - xfb) - psi[p] * a2[p] * vk_), lim[p], lsl[p],
                                               vk_, sa_windup)
                        u = _clip(u, lim[p], lsl[p], vk_)
                    wind_x[p] = wind
                if want_u and j == 0:
                    OUT_U[p, k] = u
                if td_loop:
                    u = _loop_delayed(buf, bi, p, u, dsteps[p], nbuf[p])
                if cy_force:
                    u -= cs[p] * sin(tw[p] * xm[p]) + cc[p] * cos(tw[p] * xm[p])
                if two_exact:
                    x_old = xm[p]
                    C = (TM[p, 0], TM[p, 1], TM[p, 2], TM[p, 3], TM[p, 4], TM[p, 5], TM[p, 6], TM[p, 7],
                         TM[p, 8], TM[p, 9], TM[p, 10], TM[p, 11], TM[p, 12])
                    xm[p], v[p], xt[p], vt[p] = _two_mass_step(xm[p], v[p], xt[p], vt[p], u, h + 0.0 * u, mu[p],
                                                               kc[p], cdmp[p], C, d0[p], d1[p], rs[p], on_st, vs[p])
                    xw[p] += wind_x[p] * (xm[p] - x_old)
                    continue
                if two:
                    dl = xm[p] - xt[p]
                    ddl = v[p] - vt[p] + 0.5 * h * (am[p] - at[p])  # at the kick's instant
                    hc = half_c[p]
                    if hc.real > 0.0:  # the contact's mean push over the kick's span, centred on its instant
                        fc = (_contact_push(dl - hc - 0.5 * h * ddl, ddl, kc[p], cdmp[p], h)
                              - _contact_push(-dl - hc + 0.5 * h * ddl, -ddl, kc[p], cdmp[p], h))
                    else:
                        fc = kc[p] * dl + cdmp[p] * ddl
                    # (after a restart the velocities are at the restart's instant: a half kick)
                    hh = 0.5 * h if hk[p] else h
                    vn = v[p] + div(hh * (u - fc), mu[p])
                    mt = 1.0 - mu[p]
                    vtn = _friction_step(vt[p], fc, hh, mt, d0[p], d1[p], rs[p], on_st, vs[p])
                    am[p] = div(vn - v[p], hh)
                    at[p] = div(vtn - vt[p], hh)
                    hk[p] = False
                    v[p] = vn
                    vt[p] = vtn
                    xm[p] += h * vn
                    xt[p] += h * vtn
                    # the integral by the midpoint of the feedback's move
                    if wind.real != 0.0:  # (the sampled controller's integral moves at samples only)
                        ei[p] += wind * h * (xrj + 0.5 * h * sr - xfb - 0.5 * h * (vn if fb_motor else vtn))
                    xw[p] += wind_x[p] * h * vn
                    continue
                vn = _friction_step(v[p], u, h, 1.0, d0[p], d1[p], rs[p], on_st, vs[p])
                acc = div(vn - v[p], h)
                v[p] = vn
                xm[p] += h * vn
                if wind.real != 0.0:
                    ei[p] += wind * h * (xrj - xfb)
                xw[p] += wind_x[p] * h * vn
                if on_bl:
                    if (xm[p] - xt[p]).real > half[p].real:
                        xt[p] = xm[p] - half[p]
                    elif (xm[p] - xt[p]).real < -half[p].real:
                        xt[p] = xm[p] + half[p]
                if on_rs:  # the kick is centred on the sub-step's start here: the filter takes Euler's step
                    qdd = -2.0 * zr[p] * wr[p] * qd[p] - wr[p] * wr[p] * q[p] - kr[p] * acc
                    qd[p] += h * qdd
                    q[p] += h * qd[p]
    if on_td and not td_loop:
        for p in range(P):
            if tau[p].real > 0.0:
                _delay_output(OUT[p], starts, tau[p], Ts)


def compiled_in_this_process() -> bool:
    """Whether the simulator kernel was compiled in this process rather than loaded from
    numba's on-disk cache: the first run after an install (or a change of the kernel) spends
    about 40 s per number type compiling it, in whichever stage first simulates."""
    stats = getattr(_kernel_many, "stats", None)  # none when numba's JIT is switched off
    return bool(stats is not None and stats.cache_misses)


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
          u_out: np.ndarray | None = None, load: np.ndarray | None = None, start_rule: int = 0) -> np.ndarray:
    """:func:`_kernel_many` on P sets of parameters of number type ``dtype`` (float or complex);
    rows that are no model to simulate (:func:`_runnable`) are NaN.  ``u_out`` (N,), one
    runnable set only (:func:`~ident.diagnosis.augmented.simulate_augmented` checks): filled
    with the u the set applied.  ``load`` (N,), mm/s²: an external acceleration added to the
    command drive (:class:`ident.simulation.FreeRun`'s disturbance).
    ``start_rule``: 0 a segment starts at rest (or warm), 1 as the identification's free run
    does (:mod:`ident.simulation`: z = 0, ẋ = ẋ_r)."""
    x_r = np.ascontiguousarray(x_r, dtype=float)
    n = x_r.size
    if load is not None and np.shape(load) != (n,):  # the kernel reads an empty load as none
        raise ValueError(f"load has shape {np.shape(load)}, the command {n} samples")
    TH = np.ascontiguousarray(thetas, dtype=dtype).reshape(-1, 8)
    E = np.ascontiguousarray(eps, dtype=dtype).reshape(-1, N_EP)
    ok = _runnable(TH, E)
    y = np.empty((int(np.count_nonzero(ok)), n), dtype=dtype)
    out_u = np.empty((y.shape[0], n) if u_out is not None else (0, 0), dtype=dtype)
    if y.shape[0]:
        _kernel_many(x_r, np.ascontiguousarray(derivs[0], dtype=float), np.ascontiguousarray(derivs[1], dtype=float),
                     np.ascontiguousarray(x0, dtype=dtype), np.ascontiguousarray(starts, dtype=np.bool_),
                     *_warm_arrays(warm, n, dtype), float(Ts), int(nsub), np.ascontiguousarray(TH[ok]),
                     np.ascontiguousarray(flags, dtype=np.int64), np.ascontiguousarray(E[ok]), _padded_modes(modes),
                     y, out_u, np.zeros(0) if load is None else np.ascontiguousarray(load, dtype=float),
                     int(start_rule))
        if u_out is not None:
            u_out[:] = out_u[0]
    if ok.all():
        return y
    out = np.full((TH.shape[0], n), np.nan, dtype=dtype)
    out[ok] = y
    return out


def _warm_arrays(warm: tuple[np.ndarray, np.ndarray, np.ndarray] | None, n: int,
                 dtype=float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The kernel's (mask, v, a) of warm restarts, v and a of the run's number type (a
    complex run differentiates the restart state too): none when ``warm`` is None (v, a
    never read then)."""
    if warm is None:  # empty arrays: the kernel reads no warm restart
        unused = np.zeros(0, dtype=dtype)
        return np.zeros(0, dtype=np.bool_), unused, unused
    return (np.ascontiguousarray(warm[0], dtype=np.bool_), np.ascontiguousarray(warm[1], dtype=dtype),
            np.ascontiguousarray(warm[2], dtype=dtype))

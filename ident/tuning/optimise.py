"""Gains that minimise a predicted figure under the margins: a deterministic grid over designs.

Every candidate is a pole placement on the recovered plant, the same for every axis so the
axes come out matched (docs/tuning.md, "The search"): the continuous closed loop of
eq. 3.4 / 3.5 is given the characteristic polynomial

    s³ + a1 s² + a2 s + a3 = (s + r·ω)(s² + 2ζω s + ω²)                      (eq. 3.7)

and the gains solve eq. 3.5 (PID: Kd = (a1 − bj)/kj, Kp = a2/kj, Ki = a3/kj) or eq. 3.4
(P-PI: Kd = (a1 − bj)/kj, Kp the smaller root of Kd·Kp² − (a2/kj)·Kp + a3/kj = 0,
Ki = a3/(kj·Kp)).  The feed-forwards are a fraction φ of the plant inverse (PID:
Kv = φ·bj/kj, Ka = φ/kj, so b0 = φ and b1 = kj·Kd + φ·bj: G_track = 1 at φ = 1; P-PI:
Kv = φ/Kp, Ka = φ/(kj·Kp·Kd), so b0 = φ and b2 = a2 − (1 − φ)·kj·Ki; the P-PI structure
cannot also make b1 = a1, which the sampled prediction accounts for).  For LinuxCNC's pid
a lead λ (:data:`LEADS`) may be conceded: FF1 −= P·λ, FF2 −= D·λ, FF0 = −I·λ (docs/tuning.md).

The search: ω over :data:`OMEGA_HZ`, ζ over :data:`ZETAS`, r over :data:`RATIOS` (fixed
grids, no random start, no clock); a feedback design is admissible when every axis keeps
the phase and gain margins (:mod:`ident.tuning.margins`); each admissible design is tried
with every φ of :data:`FF_FRACTIONS` (and λ), kept when no axis overshoots a 1 mm move, and scored;
the proposal is the lowest predicted figure whose run keeps the output within its limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from ident.tuning.controllers import Gains
from ident.tuning.margins import GAIN_MARGIN_DB, OVERSHOOT_LIMIT, PHASE_MARGIN_DEG, Margins, margins, step_overshoot
from ident.tuning.plant import Plant

__all__ = ["Design", "design_gains", "admissible", "search", "OMEGA_HZ", "ZETAS", "RATIOS", "FF_FRACTIONS",
           "LEADS", "violations"]

OMEGA_HZ = tuple(float(v) for v in np.geomspace(5.0, 60.0, 8))
ZETAS = (0.8, 1.0)
RATIOS = (0.1, 0.4, 1.0)
FF_FRACTIONS = (0.0, 0.5, 0.8, 0.9, 0.95, 1.0, 1.1, 1.2)
#: Leads tried, in servo periods, where the form has FF0 to complete them (LinuxCNC pid).
LEADS = (0.0, 1.0, 2.0, 3.0)


@dataclass(frozen=True)
class Design:
    """One point of the search: pair frequency [Hz], damping, real-pole ratio, feed-forward fraction."""

    omega_hz: float
    zeta: float
    ratio: float
    ff: float
    lead: float = 0.0  # s: the lag the feed-forward concedes (module docstring)


def design_gains(template: Gains, plant: Plant, d: Design) -> Gains | None:
    """The gains of design ``d`` on ``plant`` in the form of ``template`` (module docstring); None if unrealisable."""
    kind = template.law()[0]
    w = 2 * math.pi * d.omega_hz
    p = d.ratio * w
    a1, a2, a3 = p + 2 * d.zeta * w, w * w + 2 * d.zeta * w * p, p * w * w
    kj, bj = plant.kj, plant.bj
    Kd = (a1 - bj) / kj
    if Kd <= 0:
        return None
    if kind == "pid":
        Kp, Ki = a2 / kj, a3 / kj
        # x = x_r delayed by the lead is what the loop settles to: the feedback it then sees
        # (P·lead·ẋ_r, D·lead·ẍ_r, I·lead·x_r) is taken off the feed-forwards
        Kv, Ka = d.ff * bj / kj - Kp * d.lead, d.ff / kj - Kd * d.lead
        return template.with_law(Kp, Ki, Kd, Kv, Ka, -Ki * d.lead)
    else:
        disc = (a2 / kj) ** 2 - 4 * Kd * a3 / kj
        if disc < 0:
            return None
        Kp = (a2 / kj - math.sqrt(disc)) / (2 * Kd)
        if Kp <= 0:
            return None
        Ki = a3 / (kj * Kp)
        Kv, Ka = d.ff / Kp, d.ff / (kj * Kp * Kd)
    return template.with_law(Kp, Ki, Kd, Kv, Ka)


def violations(gains: Gains, plant: Plant, Ts: float, resonance=None) -> tuple[Margins, float, list[str]]:
    """(margins, step overshoot, what is violated in words) of one axis."""
    m = margins(gains, plant, Ts, resonance)
    ov = step_overshoot(gains, plant, Ts)
    bad = []
    if not m.phase_margin_deg >= PHASE_MARGIN_DEG:
        bad.append(f"phase margin {m.phase_margin_deg:.1f}° < {PHASE_MARGIN_DEG:g}°")
    if not m.gain_margin_db >= GAIN_MARGIN_DB:
        bad.append(f"gain margin {m.gain_margin_db:.1f} dB < {GAIN_MARGIN_DB:g} dB")
    if not ov <= OVERSHOOT_LIMIT:
        bad.append("unstable step response" if not math.isfinite(ov)
                   else f"step overshoot {100 * ov:.1f} % > {100 * OVERSHOOT_LIMIT:g} %")
    return m, ov, bad


def _margin_bad(gains: Gains, plant: Plant, Ts: float, resonance) -> bool:
    m = margins(gains, plant, Ts, resonance)
    return not (m.phase_margin_deg >= PHASE_MARGIN_DEG and m.gain_margin_db >= GAIN_MARGIN_DB)


def admissible(templates: Mapping[str, Gains], plants: Mapping[str, Plant], Ts: float,
               resonances: Mapping[str, tuple[float, float] | None]) -> list[Design]:
    """Feedback designs that every axis realises within the phase and gain margins, in grid order."""
    out = []
    for w in OMEGA_HZ:
        for z in ZETAS:
            for r in RATIOS:
                d = Design(w, z, r, 1.0)
                ok = True
                for a, tmpl in templates.items():
                    g = design_gains(tmpl, plants[a], d)
                    if g is None or _margin_bad(g, plants[a], Ts, resonances.get(a)):
                        ok = False
                        break
                if ok:
                    out.append(d)
    return out


def search(templates: Mapping[str, Gains], plants: Mapping[str, Plant], Ts: float,
           score: Callable[[dict[str, Gains]], tuple[float, float]],
           resonances: Mapping[str, tuple[float, float] | None] | None = None) -> tuple[Design, dict[str, Gains], float] | None:
    """The best admissible design (module docstring).

    ``score(gains per axis) -> (figure, largest |u| / limit)``; a design whose run needs
    more than the output limit (ratio > 1) is not proposed.  None when nothing is admissible.
    """
    resonances = resonances or {}
    best: tuple[float, Design, dict[str, Gains]] | None = None

    def consider(d: Design) -> None:
        nonlocal best
        gains = {a: design_gains(t, plants[a], d) for a, t in templates.items()}
        if any(g is None for g in gains.values()):
            return
        if any(violations(g, plants[a], Ts, resonances.get(a))[2] for a, g in gains.items()):
            return
        fig, u_ratio = score(gains)
        if u_ratio <= 1.0 and math.isfinite(fig) and (best is None or fig < best[0]):
            best = (fig, d, gains)

    forms = {t.form for t in templates.values()}
    leads = [k * Ts for k in LEADS] if forms == {"linuxcnc-pid"} else [0.0]
    for d in admissible(templates, plants, Ts, resonances):
        for ff in FF_FRACTIONS:
            for lead in leads:
                consider(Design(d.omega_hz, d.zeta, d.ratio, ff, lead))
    if best is None:
        return None
    return best[1], best[2], best[0]

"""Benchmark cases: a random drive with ONE effect of SPEC §7 (or none), from a seed.

Every case draws (``numpy.random.default_rng([seed, sub, class index])``) a plant, a controller tuned
for it, sensors, and the magnitude of its one effect from :data:`RANGES`.  ``sub`` is the
redraw index of the calibration step (benchmarks/bench_independent.py).  The loop closure
(semi/full) and controller kind (ppi/pid) are given by the caller so every class has both.

Common drive ranges (all classes; ``lu`` = log-uniform, ``u`` = uniform):

- motor equivalent mass ``m_m`` u(60, 400) kg, table ``m_t`` u(80, 400) kg
- Coulomb friction ``F_c+`` = u(0.02, 0.08) x ``m_tot`` x 2 m/s²; ``F_c-`` = ``F_c+`` x u(0.7, 1.3);
  ``F_s = F_c`` (no Stribeck hump) except in class stribeck; viscous ``B_t`` such that
  ``B_t`` x 0.2 m/s = u(0.01, 0.05) x ``m_tot`` x 2 m/s²; Karnopp band 1 µm/s
- P-PI: velocity bandwidth ``f_v`` u(30, 100) Hz, ``Kp`` u(10, 40) 1/s (<= 2 pi f_v / 5);
  PID: triple pole ``w`` u(50, 130) rad/s;  velocity FF ``kvff`` = 0 (half the drives) or
  u(0.6, 1); acceleration FF ``kaff`` u(0, 1) when kvff > 0; velocity filter u(300, 800) Hz
- encoder / scale resolution from {0.1, 0.2, 0.5, 1} µm, noise sd u(0, 0.3) µm
- force limit: 10 x (m_tot x 2 m/s² + F_c) (never reached) except in class saturation
- plant rigid, capture = the feedback sensor, no dead time, except as the class says.

Effect ranges (:data:`RANGES`):

- backlash: two-mass with a gap ``g`` lu(0.05, 0.8) mm (semi-closed) or
  lu(0.01, 0.2) mm (full-closed: the integrator hunts across the gap), contact stiffness
  giving a contact mode u(150, 300) Hz with damping ratio u(0.1, 0.3); semi-closed drives are
  captured on a table scale (the motor encoder does not see the gap).
- stribeck: heavier guideway friction ``F_c+`` u(0.1, 0.3) x m_tot x 2 m/s², ``F_s±/F_c±``
  u(2, 6) each direction, ``v_s`` lu(1, 20) mm/s, exponent 1 or 2; softer loops (P-PI ``f_v``
  u(15, 40) Hz, PID ``w`` u(30, 70) rad/s), where stick-slip shows.
- resonance: two-mass, free mode ``f`` u(15, 150) Hz (semi-closed) or u(40, 150) Hz
  (full-closed), damping ratio u(0.01, 0.05); full-closed drives get ``f_v <= 0.8 f``
  (PID ``3w <= 2 pi 0.8 f``); semi-closed drives are captured on the table scale.
  (Version 1 capped full-closed drives at ``0.5 f``: the loop then damped the mode out of
  sight and full-closed P-PI cases did not calibrate on the report seeds; raised to 0.8 on the
  tuning seeds during the first report run.)
- time_delay: ``tau`` lu(1, 8) ms (integer + fractional samples) at actuation or in the
  feedback (half each); the drive is tuned for it: P-PI ``f_v`` at most the bandwidth that
  keeps a 30° phase margin with the dead time, the hold, the backward-difference velocity
  and the velocity filter (:func:`ppi_bandwidth_for_margin`), PID ``3w <= 2 pi 0.2 / tau``.
  (Version 1 capped P-PI at ``f_v <= 0.2 / tau``, which leaves no margin once the hold,
  the velocity difference and the filter are counted: five of the six P-PI cases of the
  tuning seeds that were not named a dead time sat at their amplifier's force limit in
  54-62 % of the samples, unstable drives in a limit cycle, not drives with a dead time;
  replaced by version 2 after the report seeds had been run on version 1.)
- cyclic_error: cogging/force ripple of amplitude u(0.3, 1.0) x m_tot x 2 m/s² and period
  u(2, 10) mm (any closure), or (semi-closed, half of them) a lead-screw pitch error of
  amplitude lu(20, 200) µm and period u(2, 10) mm seen on a table scale.
- saturation: force limit u(0.95, 1.2) x the sustained force of the fastest moves,
  ``m_tot a_max + F_c+ + B_t 0.2 m/s`` (the limit is reached in the fastest accelerations,
  where the loop adds its transient to the feed-forward); feed-forward on (kvff u(0.6, 1),
  kaff u(0.5, 1)).  Well below that the integrator (no anti-windup) runs away after a
  saturated acceleration (metres of error), and the calibration rejects the draw.
  (Version 1 of this class, limit u(0.85, 0.98) x the peak force of the unlimited drive,
  clipped only short spikes -- invisible -- or ran away; it calibrated on none of the report
  seeds and was replaced, on the tuning seeds, during the first report run.)
- none: the common drive only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from .controller import tune_pid, tune_ppi
from .plant import PlantParams
from .sensors import SensorParams
from .simulate import TS, Drive, record

CLASSES = ["backlash", "stribeck", "resonance", "time_delay", "cyclic_error", "saturation", "none"]
A_MAX = 2.0  # m/s², the programs' acceleration limit (gcode_gen a_max 2000 mm/s²)

RANGES = {
    "backlash": {"gap_mm_semi": (0.05, 0.8, "log"), "gap_mm_full": (0.01, 0.2, "log"), "contact_hz": (150, 300),
                 "contact_damping": (0.1, 0.3)},
    "stribeck": {"coulomb_rel": (0.1, 0.3), "static_to_coulomb_ratio": (2.0, 6.0),
                 "stribeck_velocity_mm_s": (1.0, 20.0, "log"),
                 "exponent": (1, 2)},
    "resonance": {"freq_hz_semi": (15, 150), "freq_hz_full": (40, 150), "damping": (0.01, 0.05)},
    "time_delay": {"delay_s": (0.001, 0.008, "log"), "at": ("actuation", "feedback")},
    "cyclic_error": {"ripple_rel": (0.3, 1.0), "pitch_amp_mm": (0.02, 0.2, "log"), "period_mm": (2, 10)},
    "saturation": {"limit_rel_of_sustained": (0.95, 1.2), "kvff": (0.6, 1.0), "kaff": (0.5, 1.0)},
    "none": {},
}


#: Phase margin (rad) a P-PI velocity loop is tuned to keep with its dead time: 30°, the
#: low end of how drives are commissioned.  45°, the textbook figure, hid the dead time
#: (held-out base fits 96-99.9 %: two of the tuning seeds' five P-PI cases never
#: calibrated in 40 draws); chosen for the calibration window, not for a score.
PHASE_MARGIN = math.pi / 6


def ppi_bandwidth_for_margin(tau: float, f_vf: float, margin: float = PHASE_MARGIN, Ts: float = TS) -> float:
    """Largest velocity bandwidth f_v (Hz) of :func:`tune_ppi` that keeps ``margin`` with a dead time ``tau`` (s).

    At the crossover ω = 2π f_v the velocity loop's open-loop phase is −90° (the mass)
    − atan(1/4) (the PI corner at f_v/4) − ω(τ + Ts) (the dead time, and half a sample each
    for the hold and the backward-difference velocity) − atan(ω/ω_f) (the velocity filter
    at ``f_vf`` Hz); the margin is 180° plus that.  Solved for ω by bisection.
    """
    budget = math.pi / 2 - math.atan(0.25) - margin
    lag = lambda w: w * (tau + Ts) + math.atan(w / (2 * math.pi * f_vf))  # noqa: E731
    lo, hi = 0.0, budget / (tau + Ts)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if lag(mid) <= budget else (lo, mid)
    return lo / (2 * math.pi)


@dataclass(frozen=True)
class Case:
    cls: str
    seed: int
    sub: int
    closure: str             # "semi" or "full"
    kind: str                # "ppi" or "pid"
    drive: Drive
    truth: dict = field(default_factory=dict)
    id_seed: int = 0
    val_seed: int = 0

    @property
    def name(self) -> str:
        return f"s{self.seed}.{self.sub}"


def draw_case(cls: str, seed: int, sub: int = 0, closure: str = "semi", kind: str = "ppi") -> Case:
    """The case of class ``cls`` drawn from ``(seed, sub)``; the same arguments give the same case."""
    if cls not in CLASSES:
        raise ValueError(f"unknown class {cls!r}")
    rng = np.random.default_rng([seed, sub, CLASSES.index(cls)])
    u = lambda a, b: float(rng.uniform(a, b))                               # noqa: E731
    lu = lambda a, b: float(np.exp(rng.uniform(np.log(a), np.log(b))))     # noqa: E731

    m_m, m_t = u(60, 400), u(80, 400)
    m = m_m + m_t
    f_ref = m * A_MAX
    fc_pos = u(0.02, 0.08) * f_ref
    fc_neg = fc_pos * u(0.7, 1.3)
    b_t = u(0.01, 0.05) * f_ref / 0.2
    plant = PlantParams(m_m=m_m, m_t=m_t, fc_pos=fc_pos, fc_neg=fc_neg, fs_pos=fc_pos, fs_neg=fc_neg,
                        v_s=1e-3, delta=2.0, b_t=b_t, b_m=0.0, dv=1e-6)
    res = [1e-7, 2e-7, 5e-7, 1e-6]
    sens = SensorParams(q_enc=res[int(rng.integers(4))], q_scale=res[int(rng.integers(4))],
                        noise_sd=u(0, 3e-7), full_closed=closure == "full")
    f_v, kp, w = u(30, 100), u(10, 40), u(50, 130)
    kvff = 0.0 if rng.random() < 0.5 else u(0.6, 1.0)
    kaff = u(0.0, 1.0) if kvff > 0 else 0.0
    f_vf = u(300, 800)
    f_max = 10.0 * (f_ref + fc_pos)
    truth: dict = {}

    if cls == "backlash":
        gap = (lu(0.05, 0.8) if closure == "semi" else lu(0.01, 0.2)) * 1e-3
        fcon, zc = u(150, 300), u(0.1, 0.3)
        mu = m_m * m_t / m
        k = mu * (2 * math.pi * fcon) ** 2
        plant = replace(plant, two_mass=True, gap=gap, k_link=k, c_link=2 * zc * math.sqrt(k * mu))
        sens = replace(sens, capture_table=closure == "semi")
        truth = {"gap_mm": gap * 1e3}
    elif cls == "stribeck":
        fc_pos = u(0.1, 0.3) * f_ref
        fc_neg = fc_pos * u(0.7, 1.3)
        r_pos, r_neg = u(2.0, 6.0), u(2.0, 6.0)
        f_v = u(15, 40)
        w = u(30, 70)
        v_s, delta = lu(1.0, 20.0) * 1e-3, float(rng.choice([1.0, 2.0]))
        plant = replace(plant, fc_pos=fc_pos, fc_neg=fc_neg, fs_pos=fc_pos * r_pos, fs_neg=fc_neg * r_neg,
                        v_s=v_s, delta=delta)
        truth = {"static_to_coulomb_ratio": 0.5 * (r_pos + r_neg), "stribeck_velocity_mm_s": v_s * 1e3,
                 "exponent": delta}
    elif cls == "resonance":
        f, z = (u(15, 150) if closure == "semi" else u(40, 150)), u(0.01, 0.05)
        mu = m_m * m_t / m
        k = mu * (2 * math.pi * f) ** 2
        plant = replace(plant, two_mass=True, k_link=k, c_link=2 * z * math.sqrt(k * mu))
        if closure == "full":
            f_v = min(f_v, 0.8 * f)
            w = min(w, 2 * math.pi * 0.8 * f / 3.0)
        sens = replace(sens, capture_table=closure == "semi")
        truth = {"freq_hz": f, "damping": z}
    elif cls == "time_delay":
        tau = lu(0.001, 0.008)
        at = "actuation" if rng.random() < 0.5 else "feedback"
        sens = replace(sens, delay_act=tau if at == "actuation" else 0.0, delay_fb=tau if at == "feedback" else 0.0)
        f_v = min(f_v, ppi_bandwidth_for_margin(tau, f_vf))
        w = min(w, 2 * math.pi * 0.2 / tau / 3.0)
        truth = {"delay_s": tau, "at": at}
    elif cls == "cyclic_error":
        period = u(2, 10) * 1e-3
        phase = u(0, 2 * math.pi)
        if closure == "semi" and rng.random() < 0.5:
            amp = lu(0.02, 0.2) * 1e-3
            sens = replace(sens, pitch_amp=amp, pitch_period=period, pitch_phase=phase, capture_table=True)
            truth = {"period_mm": period * 1e3, "amplitude_mm": amp * 1e3, "kind": "pitch"}
        else:
            amp = u(0.3, 1.0) * f_ref
            plant = replace(plant, ripple_amp=amp, ripple_period=period, ripple_phase=phase)
            truth = {"period_mm": period * 1e3, "amplitude_N": amp, "kind": "ripple"}
    elif cls == "saturation":
        rel = u(0.95, 1.2)          # of the sustained force of the fastest moves
        f_max = rel * (f_ref + fc_pos + 0.2 * b_t)
        kvff, kaff = u(0.6, 1.0), u(0.5, 1.0)   # feed-forward on: the limit clips the acceleration force
        truth = {"limit_N": f_max, "limit_mm_s2": f_max / m * 1e3, "limit_rel": rel}

    kp = min(kp, 2 * math.pi * f_v / 5.0)
    common = dict(kvff=kvff, kaff=kaff, f_max=f_max, f_vf=f_vf)
    if kind == "ppi":
        ctrl = tune_ppi(m, f_v, kp, **common)
    else:
        ctrl = tune_pid(m, w, b_ff=b_t, **common)
    drive = Drive(plant=plant, controller=ctrl, sensors=sens,
                  meta={"f_v": f_v, "kp": kp, "w": w, "m_total": m})
    base = 1_000_000 + 64 * seed + 2 * sub
    return Case(cls=cls, seed=seed, sub=sub, closure=closure, kind=kind, drive=drive, truth=truth,
                id_seed=base, val_seed=base + 1)


def case_recordings(case: Case):
    """(identification, validation) recordings of a case: two random programs, the same drive."""
    import gcode_gen

    meta = {"simulator": "independent_bench", "case": case.name, "class": case.cls,
            "closure": case.closure, "controller": case.kind}
    rec = record(case.drive, gcode_gen.generate(["X"], seed=case.id_seed), seed=case.id_seed, metadata=meta)
    val = record(case.drive, gcode_gen.generate(["X"], seed=case.val_seed), seed=case.val_seed, metadata=meta)
    return rec, val

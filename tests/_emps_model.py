"""A physical model of the EMPS drive, fitted from DATA_EMPS.mat, to make recordings with known loads.

EMPS (Janot, Gautier, Brunot 2019; ``shared/data/emps/README.md``) is a ball-screw axis
under a cascade of a proportional position loop and a proportional velocity loop computed
by a dSPACE system at 1 kHz.  The load side is the rigid-body model of the benchmark::

    M·q̈ = gtau·vir − Fv·q̇ − Fc(q̇) − offset + f_ext(t)        Fc = Fc⁺ (q̇ > 0), −Fc⁻ (q̇ < 0)

and the controller, checked against the recorded voltage (``controller_residual``)::

    vir(k) = kv·(kp·(qg(k) − qm(k)) − (qm(k) − qm(k−1))/Ts)       held over one sample (ZOH)

M, Fv, Fc±, offset are fitted by least squares from the recorded ``vir`` and ``gtau``
(q̇, q̈ from ``qm`` by a zero-phase low-pass and central differences).  The closed loop is
then driven by the recorded reference ``qg`` (:func:`simulate`), with an optional external
force f_ext(t) in N (:func:`pulses`, :func:`steps`, :func:`sinusoidal_load`), and read
through an encoder of the real one's resolution (50 nm).  :func:`recording` returns it as a
``core.Recording`` in mm.  The recording with real force pulses is held out of the tests:
these recordings stand in for it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import signal

from core.recording import Recording

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "emps" / "DATA_EMPS.mat"
#: The encoder resolution of the real recording: every step of qm is a multiple of 50 nm, m.
ENCODER_M = 5e-8
#: Low-pass (Hz) of qm before differentiating for the friction fit: above ~40 Hz q̈ is noise.
FIT_LOWPASS_HZ = 40.0
#: Edge samples the zero-phase filter's start-up disturbs, left out of the fit.
FIT_EDGE = 50


@dataclass(frozen=True)
class EmpsData:
    """The recording of DATA_EMPS.mat: time (s), reference and motor position (m), voltage (V), gains."""

    t: np.ndarray
    qg: np.ndarray
    qm: np.ndarray
    vir: np.ndarray
    kp: float
    kv: float
    gtau: float

    @property
    def Ts(self) -> float:
        return float(np.median(np.diff(self.t)))


@dataclass(frozen=True)
class EmpsModel:
    """The rigid-body drive and its controller (SI units: kg, N/(m/s), N, 1/s, V/(m/s), N/V)."""

    M: float
    Fv: float
    Fc_pos: float
    Fc_neg: float
    offset: float
    kp: float
    kv: float
    gtau: float


def load(path: Path = DATA) -> EmpsData:
    """DATA_EMPS.mat as arrays (time starting at 0)."""
    from scipy.io import loadmat

    m = loadmat(path)
    t = m["t"].ravel()
    return EmpsData(t - t[0], m["qg"].ravel(), m["qm"].ravel(), m["vir"].ravel(),
                    float(m["kp"].item()), float(m["kv"].item()), float(m["gtau"].item()))


def controller_voltage(qg: np.ndarray, qm: np.ndarray, kp: float, kv: float, Ts: float) -> np.ndarray:
    """vir of the P position + P velocity cascade, velocity by backward difference of qm, V."""
    v = np.diff(qm, prepend=qm[0]) / Ts
    return kv * (kp * (qg - qm) - v)


def controller_residual(data: EmpsData) -> float:
    """Rms of recorded vir minus :func:`controller_voltage` over rms vir: checks the loop's structure."""
    r = data.vir - controller_voltage(data.qg, data.qm, data.kp, data.kv, data.Ts)
    return float(np.std(r[1:]) / np.std(data.vir))


def fit(data: EmpsData) -> tuple[EmpsModel, float]:
    """(M, Fv, Fc±, offset by least squares on gtau·vir = M·q̈ + Fv·q̇ + Fc(q̇) + offset, rms force residual N)."""
    Ts = data.Ts
    b, a = signal.butter(4, FIT_LOWPASS_HZ * 2 * Ts)
    qf = signal.filtfilt(b, a, data.qm)  # zero phase: q̇, q̈ stay aligned with vir
    v = np.gradient(qf, Ts)
    acc = np.gradient(v, Ts)
    A = np.column_stack([acc, v, (v > 0).astype(float), -(v < 0).astype(float), np.ones_like(v)])
    u = data.gtau * data.vir
    keep = slice(FIT_EDGE, -FIT_EDGE)
    coef, *_ = np.linalg.lstsq(A[keep], u[keep], rcond=None)
    rms = float(np.std(u[keep] - A[keep] @ coef))
    M, Fv, Fc_pos, Fc_neg, offset = (float(c) for c in coef)
    return EmpsModel(M, Fv, Fc_pos, Fc_neg, offset, data.kp, data.kv, data.gtau), rms


def _friction_step(m: EmpsModel, F: float, v: float, h: float) -> float:
    """Velocity after one sub-step of length h (semi-implicit Euler, Karnopp stick at v = 0).

    ``F`` is the driving force gtau·vir − offset + f_ext.  At rest the Coulomb friction
    takes any value in [−Fc⁻, Fc⁺] that holds the axis; moving, a step that would cross
    zero velocity stops at zero instead (the friction cannot drive the motion back).
    """
    if v == 0.0:
        if -m.Fc_neg <= F <= m.Fc_pos:
            return 0.0
        fc = m.Fc_pos if F > 0 else -m.Fc_neg
        return h * (F - fc) / m.M
    fc = m.Fc_pos if v > 0 else -m.Fc_neg
    v1 = v + h * (F - m.Fv * v - fc) / m.M
    return 0.0 if v1 * v < 0.0 else v1


def simulate(m: EmpsModel, qg: np.ndarray, Ts: float, f_ext: np.ndarray | None = None, *, q0: float | None = None,
             substeps: int = 8, encoder_m: float = ENCODER_M, noise_m: float = 0.0,
             seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The closed loop driven by the reference ``qg`` (m): (measured qm, voltage vir), both (N,).

    The controller samples the encoder once per Ts and holds vir (ZOH); the load is
    integrated over ``substeps`` sub-steps per sample with f_ext (N, per sample) held too.
    ``encoder_m`` quantises the measured position (0: none); ``noise_m`` adds white noise, m rms.
    """
    n = qg.size
    f = np.zeros(n) if f_ext is None else np.asarray(f_ext, dtype=float)
    rng = np.random.default_rng(seed)
    noise = rng.normal(0.0, noise_m, n) if noise_m > 0 else np.zeros(n)
    q = float(qg[0] if q0 is None else q0)
    v = 0.0
    h = Ts / substeps
    qm = np.empty(n)
    vir = np.empty(n)
    prev = None
    for k in range(n):
        meas = (round(q / encoder_m) * encoder_m if encoder_m > 0 else q) + noise[k]
        vel = 0.0 if prev is None else (meas - prev) / Ts
        u = m.kv * (m.kp * (float(qg[k]) - meas) - vel)
        qm[k], vir[k], prev = meas, u, meas
        F = m.gtau * u - m.offset + float(f[k])
        for _ in range(substeps):
            v = _friction_step(m, F, v, h)
            q += h * v
    return qm, vir


def pulses(t: np.ndarray, amplitude_n: float, width_s: float, period_s: float, start_s: float = 1.0,
           stop_s: float | None = None) -> np.ndarray:
    """Rectangular force pulses, N: ``amplitude_n`` for ``width_s`` every ``period_s`` from ``start_s``."""
    stop = float(t[-1]) if stop_s is None else stop_s
    phase = np.mod(t - start_s, period_s)
    return np.where((t >= start_s) & (t <= stop) & (phase < width_s), amplitude_n, 0.0)


def pulse_windows(t: np.ndarray, width_s: float, period_s: float, start_s: float = 1.0,
                  stop_s: float | None = None) -> list[tuple[float, float]]:
    """(start, end) s of each pulse of :func:`pulses`."""
    stop = float(t[-1]) if stop_s is None else stop_s
    return [(s, s + width_s) for s in np.arange(start_s, stop, period_s) if s + width_s <= t[-1]]


def steps(t: np.ndarray, times_s: list[float], levels_n: list[float]) -> np.ndarray:
    """A piecewise-constant load, N: ``levels_n[i]`` from ``times_s[i]`` on (0 before the first)."""
    f = np.zeros_like(t, dtype=float)
    for ts, lv in zip(times_s, levels_n):
        f[t >= ts] = lv
    return f


def sinusoidal_load(t: np.ndarray, amplitude_n: float, period_s: float) -> np.ndarray:
    """A slowly varying load ``amplitude_n·sin(2πt/period_s)``, N."""
    return amplitude_n * np.sin(2 * np.pi * t / period_s)


def recording(t: np.ndarray, qg: np.ndarray, qm: np.ndarray) -> Recording:
    """Reference and measured position (m) as a one-axis ``Recording`` in mm, axis X."""
    return Recording.from_arrays(t=t, commanded={"X": qg * 1e3}, actual={"X": qm * 1e3})


def tracking_fit_pct(qg: np.ndarray, qm_true: np.ndarray, qm_sim: np.ndarray) -> float:
    """SPEC §5 tracking-error fit of a simulated against a recorded position, %."""
    e = qg - qm_true
    return 100.0 * (1.0 - float(np.linalg.norm((qg - qm_sim) - e)) / float(np.linalg.norm(e - e.mean())))

"""Position sensors: motor encoder and table linear scale, as the drive and a capture see them.

- motor encoder: ``x_m`` (linear equivalent), quantised to ``q_enc``;
- linear scale on the table: ``x_t + e_p(x_m)``, quantised to ``q_scale``, where
  ``e_p(x_m) = A_p sin(2 pi x_m / P_p + phi_p)`` is the lead-screw pitch error carried to
  the table (a position-domain cyclic error: the motor encoder does not see it).
- white noise of standard deviation ``noise_sd`` is added before quantisation, so every
  reading lies on its sensor's grid: ``q round((x + n) / q)``.

Loop closure: semi-closed (position and velocity feedback from the motor encoder) or
full-closed (position loop on the table scale, velocity loop on the motor encoder).
Capture: by default what the loop's feedback sensor reports; ``capture_table`` records the
table scale instead (a semi-closed machine fitted with a scale for the identification run,
the only way lost motion, the table mode or a pitch error of a semi-closed drive shows).
Dead time: ``delay_act`` (s) between the control law and the force, ``delay_fb`` (s) in the
feedback path (the drive -- and a capture of the feedback -- reads ``x(t - delay_fb)``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

Q_ENC, Q_SCALE, NOISE_SD, PITCH_A, PITCH_P, PITCH_PHI, FULL_CLOSED, CAPTURE_TABLE, DELAY_ACT, DELAY_FB = range(10)
N_SENSOR = 10


@dataclass(frozen=True)
class SensorParams:
    q_enc: float = 1.0e-7            # m, motor encoder resolution (linear equivalent)
    q_scale: float = 1.0e-7          # m, linear scale resolution
    noise_sd: float = 0.0            # m
    pitch_amp: float = 0.0           # m
    pitch_period: float = 0.005      # m
    pitch_phase: float = 0.0         # rad
    full_closed: bool = False
    capture_table: bool = False
    delay_act: float = 0.0           # s
    delay_fb: float = 0.0            # s

    def pack(self) -> np.ndarray:
        s = np.zeros(N_SENSOR)
        s[Q_ENC], s[Q_SCALE], s[NOISE_SD] = self.q_enc, self.q_scale, self.noise_sd
        s[PITCH_A], s[PITCH_P], s[PITCH_PHI] = self.pitch_amp, self.pitch_period, self.pitch_phase
        s[FULL_CLOSED], s[CAPTURE_TABLE] = float(self.full_closed), float(self.capture_table)
        s[DELAY_ACT], s[DELAY_FB] = self.delay_act, self.delay_fb
        return s


@njit(cache=True)
def quantize(x, q):
    if q <= 0.0:
        return x
    return q * math.floor(x / q + 0.5)


@njit(cache=True)
def table_scale_true(x_m, x_t, s):
    """What an ideal scale on the table reads (pitch error included), m."""
    e = 0.0
    if s[PITCH_A] != 0.0:
        e = s[PITCH_A] * math.sin(2.0 * math.pi * x_m / s[PITCH_P] + s[PITCH_PHI])
    return x_t + e


@njit(cache=True)
def feedback_true(x_m, x_t, s):
    """The loop's feedback sensor before noise and quantisation, m."""
    if s[FULL_CLOSED] != 0.0:
        return table_scale_true(x_m, x_t, s)
    return x_m


@njit(cache=True)
def feedback_q(s):
    return s[Q_SCALE] if s[FULL_CLOSED] != 0.0 else s[Q_ENC]

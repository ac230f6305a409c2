"""Can a drive model be run?  The checks on a model set by hand (``--set``, a machine file).

An identified model is stable and inside the pole bounds of eq. 3.8 by construction; a
parameter typed by a user is not.  :func:`check_runnable` refuses, with one line in the
machine's terms, a model whose prediction would be meaningless: a parameter that is not a
finite number, an unstable closed loop (a pole of s³ + a1 s² + a2 s + a3, eq. 3.7, in the
right half-plane: the position grows without bound, and a free run overflows), a pole so
slow that the axis never follows its command, and — for a loop closed once per sample,
as the virtual CNC's servo is — a pole above the Nyquist frequency 1/(2 Ts), which such a
loop cannot realise.
"""

from __future__ import annotations

import math

import numpy as np

from core.errors import MachineError
from ident.model import BASE_KEYS, DriveModel

__all__ = ["check_runnable", "SLOWEST_POLE_HZ"]

#: A closed-loop pole slower than this (a time constant of 160 s) never lets the axis move
#: within a part program.
SLOWEST_POLE_HZ = 1e-3


def check_runnable(model: DriveModel, Ts: float, what: str, *, sampled_loop: bool = False) -> None:
    """Raise :class:`MachineError` naming ``what`` when ``model`` cannot be run meaningfully.

    Parameters
    ----------
    model : the eq. 3.3 parameters.
    Ts : the sample period the model runs at, s.
    what : how the message names the model ("'X.a1=-3000' (axis X)", "machine.toml axis X").
    sampled_loop : the loop is closed once per sample (the virtual CNC's servo): a pole above
        Nyquist is an error too.  The identified model is simulated by an exact
        discretisation, which runs such a pole fine.
    """
    for k in BASE_KEYS:
        v = getattr(model, k)
        if not math.isfinite(v):
            raise MachineError(f"{what}: {k} = {v} is not a finite number")
    roots = np.roots(model.denominator)
    hz = np.abs(roots) / (2 * math.pi)
    growing = roots.real > 0
    if growing.any():
        k = int(np.argmax(np.where(growing, roots.real, -np.inf)))
        raise MachineError(
            f"{what} makes the drive model unstable: a closed-loop pole at {hz[k]:.3g} Hz lies in the right "
            f"half-plane, so the predicted position grows without bound (error e-fold every "
            f"{1 / roots.real[k]:.3g} s)")
    if hz.min() < SLOWEST_POLE_HZ:
        raise MachineError(
            f"{what} puts a closed-loop pole at {hz.min():.3g} Hz: the axis would take "
            f"{1 / (2 * math.pi * max(hz.min(), 1e-300)):.3g} s to follow its command, i.e. never move")
    nyquist = 0.5 / Ts
    if sampled_loop and hz.max() > nyquist * (1 + 1e-6):
        raise MachineError(
            f"{what}: the closed loop has a pole at {hz.max():.3g} Hz, above the {nyquist:g} Hz a servo loop closed "
            f"every {Ts * 1e3:g} ms can realise; the sampled loop would be unstable (gains far too high?)")

"""How long a run may be: refuse, before allocating, a program whose samples would not fit in memory.

Every command that runs programs (``agent simulate``, ``predict``, ``ballbar``, ``serve``)
interpolates them on the servo clock first, and every later stage keeps arrays of that
length per axis.  ``G1 X100000 F60`` is 28 hours of machine time — 10⁸ samples at 1 kHz —
and a 1 km ballbar circle more: such a run used to end in a MemoryError or the kernel's
out-of-memory killer.  :func:`check_run_size` turns it into one line before the first array.
"""

from __future__ import annotations

import os

from core.errors import InputError

__all__ = ["check_run_size", "BYTES_PER_AXIS_SAMPLE", "MAX_AXIS_SAMPLES", "available_memory"]

#: Memory a run holds per axis and sample, all stages together.  Measured with
#: /usr/bin/time on 300 s programs at 1 kHz: agent predict 220 B (1 axis), agent simulate
#: 270 B (2 axes); twice that for the stages that keep copies (ballbar variants, reports).
BYTES_PER_AXIS_SAMPLE = 500
#: Whatever the memory: 10⁸ axis-samples (28 h of one axis at 1 kHz) is not a run to start.
MAX_AXIS_SAMPLES = 100_000_000


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux MemAvailable), None where unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def _hours(seconds: float) -> str:
    return f"{seconds / 3600:.3g} h" if seconds >= 3600 else f"{seconds:.3g} s"


def check_run_size(n_samples: int, Ts: float, n_axes: int, what: str) -> None:
    """One-line :class:`InputError` when ``n_samples`` on ``n_axes`` would not fit in memory.

    Parameters
    ----------
    n_samples : samples on the servo clock the run would have.
    Ts : the servo period, s.
    n_axes : axes carried per sample.
    what : the program (or test) named in the message.
    """
    axis_samples = int(n_samples) * max(1, int(n_axes))
    need = axis_samples * BYTES_PER_AXIS_SAMPLE
    free = available_memory()
    if axis_samples <= MAX_AXIS_SAMPLES and (free is None or need <= free // 2):
        return
    reason = (f"more than the {MAX_AXIS_SAMPLES:.0e} axis-samples any run may have" if axis_samples > MAX_AXIS_SAMPLES
              else f"more than half the {free / 1e9:.3g} GB of memory free")
    raise InputError(
        f"{what} runs {_hours(n_samples * Ts)} of machine time: {n_samples:.3g} samples at {1 / Ts:g} Hz on "
        f"{n_axes} {'axis' if n_axes == 1 else 'axes'}, about {need / 1e9:.3g} GB, {reason}; run a shorter program (or a smaller circle, "
        f"a higher feed)")

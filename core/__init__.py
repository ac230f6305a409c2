"""The bottom layer of rapid-ident: what every other package shares and nothing above it defines.

* :mod:`core.errors` — the exception hierarchy, one class per phase;
* :mod:`core.recording` — :class:`Recording` (the in-memory recording every stage works
  on) and :class:`Sample` (one controller tick as a transport delivers it);
* :mod:`core.log_format` — the ``rapid-ident/1`` MCAP layout;
* :mod:`core.reader` / :mod:`core.writer` — the one MCAP/CSV reader and writer pair;
* :mod:`core.pid_law` — one period of the servo's position-loop law (compiled), which the
  virtual CNC and the tuner's sampled loop both run.

It imports only numpy, numba and mcap, so ``drivers``, ``ident``, ``gcode_gen`` and
``virtual_cnc`` can all depend on it without depending on each other.
"""

from core.errors import (
    IdentificationError,
    InputError,
    MachineError,
    ProgramError,
    RapidIdentError,
    RapidIdentWarning,
    RecordingError,
    TransportError,
    TransportTimeout,
)
from core.reader import check_recording, load_csv, load_mcap, load_recording
from core.recording import AxisTrace, Recording, Sample
from core.writer import McapRecorder, write_recording_csv, write_recording_mcap

__all__ = [
    "RapidIdentError", "InputError", "ProgramError", "RecordingError", "MachineError",
    "IdentificationError", "TransportError", "TransportTimeout", "RapidIdentWarning",
    "AxisTrace", "Recording", "Sample",
    "load_recording", "load_mcap", "load_csv", "check_recording",
    "McapRecorder", "write_recording_mcap", "write_recording_csv",
]

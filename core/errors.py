"""The project's exception hierarchy, one class per phase.

Library code raises these with a one-line message that names the problem and the
offending value in the library's own terms (a function argument, a file, a URL) — never
a command-line flag, since a library caller passed none.  An error about one argument
says which with ``XError.about("port", "...")``; the ``agent`` CLI, which catches
:class:`RapidIdentError` once per command, maps that argument to its flag (``--port``)
when it prints the message, and exits non-zero.  Wrap third-party errors with
``raise XError("...") from exc`` so the cause stays chained for debugging.
"""

from __future__ import annotations

__all__ = [
    "RapidIdentError",
    "InputError",
    "ProgramError",
    "RecordingError",
    "MachineError",
    "IdentificationError",
    "UnusableRecordingError",
    "TransportError",
    "TransportTimeout",
    "StreamError",
    "RapidIdentWarning",
]


class RapidIdentError(Exception):
    """Base class of every error the tool reports to the user.

    ``parameter`` names the library argument the error is about (``"port"``,
    ``"axes"``, ``"validate"`` ...), or is None; front ends use it to name their own
    option for that argument.
    """

    parameter: str | None = None

    @classmethod
    def about(cls, parameter: str, message: str) -> "RapidIdentError":
        """The error ``message`` concerning the argument ``parameter``."""
        exc = cls(message)
        exc.parameter = parameter
        return exc


class InputError(RapidIdentError, ValueError):
    """A parameter or option given by the user is invalid (out of range, unknown name)."""


class ProgramError(InputError):
    """A G-code program cannot be read; the message carries the line number."""

    def __init__(self, message: str, line: int | None = None, source: str | None = None):
        where = ""
        if source:
            where += f"{source}:"
        if line is not None:
            where += f"{line}: " if source else f"line {line}: "
        elif source:
            where += " "
        super().__init__(f"{where}{message}")
        self.line = line
        self.source = source


class RecordingError(InputError):
    """A recording (MCAP or CSV) is missing, truncated, malformed or physically implausible."""


class MachineError(InputError):
    """A machine preset or TOML machine file is unknown or inconsistent."""


class IdentificationError(RapidIdentError):
    """The drive model cannot be identified from the data (no motion, no reversals, singular regression)."""


class UnusableRecordingError(RecordingError, IdentificationError):
    """A readable recording that cannot identify a drive: no motion, one direction only, too
    short, actual equal to commanded, channels swapped, a prediction rather than a measurement.

    Bad input (exit 2) said in the recording's terms; still an :class:`IdentificationError`
    for callers that catch that around the regression.
    """


class TransportError(RapidIdentError):
    """A controller connection failed: cannot open, lost, or the peer answered with an error."""


class TransportTimeout(TransportError, TimeoutError):
    """The controller did not answer within the timeout."""


class StreamError(TransportError):
    """The controller's data arrives but cannot be recorded as read: counters that never
    match where they are read from (word order, register layout), or a stream that
    changes mid-capture.  A capture that ends with it ends ``"unusable data"``."""


class ControllerRestartError(StreamError):
    """The controller restarted mid-capture (its counter went back, or it announced a boot).
    A capture that ends with it ends ``"controller restarted"``, keeping the samples before."""


class RapidIdentWarning(UserWarning):
    """Something is suspicious but usable (resampled timing, missing capture summary, ...)."""

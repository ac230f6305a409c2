"""Output files of the commands: the suffix an option needs, and writing the JSON result.

One place for what ``identify``, ``predict`` and ``ballbar`` each check and write, so their
errors read the same.
"""

from __future__ import annotations

from pathlib import Path

from core.errors import InputError

__all__ = ["check_suffix", "write_json"]


def check_suffix(path: Path | None, flag: str, *suffixes: str) -> None:
    """One-line InputError when ``path`` (given with ``flag``) does not end in one of ``suffixes``."""
    if path is not None and path.suffix.lower() not in suffixes:
        raise InputError(f"{flag} {path}: expected a {' or '.join(suffixes)} file")


def write_json(text: str, path: Path) -> None:
    """Write a JSON document for ``--json``; an unwritable path is a one-line error."""
    try:
        Path(path).write_text(text)
    except OSError as exc:
        raise InputError.about("json", f"{path}: cannot write ({exc.strerror})") from None

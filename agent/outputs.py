"""Output files of the commands: checked before the run, and writing the JSON result.

One place for what ``identify``, ``predict``, ``ballbar`` and ``simulate`` each check and
write, so their errors read the same.  Outputs are checked *before* the work: a run of
minutes must not end in "no such directory".
"""

from __future__ import annotations

import os
from pathlib import Path

from core.errors import InputError

__all__ = ["check_output", "write_json"]


def check_output(path: Path | None, flag: str, *suffixes: str) -> None:
    """One-line InputError, before any work, when ``path`` (given with ``flag``) cannot be written:
    a suffix not among ``suffixes``, a directory, or a directory to put it in that does not exist
    or is not writable."""
    if path is None:
        return
    path = Path(path)
    if suffixes and path.suffix.lower() not in suffixes:
        raise InputError(f"{flag} {path}: expected a {' or '.join(suffixes)} file")
    if path.is_dir():
        raise InputError(f"{flag} {path}: is a directory; give a file name")
    parent = path.parent
    if not parent.is_dir():
        what = "is not a directory" if parent.exists() else "does not exist"
        raise InputError(f"{flag} {path}: the directory {parent} {what}")
    if not os.access(parent, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise InputError(f"{flag} {path}: not writable (permission denied)")


def write_json(text: str, path: Path) -> None:
    """Write a JSON document for ``--json``; an unwritable path is a one-line error."""
    try:
        Path(path).write_text(text)
    except OSError as exc:
        raise InputError.about("json", f"{path}: cannot write ({exc.strerror})") from None

"""Checks of command-line values that the library would only reject deep inside a run.

Each raises a one-line :class:`InputError` naming the option, before any work is done.
"""

from __future__ import annotations

from core.errors import InputError

__all__ = ["check_seed"]


def check_seed(seed: int, flag: str = "--seed") -> None:
    """Random seeds are whole numbers >= 0 (numpy's generators refuse negative ones)."""
    if seed < 0:
        raise InputError(f"{flag} must be a whole number >= 0, got {seed}")

"""Command modules of the ``agent`` CLI; each exposes one typer-annotated function."""

from __future__ import annotations

import importlib
from typing import Callable

#: command name -> (module, function)
COMMANDS: dict[str, tuple[str, str]] = {
    "generate": ("agent.commands.generate", "generate"),
    "simulate": ("agent.commands.simulate", "simulate"),
    "serve": ("agent.commands.serve", "serve"),
    "capture": ("agent.commands.capture", "capture"),
    "identify": ("agent.commands.identify", "identify"),
    "predict": ("agent.commands.predict", "predict"),
    "ballbar": ("agent.commands.ballbar", "ballbar"),
    "tune": ("agent.commands.tune", "tune"),
}


def registered_commands() -> list[tuple[str, Callable]]:
    """(name, function) of every command; a module that fails to import is an error, never skipped."""
    return [(name, getattr(importlib.import_module(module), func)) for name, (module, func) in COMMANDS.items()]

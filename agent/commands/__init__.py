"""Command modules of the ``agent`` CLI; each exposes one typer-annotated function."""

from __future__ import annotations

import importlib
from typing import Callable

#: command name -> (module, function); a missing module (not written yet) is skipped.
COMMANDS: dict[str, tuple[str, str]] = {
    "generate": ("agent.commands.generate", "generate"),
    "simulate": ("agent.commands.simulate", "simulate"),
    "serve": ("agent.commands.serve", "serve"),
    "capture": ("agent.commands.capture", "capture"),
    "identify": ("agent.commands.identify", "identify"),
}


def registered_commands() -> list[tuple[str, Callable]]:
    out = []
    for name, (module_name, func_name) in COMMANDS.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name == module_name:
                continue
            raise
        out.append((name, getattr(module, func_name)))
    return out

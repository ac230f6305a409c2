"""Checks of command-line values that the library would only reject deep inside a run.

Each raises a one-line :class:`InputError` naming the option, before any work is done.
"""

from __future__ import annotations

from core.errors import InputError

__all__ = ["check_seed", "check_machine", "parse_plane"]


def check_seed(seed: int, flag: str = "--seed") -> None:
    """Random seeds are whole numbers >= 0 (numpy's generators refuse negative ones)."""
    if seed < 0:
        raise InputError(f"{flag} must be a whole number >= 0, got {seed}")


def parse_plane(text: str) -> tuple[str, ...]:
    """The axes of a plane option: ``X,Y`` (names, comma separated) or ``XY`` (two letters).

    Axis names may be longer than a letter (a gantry's ``Y2``), so only a single two-letter
    word with no comma is read as two letters."""
    names = tuple(a.strip().upper() for a in text.split(",") if a.strip())
    if len(names) == 1 and len(names[0]) == 2 and names[0].isalpha():
        return tuple(names[0])
    return names


def check_machine(machine: str | None) -> None:
    """A built-in or TOML machine whose servo loops the virtual CNC can close at its servo period.

    Each axis's controller and plant give the closed loop of thesis eq. 3.3
    (:func:`virtual_cnc.drive.closed_loop_parameters`); a loop that is unstable, or whose
    poles lie above the Nyquist frequency of the servo clock (a position gain of 10⁹), would
    run — into millimetres of tracking error — without a word, so it is refused here.
    """
    from ident.model import DriveModel
    from ident.model_limits import check_runnable
    from virtual_cnc.drive import closed_loop_parameters
    from virtual_cnc.presets import DEFAULT_MACHINE, load_machine

    m = load_machine(machine or DEFAULT_MACHINE)
    for name, axis in m.axes.items():
        c = axis.controller
        check_runnable(DriveModel(**closed_loop_parameters(axis)), m.Ts,
                       f"machine {m.name}, axis {name} ({c.kind} gains Kp {c.Kp:g}, Ki {c.Ki:g}, Kd {c.Kd:g})",
                       sampled_loop=True)

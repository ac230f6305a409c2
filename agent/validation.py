"""Checks of command-line values that the library would only reject deep inside a run.

Each raises a one-line :class:`InputError` naming the option, before any work is done.
"""

from __future__ import annotations

from core.errors import InputError

__all__ = ["check_seed", "check_machine"]


def check_seed(seed: int, flag: str = "--seed") -> None:
    """Random seeds are whole numbers >= 0 (numpy's generators refuse negative ones)."""
    if seed < 0:
        raise InputError(f"{flag} must be a whole number >= 0, got {seed}")


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

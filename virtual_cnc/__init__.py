"""The virtual CNC: G-code programs through the interpolator, servo loops and drive physics.

``simulate(programs, machine)`` returns the :class:`core.Recording` a capture of that
machine would make; ``agent simulate`` writes it to a log and the simulated controller
endpoints (drivers/endpoints) serve it in real time.

Modules:
* :mod:`virtual_cnc.machine_run` — ``simulate``: programs → interpolator → servo loops → Recording
  (``not_following``: the axes of a run that do not follow their command);
* :mod:`virtual_cnc.drive` — controller/plant/encoder dataclasses, eq. 3.4/3.5 parameters;
* :mod:`virtual_cnc.effects` — optional physics (SPEC §7) and the ``--effect`` parser;
* :mod:`virtual_cnc.presets` — named machines (thesis §3.4.1) and TOML machine files;
* :mod:`virtual_cnc.servo` — the numba servo loop: ``simulate_axis``, ``simulate_machine``.

The servo module (and numba) is imported only when one of its names is first used.
"""

from __future__ import annotations

from virtual_cnc.drive import AxisDrive, Controller, Encoder, Plant, closed_loop_parameters, smc_gains
from virtual_cnc.effects import EFFECTS, Effect, format_effect, parse_effect
from virtual_cnc.machine_run import not_following, simulate
from virtual_cnc.presets import DEFAULT_MACHINE, PRESETS, Machine, load_machine, machine_to_toml

__all__ = [
    "simulate", "not_following",
    "AxisDrive", "Controller", "Encoder", "Plant", "closed_loop_parameters", "smc_gains",
    "EFFECTS", "Effect", "format_effect", "parse_effect",
    "DEFAULT_MACHINE", "PRESETS", "Machine", "load_machine", "machine_to_toml",
    "AxisResponse", "simulate_axis", "simulate_axis_response", "simulate_machine",
]

_SERVO_NAMES = {"AxisResponse", "simulate_axis", "simulate_axis_response", "simulate_machine"}


def __getattr__(name: str):
    if name in _SERVO_NAMES:
        from virtual_cnc import servo

        return getattr(servo, name)
    raise AttributeError(f"module 'virtual_cnc' has no attribute {name!r}")

"""The virtual CNC's servo drives: controllers, drive physics, presets, the servo-loop simulator.

Modules:

* :mod:`drivers.sim.drive` — controller/plant/encoder dataclasses, eq. 3.4/3.5 parameters;
* :mod:`drivers.sim.effects` — optional physics (SPEC §7) and the ``--effect`` parser;
* :mod:`drivers.sim.presets` — named machines (thesis §3.4.1) and TOML machine files;
* :mod:`drivers.sim.servo` — the numba servo loop: ``simulate_axis``, ``simulate_machine``.

The servo module (and numba) is imported only when one of its names is first used.
"""

from __future__ import annotations

from drivers.sim.drive import AxisDrive, Controller, Encoder, Plant, closed_loop_parameters, smc_gains
from drivers.sim.effects import EFFECTS, Effect, format_effect, parse_effect
from drivers.sim.presets import DEFAULT_MACHINE, PRESETS, Machine, load_machine, machine_to_toml

__all__ = [
    "AxisDrive", "Controller", "Encoder", "Plant", "closed_loop_parameters", "smc_gains",
    "EFFECTS", "Effect", "format_effect", "parse_effect",
    "DEFAULT_MACHINE", "PRESETS", "Machine", "load_machine", "machine_to_toml",
    "AxisResponse", "simulate_axis", "simulate_axis_response", "simulate_machine",
]

_SERVO_NAMES = {"AxisResponse", "simulate_axis", "simulate_axis_response", "simulate_machine"}


def __getattr__(name: str):
    if name in _SERVO_NAMES:
        from drivers.sim import servo

        return getattr(servo, name)
    raise AttributeError(f"module 'drivers.sim' has no attribute {name!r}")

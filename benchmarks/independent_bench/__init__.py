"""An independent feed-drive simulator and its benchmark cases (test bench for ident.diagnosis).

Written from the physics, not from ``virtual_cnc`` or ``ident.diagnosis``: a lumped
motor/table plant (rigid or two-mass, a gap with contact stiffness and damping, asymmetric
Coulomb + viscous + Stribeck friction with a Karnopp stick model, cogging ripple), drive
controllers sampled at 1 kHz (cascade P-PI and PID, both with velocity/acceleration
feed-forward, integral without anti-windup, a force limit), dead time in actuation or
feedback, and sensors (quantised motor encoder or linear scale, white noise, lead-screw
pitch error).  Internal units are SI (m, m/s, N, kg); the recordings are in mm.

Modules, one job each:

- :mod:`.plant`      -- plant parameters and the sub-step integrator (numba)
- :mod:`.controller` -- controller parameters and the 1 kHz control law (numba)
- :mod:`.sensors`    -- sensor parameters, quantisation, pitch error (numba)
- :mod:`.simulate`   -- the closed loop: ``Drive``, ``simulate``, ``record``
- :mod:`.cases`      -- classes, parameter ranges, ``draw_case``, ``case_recordings``
- :mod:`.linear`     -- the linearised closed loop: ``closed_loop_mode`` (resonance truth as seen)
"""

from .plant import PlantParams
from .controller import ControllerParams, tune_pid, tune_ppi
from .sensors import SensorParams
from .simulate import Drive, SimResult, command, record, simulate
from .cases import CLASSES, RANGES, Case, case_recordings, draw_case

__all__ = ["PlantParams", "ControllerParams", "SensorParams", "tune_ppi", "tune_pid",
           "Drive", "SimResult", "simulate", "record", "command",
           "CLASSES", "RANGES", "Case", "draw_case", "case_recordings"]

"""G-code for rapid identification: excitation programs, validation toolpaths, dialect
writers, the interpreter and the interpolator.

Pipeline::

    Toolpath (excitation / toolpaths) --dialects.write--> text
    text --interpreter.parse_program--> Program --interpolator.interpolate--> Trajectory

Units: mm, mm/s, mm/s², s.  See the module docstrings for the thesis sections each follows.
"""

from gcode_gen.dialects import DIALECTS, EXTENSIONS, file_name, save, write
from gcode_gen.generator import generate, save_programs
from gcode_gen.excitation import ExcitationSpec, high_speed_program, identification_programs, low_speed_program
from gcode_gen.interpolator import Trajectory, concatenate, interpolate, interpolate_programs, plan_profile
from gcode_gen.interpreter import detect_dialect, parse_program, read_program
from gcode_gen.program import Block, Program, Toolpath
from gcode_gen.toolpaths import TOOLPATHS, circle, diamond

__all__ = [
    "generate", "save_programs", "save",
    "Block", "Program", "Toolpath", "Trajectory",
    "ExcitationSpec", "identification_programs", "low_speed_program", "high_speed_program",
    "circle", "diamond", "TOOLPATHS",
    "DIALECTS", "EXTENSIONS", "write", "file_name",
    "parse_program", "read_program", "detect_dialect",
    "interpolate", "interpolate_programs", "concatenate", "plan_profile",
]

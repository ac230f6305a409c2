"""Identification of the closed-loop feed-drive model of the thesis (eq. 3.3) from a recording.

The Python API, in the order of a session (docs/python-api.md has a worked example)::

    import ident
    rec = ident.Recording.from_arrays(t=t, commanded={"X": x_r}, actual={"X": x})  # or ident.load(path)
    result = ident.identify(rec, validate=None, diagnose=True)
    result.axes["X"].model            # DriveModel: a1, a2, a3, b0, b1, b2, d0, d1
    result.axes["X"].fit_identification.tracking_error_fit_pct
    result.to_json(); result.report("report.html")

    # the identified drives as a virtual machine (docs/virtual-machine.md)
    vm = ident.VirtualMachine.from_result(json.loads(result.to_json()))   # or ident.load_virtual_machine(path)
    summary = ident.predict([gcode_gen.circle(size=20, feed=100)], vm)
    summary.contour_max_mm, summary.worst

Modules, one stage each: :mod:`ident.preprocessing`, :mod:`ident.regression` (eq. 3.11),
:mod:`ident.model` (eq. 3.3, 3.8), :mod:`ident.solvers` (ls, exact, ga), :mod:`ident.refine`,
:mod:`ident.simulation`, :mod:`ident.metrics`, :mod:`ident.contour`, :mod:`ident.diagnosis`,
:mod:`ident.results`, :mod:`ident.report`; :mod:`ident.pipeline` joins them.
"""

from core.errors import IdentificationError, InputError, RapidIdentError, RecordingError
from core.reader import load_recording as load
from core.recording import AxisTrace, Recording
from core.writer import write_recording_csv, write_recording_mcap
from ident.metrics import FitResult, fit_result
from ident.model import Bounds, DriveModel
from ident.pipeline import identify, load_models
from ident.results import AxisResult, IdentifyResult
from ident.prediction import Comparison, PredictionSummary, analyse, compare, predict
from ident.simulation import simulate
from ident.virtual_machine import Prediction, VirtualMachine, load_virtual_machine
from ident.axis_model import AxisModel

__all__ = [
    "Recording", "AxisTrace", "load", "write_recording_mcap", "write_recording_csv",
    "identify", "load_models", "IdentifyResult", "AxisResult",
    "DriveModel", "Bounds", "FitResult", "fit_result", "simulate",
    "AxisModel", "VirtualMachine", "load_virtual_machine", "Prediction", "PredictionSummary", "Comparison",
    "predict", "analyse", "compare",
    "RapidIdentError", "InputError", "RecordingError", "IdentificationError",
]

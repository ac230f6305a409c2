"""AxisModel: the controller form the diagnosis fitted travels with the model."""

from __future__ import annotations

import pytest

from core.errors import InputError
from ident.axis_model import AxisModel
from ident.model import DriveModel

BASE = dict(a1=372.76, a2=62009.83, a3=1527104.87, b0=1.0, b1=372.76, b2=62009.83, d0=441.0, d1=-302.0)


@pytest.mark.parametrize("controller, slot", [("continuous", 0), ("sampled", 1), ("sampled_causal", 2)])
def test_the_controller_form_survives_json_and_sets_the_simulators_slot(controller, slot):
    m = AxisModel(DriveModel(**BASE), 0.001, controller=controller)
    back = AxisModel.from_dict(m.to_dict())
    assert back.controller == controller
    assert int(back.spec_arrays()[3][4]) == slot


def test_an_unknown_controller_form_is_a_one_line_error():
    with pytest.raises(InputError, match="controller 'digital': one of continuous, sampled, sampled_causal"):
        AxisModel(DriveModel(**BASE), 0.001, controller="digital")


def test_a_model_is_checked_without_loading_the_diagnosis_signal_processing():
    # every identification builds an AxisModel, with or without the diagnosis: checking its
    # controller form must not import scipy.signal (half a second of `agent identify`)
    import subprocess
    import sys

    code = ("import sys; from ident.axis_model import AxisModel; from ident.model import DriveModel; "
            f"AxisModel(DriveModel(**{BASE!r}), 0.001, controller='sampled_causal'); "
            "print('scipy.signal' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("mode", [0, 1, 2])
def test_every_backlash_variant_the_diagnosis_reports_is_the_one_the_model_simulates(mode):
    # the diagnosis's words (parameters) and the model's arrays (set_arrays) are one mapping
    import numpy as np

    from ident.diagnosis.effects import EFFECT_MODELS
    from ident.diagnosis.spec import ModelSpec

    theta = np.array(list(BASE.values()))
    two_mass = {"motor_fraction": 0.6, "position_motor_share": 0.3 if mode == 1 else 0.0} if mode else {}
    spec = ModelSpec(theta).with_effect("backlash", {"gap_mm": 0.05, **two_mass}, mode)
    words = EFFECT_MODELS["backlash"].parameters(spec)
    m = AxisModel.from_dict(AxisModel(DriveModel(**BASE), 0.001, effects={"backlash": words}).to_dict())
    _theta, _flags, ep, modes = m.spec_arrays()
    assert int(modes[0]) == mode
    assert np.allclose(ep, spec.ep)


#: An identified P-PI cascade (fadal-ppi): its equivalent of eq. 3.3 has b2 ≠ a2, so at rest at x the
#: integral holds z = (a2 − b2)·x/a3, zero only at the origin.
CASCADE = dict(a1=3174.4, a2=103319.8, a3=334817.3, b0=-0.0925, b1=574.16, b2=93839.0, d0=441.0, d1=-302.0)


@pytest.mark.parametrize("effects", [{}, {"time_delay": {"delay_s": 0.002, "where": "capture"}}])
def test_a_prediction_from_rest_is_the_same_wherever_the_axis_stands(effects):
    """A drive standing still has no preferred position: the predicted move from 7 mm is the move
    from the origin shifted by 7 mm, with the plain model's simulator as with the augmented one."""
    import numpy as np

    tau = np.clip((np.arange(1500) * 0.001 - 0.1) / 0.5, 0.0, 1.0)
    x_r = 5.0 * tau ** 3 * (10 - 15 * tau + 6 * tau ** 2)  # rest, a 5 mm minimum-jerk move, rest
    m = AxisModel(DriveModel(**CASCADE), 0.001, shift=-5, effects=effects)
    assert np.max(np.abs(m.simulate(x_r + 7.0) - 7.0 - m.simulate(x_r))) < 1e-9

"""The linuxcnc:// driver's URL options: bad input is a one-line error before HAL is touched."""

from __future__ import annotations

import pytest

from core.errors import InputError
from drivers.registry import open_driver


def test_defaults_read_joint_0_motor_pins_as_x():
    d = open_driver("linuxcnc://")
    assert d.names == ("X",)
    assert d.pins == ["joint.0.motor-pos-cmd", "joint.0.motor-pos-fb"]
    assert d.running_pin == "halui.program.is-running"


def test_joints_axes_and_pin_templates():
    d = open_driver("linuxcnc://?joints=1,3&axes=Y,Y2&fb=hm2.encoder.{j}.position&running=")
    assert d.names == ("Y", "Y2")
    assert d.pins == ["joint.1.motor-pos-cmd", "hm2.encoder.1.position",
                      "joint.3.motor-pos-cmd", "hm2.encoder.3.position"]
    assert d.running_pin is None


@pytest.mark.parametrize("url, match", [
    ("linuxcnc://host/path", "no host or path"),
    ("linuxcnc://?joints=x", "joint numbers"),
    ("linuxcnc://?joints=0,0", "distinct"),
    ("linuxcnc://?joints=0,1&axes=X", "one name per joint"),
    ("linuxcnc://?joints=12", "give axes="),
    ("linuxcnc://?depth=10", "depth >= 100"),
    ("linuxcnc://?channel=99", "channel must be"),
    ("linuxcnc://?speed=1", "unknown option 'speed'"),
])
def test_bad_options_are_one_line_errors(url, match):
    with pytest.raises(InputError, match=match):
        open_driver(url)

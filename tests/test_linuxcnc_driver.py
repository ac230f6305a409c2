"""The linuxcnc:// driver's URL options: bad input is a one-line error before HAL is touched."""

from __future__ import annotations

import subprocess
import sys

import pytest

from core.errors import InputError
from drivers.registry import open_driver
from drivers.transports.linuxcnc_hal import _started_with_ini


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


def test_the_units_come_from_the_ini_the_running_linuxcnc_was_started_with(tmp_path):
    # LinuxCNC's start script exports INI_FILE_NAME to what it starts (rtapi_app among them);
    # a process started so stands in for rtapi_app here
    (tmp_path / "lathe.ini").write_text("[TRAJ]\n  LINEAR_UNITS = inch\n[JOINT_0]\nTYPE = LINEAR\n"
                                        "[JOINT_1]\nTYPE = ANGULAR\n")
    proc = subprocess.Popen([sys.executable, "-c", "print('up', flush=True); input()"], cwd=tmp_path,
                            env={"INI_FILE_NAME": "lathe.ini"}, stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    try:
        proc.stdout.readline()  # its environment is the one given once it runs (not the fork's)
        ini = _started_with_ini(proc.pid)
    finally:
        proc.kill()
        proc.wait()
    assert ini == tmp_path / "lathe.ini"
    scales, units, source = open_driver("linuxcnc://?joints=0,1")._joint_units(ini)
    assert (scales, units) == ([25.4, 1.0], ("mm", "deg"))
    assert source.startswith(str(ini))
    # scale= wins, on every joint; without an INI positions are taken as mm, and the log says so
    assert open_driver("linuxcnc://?joints=0,1&scale=2")._joint_units(ini)[:2] == ([2.0, 2.0], ("mm", "mm"))
    scales, units, source = open_driver("linuxcnc://")._joint_units(None)
    assert (scales, units) == ([1.0], ("mm",)) and "not found" in source

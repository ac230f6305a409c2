"""One contour-error definition (issue 41): the distance to the programmed path with a sign
that does not flip on rounding, over the same feed-move samples whether the prediction
stands alone or is compared with a recording from another planner."""

from __future__ import annotations

import numpy as np
import pytest

import gcode_gen
import ident
import virtual_cnc
from gcode_gen.planner_limits import PlannerLimits
from ident.contour import contour_error, path_contour_error
from ident.prediction import block_of_samples, compare


def _one(path: list[tuple[float, float]], q: tuple[float, float]) -> float:
    P = np.array(path, dtype=float)
    return float(contour_error(P[:, 0], P[:, 1], np.array([q[0]]), np.array([q[1]]))[0])


# -- the sign --------------------------------------------------------------------------------

@pytest.mark.parametrize("y", [0.0, -17e-6, 17e-6])
def test_a_point_beyond_the_paths_end_on_its_extension_is_its_distance_away(y):
    """An overshoot to (10.163, 0) past a line ending at (10, 0): 163 µm, not 0, and a rounding
    error of 17 nm across the line's extension does not flip it to −163 µm."""
    path = [(0.0, 0.0), (5.0, 0.0), (10.0, 0.0)]
    assert _one(path, (10.163, y)) == pytest.approx(0.163, abs=1e-6)


@pytest.mark.parametrize("q", [(10.163, 0.0), (10.163, -17e-6), (10.1, 0.05), (10.05, -0.1)])
def test_an_overshoot_past_a_counter_clockwise_corner_is_outside_it(q):
    """Past the corner (10, 0) of a counter-clockwise path (in along +X, out towards (0, 10))
    the point is outside, i.e. right of travel (−), whichever of the two sides is nearer."""
    path = [(0.0, 0.0), (10.0, 0.0), (0.0, 10.0)]
    d = _one(path, q)
    assert d < 0
    assert abs(d) == pytest.approx(np.hypot(q[0] - 10.0, q[1]), rel=1e-9)


def test_inside_a_segment_the_sign_is_the_side_of_travel():
    path = [(0.0, 0.0), (10.0, 0.0)]
    assert _one(path, (5.0, 0.1)) == pytest.approx(0.1)
    assert _one(path, (5.0, -0.1)) == pytest.approx(-0.1)
    # the same in the path function with arcs and time that predict uses
    P = np.array(path)
    assert path_contour_error(P, np.array([[10.163, -17e-6]]))[0] == pytest.approx(0.163, abs=1e-6)


# -- the samples counted ---------------------------------------------------------------------

@pytest.fixture(scope="module")
def machine():
    rec = virtual_cnc.simulate(gcode_gen.generate(["X", "Y"], seed=3, n_low=60, n_high=20), "fadal-pid", seed=3)
    import json

    return ident.VirtualMachine.from_result(json.loads(ident.identify(rec, diagnose=False).to_json()), "m.json")


def test_the_g0_lead_in_is_not_counted_against_a_recording_from_another_planner(machine):
    """A circle with its G0 lead-in recorded on the virtual CNC (path-limited planner) and
    compared on a machine that plans with per-axis limits (so the command differs sample for
    sample): only the circle's samples count, as in the stand-alone prediction, and the
    measured figure is the one the same recording gives against its own planner."""
    circle = gcode_gen.circle(size=20, feed=100, start_deg=45)
    recorded = virtual_cnc.simulate([circle], "fadal-pid", seed=5)
    per_axis = machine.with_planner_limits(PlannerLimits({"X": (200.0, 2000.0), "Y": (200.0, 2000.0)}, 200.0, "test"))
    own = compare(machine, recorded, machine.run([circle]).run)
    other_run = per_axis.run([circle]).run
    assert not np.array_equal(other_run.commanded["X"][:len(recorded.t)], recorded.axes["X"].commanded[:len(other_run.t)])
    other = compare(per_axis, recorded, other_run)
    x, y = recorded.axes["X"].commanded, recorded.axes["Y"].commanded
    on_circle = np.abs(np.hypot(x, y) - np.hypot(7.0711, 7.0711)) < 1e-6  # the start as written, 4 decimals
    lead_in = ~on_circle & (np.hypot(np.diff(x, prepend=x[0]), np.diff(y, prepend=y[0])) > 0)
    assert lead_in.sum() > 50  # the G0 from (0, 0) to the start is in the recording
    for c in (own, other):
        assert not (c.mask & lead_in).any()
        assert on_circle[c.mask].all()
    assert other.mask.sum() == own.mask.sum()
    assert other.to_dict()["measured_max_abs_mm"] == pytest.approx(own.to_dict()["measured_max_abs_mm"], rel=1e-12)


def test_recorded_samples_are_assigned_to_the_block_whose_end_they_reach(machine):
    diamond = gcode_gen.diamond(size=20, feed=50)
    run = machine.run([diamond]).run
    seg, line = block_of_samples(run, run.commanded)
    moving = np.concatenate([[False], np.diff(run.commanded["X"]) != 0])
    np.testing.assert_array_equal(line[moving], run.line[moving])


def test_a_recording_of_another_program_is_refused_with_a_reason(machine):
    recorded = virtual_cnc.simulate([gcode_gen.diamond(size=20, feed=100)], "fadal-pid", seed=5)
    with pytest.raises(ValueError, match="does not run the program's feed moves"):
        compare(machine, recorded, machine.run([gcode_gen.circle(size=40, feed=100, start_deg=30)]).run)

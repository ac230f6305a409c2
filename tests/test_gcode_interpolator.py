"""Interpolator: sampling grid, feed/acceleration/jerk limits, exact stop, arcs, several axes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from core.errors import InputError
from gcode_gen import dialects
from gcode_gen.excitation import identification_programs
from gcode_gen.interpolator import concatenate, interpolate, interpolate_programs, plan_profile
from gcode_gen.interpreter import parse_program
from gcode_gen.toolpaths import circle, diamond

TS = 0.001


def _prog(text, dialect="linuxcnc"):
    return parse_program(text, dialect=dialect)


def _xyz(tr):
    return np.vstack([tr.axes[a] for a in sorted(tr.axes)])


def _rates(tr):
    P = _xyz(tr)
    v = np.linalg.norm(np.diff(P, axis=1), axis=0) / tr.Ts
    a = np.linalg.norm(np.diff(P, 2, axis=1), axis=0) / tr.Ts**2
    j = np.linalg.norm(np.diff(P, 3, axis=1), axis=0) / tr.Ts**3
    return v, a, j


@pytest.mark.parametrize(
    "L, v, a, j, T",
    [
        (0.03, 200.0, 2000.0, None, 2 * math.sqrt(0.03 / 2000)),  # triangle
        (50.0, 200.0, 2000.0, None, 50 / 200 + 200 / 2000),  # trapezoid: L/v + v/a
        (50.0, 200.0, 2000.0, 1e5, 50 / 200 + 200 / 2000 + 2000 / 1e5),  # S-curve: + a/j
        (1e-4, 200.0, 2000.0, 1e5, 4 * (1e-4 / 2 / 1e5) ** (1 / 3)),  # jerk-limited triangle
    ],
)
def test_profile_durations_match_closed_forms(L, v, a, j, T):
    prof = plan_profile(L, v, a, j)
    assert prof.T == pytest.approx(T, rel=1e-12)
    assert prof.vp <= v


def test_samples_lie_on_the_grid_and_the_start_is_sample_zero():
    tr = interpolate(_prog("G0 X0\nG1 X1.2345 F600\nM2\n"), Ts=TS)
    assert np.array_equal(tr.t, np.arange(len(tr.t)) * TS)
    assert tr.axes["X"][0] == 0.0 and tr.axes["X"][-1] == 1.2345
    assert tr.block[0] == 0 and set(tr.block[1:]) == {2}


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("j_max", [None, 4e4])
def test_feed_acceleration_and_jerk_never_exceeded(seed, j_max):
    rng = np.random.default_rng(seed)
    feed = float(rng.uniform(20, 300))
    a_max = float(rng.uniform(200, 5000))
    low, high = identification_programs(axes=("X", "Y"), range_mm=float(rng.uniform(1, 20)),
                                        n_low=40, n_high=40, feed=feed, seed=seed)
    for tp in (low, high):
        tr = interpolate(parse_program(dialects.write(tp, "iso")), a_max=a_max, j_max=j_max, rapid_feed=feed)
        v, a, j = _rates(tr)
        assert v.max() <= feed * (1 + 1e-9)
        assert a.max() <= a_max * (1 + 1e-6)
        if j_max is not None:
            assert j.max() <= j_max * (1 + 1e-6)


def test_peak_speed_of_each_move_is_sqrt_a_d_and_full_feed_needs_the_full_stroke():
    """Thesis §3.3: the feed (200 mm/s) is reached only from one end of the ±10 mm range to the other."""
    _, high = identification_programs(seed=1)
    prog = parse_program(dialects.write(high, "linuxcnc"))
    tr = interpolate(prog, a_max=2000.0)
    speed = np.abs(np.diff(tr.axes["X"])) / TS
    x_prev = prog.blocks[0].target["X"]
    for b in prog.blocks[1:]:
        d = abs(b.target["X"] - x_prev)
        x_prev = b.target["X"]
        if d > 1.0:
            peak = speed[tr.block[1:] == b.line].max()
            assert peak == pytest.approx(min(200.0, math.sqrt(2000.0 * d)), rel=0.01, abs=2.0)
    stroke = prog.blocks[2]  # -10 -> +10: d = 20 mm = v²/a
    assert speed[tr.block[1:] == stroke.line].max() == pytest.approx(200.0, rel=0.01)


def test_every_block_ends_exactly_at_its_target_and_at_rest():
    low, _ = identification_programs(axes=("X", "Y"), n_low=60, seed=9)
    prog = parse_program(dialects.write(low, "heidenhain"))
    tr = interpolate(prog, a_max=2000.0)
    X = _xyz(tr)
    ends = np.flatnonzero(np.diff(tr.block) != 0)  # last sample of each block (index 0 = start)
    ends = np.append(ends[1:], len(tr.t) - 1)
    targets = {b.line: b.target for b in prog.blocks}
    for k in ends:
        target = targets[int(tr.block[k])]
        assert tr.axes["X"][k] == target["X"] and tr.axes["Y"][k] == target["Y"]
        if k + 1 < len(tr.t):  # exact stop: the next block starts from rest
            assert np.linalg.norm(X[:, k + 1] - X[:, k]) <= 0.5 * 2000.0 * TS**2 * (1 + 1e-9)


@pytest.mark.parametrize("direction", ["ccw", "cw"])
@pytest.mark.parametrize("j_max", [None, 1e5])
def test_circle_radius_constant_endpoints_exact_and_centripetal_limit(direction, j_max):
    tp = circle(size=10.0, feed=200.0, center=(3.0, -2.0), direction=direction)
    tr = interpolate(parse_program(dialects.write(tp, "iso")), a_max=2000.0, j_max=j_max)
    x, y = tr.axes["X"], tr.axes["Y"]
    r = np.hypot(x - 3.0, y + 2.0)
    assert np.abs(r - 5.0).max() < 1e-9
    assert (x[-1], y[-1]) == (8.0, -2.0) and (x[0], y[0]) == (8.0, -2.0)
    v, a, _ = _rates(tr)
    assert v.max() <= math.sqrt(2000.0 * 5.0 / math.sqrt(2)) * (1 + 1e-9)  # feed lowered: v²/r <= a/√2
    assert a.max() <= 2000.0 * (1 + 1e-6)
    turn = np.unwrap(np.arctan2(y + 2.0, x - 3.0))
    assert turn[-1] - turn[0] == pytest.approx(2 * math.pi if direction == "ccw" else -2 * math.pi)


def test_quarter_arc_with_r_reaches_feed_when_gentle():
    prog = _prog("G0 X0 Y10\nG2 X10 Y0 R10 F600\nM2\n")
    tr = interpolate(prog)
    r = np.hypot(tr.axes["X"], tr.axes["Y"])
    assert np.abs(r - 10).max() < 1e-9
    v, _, _ = _rates(tr)
    assert v.max() == pytest.approx(10.0, rel=1e-3)
    assert tr.duration == pytest.approx(10 * math.pi / 2 / 10 + 10 / 2000, abs=2 * TS)


def test_several_axes_move_together_on_a_straight_line():
    tr = interpolate(_prog("G0 X0 Y0 Z0\nG1 X30 Y-40 Z0 F6000\nM2\n"), a_max=1000.0)
    x, y = tr.axes["X"], tr.axes["Y"]
    assert np.allclose(y, -4 / 3 * x, atol=1e-12)
    assert np.all(tr.axes["Z"] == 0.0)
    vx = np.abs(np.diff(x)).max() / TS
    vy = np.abs(np.diff(y)).max() / TS
    assert vx == pytest.approx(0.6 * 100, rel=1e-3) and vy == pytest.approx(0.8 * 100, rel=1e-3)


def test_diamond_corners_stop_and_limits_hold():
    tr = interpolate(parse_program(dialects.write(diamond(size=20.0, feed=200.0), "linuxcnc")))
    v, a, _ = _rates(tr)
    assert v.max() <= 200 * (1 + 1e-9) and a.max() <= 2000 * (1 + 1e-6)
    for corner in [(0.0, 10.0), (-10.0, 0.0), (0.0, -10.0), (10.0, 0.0)]:
        assert np.any((tr.axes["X"] == corner[0]) & (tr.axes["Y"] == corner[1]))


def test_axes_that_never_move_keep_their_start_value():
    tr = interpolate(_prog("G1 X1 F600\nG1 X2\nM2\n"), start={"X": 0.5, "Z": 7.25, "A": -3.0})
    assert tr.axes["X"][0] == 0.5 and tr.axes["X"][-1] == 2.0
    assert np.all(tr.axes["Z"] == 7.25) and np.all(tr.axes["A"] == -3.0)


def test_default_start_is_the_first_programmed_position():
    tr = interpolate(_prog("G0 X5 Y5\nG1 X6 F600\nM2\n"))
    assert tr.axes["X"][0] == 5.0 and tr.axes["Y"][0] == 5.0
    assert tr.duration == pytest.approx(1 / 10 + 10 / 2000, abs=TS)  # only the G1: L/v + v/a


def test_rapid_moves_use_the_rapid_feed():
    tr = interpolate(_prog("G0 X0\nG0 X100\nM2\n"), rapid_feed=500.0, a_max=1e4)
    assert np.abs(np.diff(tr.axes["X"])).max() / TS == pytest.approx(500.0, rel=1e-6)


def test_dwell_holds_position_for_its_time():
    tr = interpolate(_prog("G0 X0\nG1 X1 F600\nG4 P0.25\nG1 X0\nM2\n"))
    held = tr.block == 3
    assert held.sum() == 250 and np.all(tr.axes["X"][held] == 1.0)


def test_blending_runs_same_direction_blocks_without_stopping():
    text = "G0 X0\nG1 X1 F3000\nG1 X2\nG1 X3\nG1 X0\nM2\n"
    stop = interpolate(_prog(text))
    blend = interpolate(_prog(text), blending=True)
    assert blend.duration < stop.duration
    v, a, _ = _rates(blend)
    assert v.max() <= 50 * (1 + 1e-9) and a.max() <= 2000 * (1 + 1e-6)
    k = int(np.argmax(blend.axes["X"] >= 2.0))  # first pass of X2, on the way out
    assert blend.axes["X"][k + 1] - blend.axes["X"][k] == pytest.approx(50 * TS, rel=0.01)  # at full feed
    assert list(dict.fromkeys(blend.block[1:])) == [2, 3, 4, 5]  # line numbers still reported
    assert np.any(blend.axes["X"] == 3.0)  # the reversal is still an exact stop at X3


def test_concatenate_and_run_programs_back_to_back():
    low, high = identification_programs(n_low=20, n_high=20, seed=2)
    progs = [parse_program(dialects.write(tp, "iso")) for tp in (low, high)]
    joined, seg = interpolate_programs(progs)
    a = interpolate(progs[0])
    assert len(joined.t) == len(seg) and set(seg) == {0, 1}
    assert np.array_equal(joined.t, np.arange(len(joined.t)) * TS)
    assert np.array_equal(joined.axes["X"][seg == 0], a.axes["X"])
    assert joined.axes["X"][np.flatnonzero(seg == 1)[0]] == a.axes["X"][-1]  # continues from the end
    only_y = interpolate(_prog("G0 Y1\nG1 Y2 F600\nM2\n"))
    both, seg2 = concatenate([a, only_y])
    assert np.all(both.axes["Y"][seg2 == 0] == 1.0)  # held at its first value before it appears
    assert np.all(both.axes["X"][seg2 == 1] == a.axes["X"][-1])


def test_25_second_program_is_interpolated_quickly_enough_to_not_matter():
    # Structural check only (no timing assertion): a 200-move high set is ~20 s at 1 kHz.
    _, high = identification_programs()
    tr = interpolate(parse_program(dialects.write(high, "iso")))
    assert 15.0 < tr.duration < 30.0 and len(tr.t) == round(tr.duration / TS) + 1


@pytest.mark.parametrize(
    "kwargs, message",
    [({"Ts": 0.0}, "Ts must be a positive"), ({"a_max": -1.0}, "a_max must be a positive"),
     ({"j_max": 0.0}, "j_max must be a positive"), ({"rapid_feed": float("inf")}, "rapid_feed must be a positive")],
)
def test_bad_parameters_are_input_errors(kwargs, message):
    with pytest.raises(InputError, match=message):
        interpolate(_prog("G0 X1\n"), **kwargs)


def test_an_arc_in_the_xz_plane_turns_as_rs274_counts_it():
    """G18 G2 from X0 to X10 about X5: clockwise in LinuxCNC's (Z, X) frame (rs274 prints
    ARC_FEED(z, x, zc, xc, -1)), so the path dips to Z = -5 on a 5 mm radius."""
    tr = interpolate(parse_program("G21 G0 X0 Y0 Z0\nG18 G2 X10 Z0 I5 K0 F600\nM2\n"))
    x, z = tr.axes["X"], tr.axes["Z"]
    assert z.min() == pytest.approx(-5.0, abs=1e-6) and z.max() <= 1e-9
    assert np.max(np.abs(np.hypot(x - 5.0, z) - 5.0)) < 1e-6


def test_an_arc_with_p_turns_runs_every_turn():
    """G3 … P3 back to its start point runs three full circles (3 × 2π·5 mm at 10 mm/s)."""
    tr = interpolate(parse_program("G21 G0 X0 Y0\nG3 X0 Y0 I5 J0 P3 F600\nM2\n"))
    assert tr.t[-1] == pytest.approx(3 * 2 * np.pi * 5.0 / 10.0, rel=0.01)
    y = tr.axes["Y"]
    crossings = np.count_nonzero((y[:-1] < 0) & (y[1:] >= 0))  # once per turn, up through the start
    assert crossings == 3

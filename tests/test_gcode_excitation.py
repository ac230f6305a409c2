"""Identification programs (thesis §3.3, Tables 3.2/4.3/4.4): limits, seeds, spread of moves."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from gcode_gen.excitation import ExcitationSpec, high_speed_program, identification_programs, low_speed_program


def _targets(tp, axis="X"):
    return np.array([b.target[axis] for b in tp.blocks])


def test_defaults_follow_the_thesis():
    low, high = identification_programs()
    # positioning rapid + 200 random moves (+ the high set's return to the centre)
    assert len(low.blocks) == 201 and len(high.blocks) == 202
    assert all(b.motion == "G1" for b in low.blocks)  # even the positioning move: no rapid above the feed limit
    assert {b.feed for b in high.blocks[1:]} == {200.0}
    assert low.header["seed"] == "1" and low.header["range"] == "10" and low.header["low_step"] == "0.03"
    assert high.header["set"] == "high" and high.header["n_high"] == "200"


@pytest.mark.parametrize("seed", range(40))
def test_limits_hold_for_many_seeds(seed):
    rng = np.random.default_rng(seed)
    center = float(rng.uniform(-100, 100))
    R = float(rng.uniform(0.05, 30))
    step = float(rng.uniform(0.0002, min(R, 0.1)))
    feed = float(rng.uniform(1, 500))
    dist = "loguniform" if seed % 2 else "uniform"
    low, high = identification_programs(center=center, range_mm=R, low_step=step, n_low=150, n_high=150,
                                        feed=feed, seed=seed, distribution=dist)
    for tp in (low, high):
        x = _targets(tp)
        assert np.all(x >= center - R) and np.all(x <= center + R)
        assert all(b.feed is None or b.feed <= feed for b in tp.blocks)
    steps = np.abs(np.diff(_targets(low)))  # every move of the low set, from the centre on
    assert steps.max() <= step + 1e-12 and steps.min() > 0


def test_low_set_steps_spread_up_to_the_limit_with_many_reversals():
    low = low_speed_program(ExcitationSpec(n_low=2000, seed=3))
    d = np.diff(_targets(low))
    assert np.abs(d).max() == pytest.approx(0.03)
    # magnitudes uniform on (0, 0.03]: mean 0.015, every tenth of the interval visited
    assert np.abs(d).mean() == pytest.approx(0.015, rel=0.05)
    assert len(np.unique(np.floor(np.abs(d) / 0.003))) >= 10
    reversals = np.mean(np.sign(d[1:]) != np.sign(d[:-1]))
    assert 0.4 < reversals < 0.6


def test_high_set_uniform_targets_reach_full_stroke_and_reverse_often():
    high = high_speed_program(ExcitationSpec(n_high=2000, seed=5))
    x = _targets(high)
    assert list(x[1:3]) == [-10.0, 10.0]  # the full stroke, where the full feed is reached
    d = np.diff(x[1:-1])
    # uniform i.i.d. targets: |d| has a triangular density on [0, 20] with mean 20/3
    assert np.abs(d).mean() == pytest.approx(20 / 3, rel=0.06)
    assert np.mean(np.sign(d[1:]) != np.sign(d[:-1])) == pytest.approx(2 / 3, abs=0.05)


def test_loguniform_steps_cover_every_decade():
    high = high_speed_program(ExcitationSpec(n_high=1000, seed=2, distribution="loguniform"))
    d = np.abs(np.diff(_targets(high)[3:-1]))
    counts = np.histogram(np.log10(d[d > 0]), bins=[-2, -1, 0, 1, 1.31])[0]
    assert np.all(counts > 100)


def test_same_seed_same_program_other_seed_different():
    a = identification_programs(seed=11)
    b = identification_programs(seed=11)
    c = identification_programs(seed=12)
    assert a == b
    assert _targets(a[1]).tolist() != _targets(c[1]).tolist()
    assert _targets(a[0]).tolist() != _targets(c[0]).tolist()


def test_several_axes_get_independent_targets_and_own_centres():
    low, high = identification_programs(axes=("X", "Y"), center=(100.0, -50.0), range_mm=5.0)
    x, y = _targets(high, "X"), _targets(high, "Y")
    assert np.all(np.abs(x - 100) <= 5) and np.all(np.abs(y + 50) <= 5)
    assert abs(np.corrcoef(x[3:-1], y[3:-1])[0, 1]) < 0.3
    assert high.header["center"] == "100,-50" and high.header["axes"] == "X,Y"


def test_targets_are_on_the_output_grid():
    low, high = identification_programs(center=0.123456789)
    for tp, dec in ((low, 4), (high, 3)):
        x = _targets(tp)
        assert np.all(x == np.round(x, dec))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"range_mm": -1.0}, "range must be a positive"),
        ({"feed": 0.0}, "feed must be a positive"),
        ({"n_low": 0}, "n-low must be an integer >= 1"),
        ({"n_high": -5}, "n-high must be an integer >= 1"),
        ({"low_step": 20.0}, "larger than the range"),
        ({"low_step": 0.00001}, "below the output resolution"),
        ({"axes": ("Q",)}, "unknown axis letter 'Q'"),
        ({"axes": ("X", "X")}, "axis given twice"),
        ({"axes": ("X", "Y"), "center": (1.0, 2.0, 3.0)}, "3 centre values for 2 axes"),
        ({"distribution": "gauss"}, "unknown distribution"),
        ({"range_mm": float("nan")}, "range must be a positive"),
    ],
)
def test_invalid_parameters_give_one_line_errors(kwargs, message):
    with pytest.raises(InputError, match=message) as err:
        identification_programs(**kwargs)
    assert "\n" not in str(err.value)

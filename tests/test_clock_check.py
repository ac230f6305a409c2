"""drivers.plausibility.ClockCheck: the controller's clock against the host's (issue 40, items 5 and 6)."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.plausibility import CLOCK_WINDOW_S, ClockCheck


def feed(check: ClockCheck, ticks_per_host_s: float, host_s: float, T: float = 0.001, backlog: int = 0):
    """Batches every 20 ms of host time from a controller making ``ticks_per_host_s`` ticks per host
    second, the first batch carrying ``backlog`` older ticks; the first error, or None."""
    c0 = 5000 + backlog
    for i in range(int(host_s / 0.02) + 1):
        h = 100.0 + i * 0.02
        err = check.check(c0 + round(i * 0.02 * ticks_per_host_s), h)
        if err:
            return err
    return None


@pytest.mark.parametrize("rate", [1000.0, 1010.0, 990.0])
def test_a_controller_on_time_passes(rate):
    assert feed(ClockCheck(0.001), rate, 10.0, backlog=2000) is None


@pytest.mark.parametrize("rate, ratio", [(2000.0, "2"), (500.0, "0.5"), (1000.0 * 65536, "6.55e+04")])
def test_a_clock_running_fast_or_slow_is_an_error_naming_the_ratio(rate, ratio):
    err = feed(ClockCheck(0.001, hint="period_s in X"), rate, 3.0)
    assert err is not None and f"runs {ratio} times as fast as the host's" in err and err.endswith("check period_s in X")


def test_nothing_is_judged_before_the_window_of_host_time():
    assert feed(ClockCheck(0.001), 2000.0, CLOCK_WINDOW_S * 0.9) is None


def test_a_stall_of_the_capture_is_not_a_slow_clock():
    check = ClockCheck(0.001)
    assert check.check(0, 0.0) is None
    # 0.4 s of stall right after the start, then on time: ratio 0.71 at 1.4 s, but only 0.4 s apart
    assert check.check(1000, 1.4) is None


def feed_arrivals(check: ClockCheck, arrivals) -> str | None:
    """Feed (counter, host s) arrivals in order; the first error, or None."""
    for c, h in arrivals:
        err = check.check(c, h)
        if err:
            return err
    return None


def on_time(t0: float, t1: float, rate: float = 1000.0, every: float = 0.02):
    """Batches every ``every`` s of host time from t0 to t1, each carrying the tick made then."""
    return [(round(h * rate), h) for h in np.arange(t0, t1, every)]


def test_a_stall_of_the_controller_or_the_link_is_not_a_slow_clock():
    # on time for 1 s, then nothing for 0.7 s; the first batch after the pause carries the
    # counter the controller had reached when it paused, then it catches up
    arrivals = on_time(0.0, 1.0) + [(1000, 1.7)] + on_time(1.72, 6.0)
    assert feed_arrivals(ClockCheck(0.001), arrivals) is None


def test_a_slow_clock_is_found_through_stalls():
    # a controller at 2 ms announced as 1 ms, its batches held up 0.4 s twice
    arrivals = [(c, h) for c, h in on_time(0.0, 6.0, rate=500.0) if not (1.0 < h < 1.4 or 3.0 < h < 3.4)]
    err = feed_arrivals(ClockCheck(0.001), arrivals)
    assert err is not None and "runs 0.5 times as fast" in err


def test_a_replay_at_a_known_speed_is_expected_to_run_that_fast():
    assert feed(ClockCheck(0.001, expected=2.0), 2000.0, 5.0) is None
    assert feed(ClockCheck(0.001, expected=2.0), 1000.0, 5.0) is not None
    assert feed(ClockCheck(0.001, expected=float("inf")), 1e9, 5.0) is None


def test_replay_speed_is_an_option_of_every_port_checked_before_any_io(tmp_path):
    from core.errors import InputError
    from drivers.capture import capture

    with pytest.raises(InputError, match="replay_speed=0 must be > 0"):
        capture("serial:///nonexistent/tty?replay_speed=0", tmp_path / "a.mcap", progress=False)
    with pytest.raises(InputError, match="unknown option 'replay'"):  # the others still reach the driver
        capture("serial:///nonexistent/tty?replay=2", tmp_path / "a.mcap", progress=False)

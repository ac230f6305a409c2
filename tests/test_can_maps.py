"""CAN layouts and tick assembly: EDS/PDO mapping (canopen), DBC signals (cantools), counter unwrapping."""

from __future__ import annotations

import struct

import canopen
import pytest

from core.errors import InputError
from drivers.transports import canopen_map as com
from drivers.transports.can_ticks import ControllerRestart, CounterError, CounterUnwrapper, TickAssembler
from drivers.transports.dbc_map import DEFAULT_DBC, load_dbc, per_mm


def _remote(node_id: int, eds=com.DEFAULT_AXIS_EDS) -> canopen.RemoteNode:
    net = canopen.Network()  # no bus: mapping read from the EDS only
    return net.add_node(canopen.RemoteNode(node_id, com.load_od(eds, node_id)))


# -- EDS / PDO --------------------------------------------------------------------------
@pytest.mark.parametrize("node_id", [1, 3, 127])
def test_axis_eds_maps_demand_and_actual_position_in_one_sync_tpdo(node_id):
    lay = com.axis_pdo(_remote(node_id), from_od=True)
    assert lay.cob_id == 0x180 + node_id
    assert lay.length == 8 and lay.trans_type == 1
    assert lay.fields == ((0x6062, 0), (0x6064, 0))
    frame = struct.pack("<ii", -123456, 7890123)
    vals = lay.compiled().unpack(frame)
    assert vals[lay.position(com.POSITION_DEMAND)] == -123456
    assert vals[lay.position(com.POSITION_ACTUAL)] == 7890123


def test_status_eds_maps_segment_and_state():
    lay = com.status_pdo(_remote(64, com.DEFAULT_STATUS_EDS), from_od=True)
    assert (lay.cob_id, lay.length, lay.trans_type) == (0x1C0, 3, 254)
    vals = lay.compiled().unpack(bytes([1, 0, com.STATE_ENDED]))
    assert vals[lay.position(com.PROGRAM_STATUS, 1)] == 1
    assert vals[lay.position(com.PROGRAM_STATUS, 2)] == com.STATE_ENDED


def test_sync_parameters_come_from_the_eds():
    p = com.sync_params(_remote(2), from_od=True)
    assert (p.cob_id, p.overflow, p.period_s) == (0x80, 240, pytest.approx(0.001))


def test_a_node_without_position_tpdo_is_a_one_line_error():
    # the status node's EDS has a TPDO, but not 0x6062/0x6064
    with pytest.raises(InputError, match=r"node 5: no enabled TPDO maps both 0x6062"):
        com.axis_pdo(_remote(5, com.DEFAULT_STATUS_EDS), from_od=True)


def test_missing_or_malformed_eds_is_a_one_line_error(tmp_path):
    with pytest.raises(InputError, match="not found"):
        com.load_od(tmp_path / "nope.eds", 1)
    bad = tmp_path / "bad.eds"
    bad.write_text("[1000]\nParameterName=x\nObjectType=0x7\nDataType=0x0007\n")
    with pytest.raises(InputError, match="cannot be read"):
        com.load_od(bad, 1)


# -- DBC --------------------------------------------------------------------------------
def test_dbc_fixture_has_a_counter_frame_and_one_frame_per_axis():
    lay = load_dbc(DEFAULT_DBC, ["X", "Z"])
    assert lay.tick_id == 0x100 and lay.modulus == 1 << 16 and lay.has_segment and lay.has_state
    assert [(p.frame_id, p.axes, p.per_mm) for p in lay.parts] == [
        (0x101, ((0, "X_commanded", "X_actual"),), (10000.0,)),
        (0x103, ((1, "Z_commanded", "Z_actual"),), (10000.0,)),
    ]
    assert load_dbc(DEFAULT_DBC).axes == tuple("XYZABC")


def test_dbc_positions_decode_as_increments_over_increments_per_mm():
    lay = load_dbc(DEFAULT_DBC, ["X"])
    msg = lay.parts[0].message
    data = msg.encode({"X_commanded": 12345, "X_actual": -3}, scaling=False)
    raw = msg.decode(data, scaling=False)
    assert raw["X_commanded"] / lay.parts[0].per_mm[0] == 1.2345  # not 1.2345000000000002
    assert per_mm(0.0001) == 10000.0 and per_mm(0.3) == pytest.approx(1 / 0.3)


def test_dbc_unknown_axis_is_a_one_line_error():
    with pytest.raises(InputError, match=r"axis 'Q' needs signals Q_commanded and Q_actual \(axes found: A, B, C, X, Y, Z\)"):
        load_dbc(DEFAULT_DBC, ["X", "Q"])


# -- counter unwrapping and tick assembly ----------------------------------------------------
def test_sync_counter_1_to_240_unwraps_to_a_monotonic_counter():
    u = CounterUnwrapper(240, first=1, period_s=0.001)
    raw = [k % 240 + 1 for k in range(1000)]
    assert [u(r, 0.001 * k) for k, r in enumerate(raw)] == list(range(1000))


def test_a_silence_longer_than_a_wrap_is_resolved_with_the_receive_times():
    u = CounterUnwrapper(240, first=1, period_s=0.001)
    for k in range(500):
        u(k % 240 + 1, 0.001 * k)
    k = 499 + 1000  # 1000 ticks not heard: 4 wraps and 40 ticks
    assert u(k % 240 + 1, 0.001 * k + 0.0004) == k


def test_a_capture_that_opens_on_a_late_frame_is_live_and_numbers_a_silence_by_the_host_clock():
    # the first frame was held back 8 ms by the sender: measured from it, the stream would run
    # more than 2 % fast for 400 ticks and be taken for a replay, whose counter is read as it
    # reads, so a silence of 4 wraps there would lose 960 ticks without a word
    u = CounterUnwrapper(240, first=1, period_s=0.001)
    assert [u(k % 240 + 1, 0.001 * k + (0.008 if k == 0 else 0.0)) for k in range(200)] == list(range(200))
    k = 199 + 1000
    assert u(k % 240 + 1, 0.001 * k) == k


def test_a_pause_of_a_replay_faster_than_real_time_is_not_read_as_wraps():
    u = CounterUnwrapper(240, first=1, period_s=0.001)
    for k in range(500):  # served 50x faster than the controller's clock
        u(k % 240 + 1, 2e-5 * k)
    # the sender pauses 0.15 s (a garbage collection) and goes on with the next tick: at
    # the host period measured (20 µs) that would be 7500 ticks; the controller's own
    # clock gives 150, under one wrap
    assert u(500 % 240 + 1, 2e-5 * 499 + 0.15) == 500


def test_a_replay_whose_average_rate_passes_the_controllers_is_still_numbered_as_it_reads():
    u = CounterUnwrapper(240, first=1, period_s=0.001)
    got, ts = [], 0.0
    for k in range(2000):  # served as fast as possible (10 µs a tick); the sender stalls 0.35 s at
        ts += 0.35 if k == 300 else 1e-5  # tick 300, so that about tick 350 it has averaged 1 ms a tick
        got.append(u(k % 240 + 1, ts))
    assert got == list(range(2000))


def test_a_replay_slower_than_real_time_that_stalls_before_its_rate_is_known_is_numbered_as_it_reads():
    u = CounterUnwrapper(240, first=1, period_s=0.001)
    got, ts = [], 0.0
    for k in range(300):  # played at 1.5 ms a tick; the player stalls 0.7 s at tick 50, before the
        ts += 0.7 if k == 50 else 0.0015  # 100 ticks that establish its rate: by the host clock
        got.append(u(k % 240 + 1, ts))  # that is 720 ticks more, as the counter reads none
    assert got == list(range(300))


def test_a_live_silence_in_the_first_ticks_whose_next_frame_is_late_is_refused_not_read_as_a_replay():
    # 16 ticks on time, 700 lost, then a frame 1 ms late: later than any frame so far, so the host
    # clock cannot resolve the wraps; the 16 ticks ran at the controller's pace, so this is no replay
    # whose counter could be taken as it reads (which would number it 236, 480 ticks short)
    u = CounterUnwrapper(240, first=1, period_s=0.001)
    assert [u(k % 240 + 1, 0.001 * k) for k in range(16)] == list(range(16))
    with pytest.raises(CounterError, match="cannot tell how many ticks passed"):
        u(716 % 240 + 1, 0.716 + 0.001)


@pytest.mark.parametrize("silence_at", [10, 300])
def test_a_live_capture_whose_first_frames_came_in_a_burst_numbers_a_later_silence_by_the_host_clock(silence_at):
    # the sender held its first frames back 10 ms and sent them together (one of them lost): for
    # its first ticks the stream runs "fast", as a replay would; a silence of 700 ticks after is
    # still numbered by the host clock, before and after the stream's rate is established
    u = CounterUnwrapper(240, first=1, period_s=0.001)
    ticks = [k for k in range(silence_at + 800) if k != 1 and not silence_at <= k < silence_at + 700]
    got = [u(k % 240 + 1, 0.010 + 1e-5 * k if k < 6 else 0.001 * k) for k in ticks]
    assert got == ticks


def test_ticks_missing_a_part_are_not_emitted_and_counted_lost():
    asm = TickAssembler(2, 2, CounterUnwrapper(240, 1, 0.001), 0.001)
    out = []
    for k in range(6):
        asm.open_tick(k % 240 + 1, k * 0.001)
        for part in (0, 1):
            if (k, part) == (2, 1):
                continue  # frame lost
            s = asm.part(part, [(part, k + 0.5, -k)])
            if s:
                out.append(s)
    asm.open_tick(7 % 240 + 1, 0.007)  # counter 6 never seen
    assert [s.counter for s in out] == [0, 1, 3, 4, 5]
    assert out[2].commanded == (3.5, 3.5) and out[2].t_s == pytest.approx(0.003)
    assert asm.lost_ticks == 2 and asm.incomplete_ticks == 1


def test_a_part_repeated_within_a_tick_is_ignored():
    asm = TickAssembler(1, 2, CounterUnwrapper(240, 1, 0.001), 0.001)
    asm.open_tick(1, 0.0)
    assert asm.part(0, [(0, 1.0, 1.0)]) is None
    assert asm.part(0, [(0, 9.0, 9.0)]) is None  # its SYNC was lost: cannot be stamped
    assert asm.orphan_parts == 1


def test_a_repeated_counter_value_is_a_repeat_not_a_wrap():
    u = CounterUnwrapper(240, first=1, period_s=0.001)
    got = [u(k % 240 + 1, 0.001 * k) for k in range(300)]
    assert u(300 % 240, 0.001 * 299 + 0.0002) is None  # tick 299's SYNC again
    assert got == list(range(300)) and u(300 % 240 + 1, 0.3) == 300


def test_without_a_counter_ticks_are_numbered_by_arrival_and_host_time():
    u = CounterUnwrapper(1, first=1, period_s=0.002)
    sent = [k for k in range(400) if k not in (5, 6, 200) and not 250 <= k < 400 - 50]
    assert [u(0, 0.002 * k + 1e-5 * (k % 7)) for k in sent] == sent


def test_a_counter_ahead_of_the_host_clock_is_a_restart():
    u = CounterUnwrapper(240, first=1, period_s=0.001)
    for k in range(500):
        u(k % 240 + 1, 0.001 * k)
    with pytest.raises(ControllerRestart, match=r"jumped by 221 \(20 -> 1\) in 1\.0 ms.*restarted"):
        u(1, 0.500)  # counter back to 1 one period later


def stalling_sender(stall_ms: int) -> CounterUnwrapper:
    """500 ticks of a 4-bit counter whose sender stalls ``stall_ms`` every 50 ticks, then sends what it held."""
    u = CounterUnwrapper(16, first=0, period_s=0.001)
    for k in range(500):
        j = (k + 25) % 50
        u(k % 16, 0.001 * k + ((stall_ms - j) * 0.00096 if j < stall_ms else 0.0))
    return u


def test_a_silence_is_resolved_when_fewer_wraps_would_make_the_frame_later_than_twice_the_jitter():
    u = stalling_sender(7)  # frames up to 6.7 ticks late; 24 ticks would make this one 16 late
    k = 499 + 40
    assert u(k % 16, 0.001 * k) == k


def test_a_silence_the_jitter_cannot_resolve_is_refused():
    u = stalling_sender(9)  # frames up to 8.6 ticks late: 16 ticks late is within twice that
    k = 499 + 40  # after 40 ticks of silence: 40 or 24 ticks?
    with pytest.raises(CounterError, match=r"cannot tell how many ticks passed \(40 or 24\)") as err:
        u(k % 16, 0.001 * k)
    assert not isinstance(err.value, ControllerRestart)


def test_ticks_numbered_across_a_silence_are_held_until_later_frames_confirm_them():
    asm = TickAssembler(1, 1, CounterUnwrapper(16, 0, 0.001), 0.001)
    out, last_out = [], {}
    for k in list(range(200)) + list(range(230, 240)):
        out += asm.open_tick(k % 16, 0.001 * k)
        s = asm.part(0, [(0, float(k), -float(k))])
        out += [s] if s else []
        last_out[k] = out[-1].counter
    assert [last_out[k] for k in (230, 231, 232, 233)] == [199, 199, 199, 233]  # 2.5 periods on hold
    assert [s.counter for s in out] == list(range(200)) + list(range(230, 240))
    assert [s.commanded[0] for s in out][-10:] == [float(k) for k in range(230, 240)]

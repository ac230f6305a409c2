"""The Modbus register map: loading, validation (one-line errors), read planning and value codecs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.errors import MachineError
from drivers.modbus_map import (
    MAX_READ_REGISTERS,
    decode_info,
    decode_u32,
    default_map,
    encode_info,
    encode_u32,
    load_map,
    plan_reads,
)

FIXTURE = Path(__file__).resolve().parent.parent / "fixtures" / "modbus" / "default_map.toml"


def test_fixture_is_the_default_layout_for_xyz():
    rmap = load_map(FIXTURE)
    assert rmap == default_map(["X", "Y", "Z"])
    assert rmap.axis_names == ("X", "Y", "Z")
    assert rmap.record_words == 3 + 4 * 3
    assert rmap.function_code == 3


def test_to_toml_round_trips(tmp_path):
    rmap = default_map(["X", "Y", "Z", "A", "B", "C"], scale_mm=1e-5, word_order="little",
                       units=["mm", "mm", "mm", "deg", "deg", "deg"])
    path = tmp_path / "m.toml"
    path.write_text(rmap.to_toml())
    assert load_map(path) == rmap


def _write(tmp_path, text: str) -> Path:
    path = tmp_path / "map.toml"
    path.write_text(FIXTURE.read_text() + text)
    return path


def _replace(tmp_path, old: str, new: str) -> Path:
    text = FIXTURE.read_text()
    assert old in text
    path = tmp_path / "map.toml"
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize(
    "old, new, message",
    [
        ('word_order = "big" ', 'word_order = "middle" ', "word_order = 'middle'"),
        ('table = "holding"', 'table = "coils"', "device.table = 'coils'"),
        ("scale_mm = 1e-6          # mm per count (1 nm)", "scale_mm = -1e-6", "scale_mm = -1e-06"),
        ("commanded = 268", "commanded = 265", "overlaps"),
        ("base = 1024", "base = 100", "inside the trace ring"),
        ("max_registers = 125", "max_registers = 200", "max_registers = 200"),
        ("max_registers = 125", "max_registers = 10", "needs 15 registers"),
        ('name = "Y"', 'name = "X"', "axis 'X' given twice"),
        ("unit = 1 ", "unit = 300 ", "unit = 300"),
        ("actual = 266", 'actual = "266"', "axis X.actual = '266' is not an integer"),
        ("[status]\naddress = 256", "[status]\naddres = 256", "unknown key status.addres"),
        ("commanded = 264", "commanded = 70000", "outside the register space"),
    ],
)
def test_bad_maps_give_one_line_errors_naming_the_field(tmp_path, old, new, message):
    path = _replace(tmp_path, old, new)
    with pytest.raises(MachineError, match="register map ") as info:
        load_map(path)
    text = str(info.value)
    assert message in text
    assert "\n" not in text


def test_unknown_section_missing_section_bad_toml_and_missing_file(tmp_path):
    with pytest.raises(MachineError, match=r"unknown section \[spindle\]"):
        load_map(_write(tmp_path, "\n[spindle]\nspeed = 1\n"))
    with pytest.raises(MachineError, match=r"missing section \[counter\]"):
        load_map(_strip_counter(tmp_path))
    with pytest.raises(MachineError, match="not valid TOML"):
        bad = tmp_path / "bad.toml"
        bad.write_text("[device\nunit = 1")
        load_map(bad)
    with pytest.raises(MachineError, match="no such file"):
        load_map(tmp_path / "none.toml")


def _strip_counter(tmp_path) -> Path:
    text = FIXTURE.read_text()
    start = text.index("[counter]")
    end = text.index("[trace]")
    path = tmp_path / "nocounter.toml"
    path.write_text(text[:start] + text[end:])
    return path


def test_no_axes_is_an_error(tmp_path):
    text = FIXTURE.read_text()
    path = tmp_path / "noaxes.toml"
    path.write_text(text[:text.index("[[axis]]")])
    with pytest.raises(MachineError, match=r"no \[\[axis\]\] given"):
        load_map(path)


def test_plan_reads_merges_nearby_fields_and_respects_the_125_register_limit():
    live = [(a, w) for _, a, w, _ in default_map(["X", "Y", "Z"]).live_fields()]
    assert plan_reads(live) == [(256, 20)]  # status..Z.actual in one request
    assert plan_reads([(0, 256)]) == [(0, 125), (125, 125), (250, 6)]
    spans = plan_reads([(0, 2), (10, 2), (200, 1), (300, 125)], max_registers=125, max_gap=16)
    assert spans == [(0, 12), (200, 1), (300, 125)]
    many = plan_reads([(a, 2) for a in range(0, 400, 4)])
    assert all(n <= MAX_READ_REGISTERS for _, n in many)
    covered = {r for a, n in many for r in range(a, a + n)}
    assert all(a in covered and a + 1 in covered for a in range(0, 400, 4))


@pytest.mark.parametrize("order", ["big", "little"])
def test_32_bit_values_round_trip_in_both_word_orders(order):
    values = np.array([0, 1, -1, 65535, 65536, -65536, 2**31 - 1, -(2**31)], dtype=np.int64)
    words = encode_u32(values, order)
    assert words.shape == (len(values), 2)
    assert np.array_equal(decode_u32(words[:, 0], words[:, 1], order, signed=True), values)
    assert np.array_equal(decode_u32(words[:, 0], words[:, 1], order, signed=False), values & 0xFFFFFFFF)
    if order == "big":
        assert encode_u32(np.array(0x12345678), order).tolist() == [0x1234, 0x5678]
    else:
        assert encode_u32(np.array(0x12345678), order).tolist() == [0x5678, 0x1234]


def test_info_block_round_trips_and_truncates_what_does_not_fit():
    info = {"controller": "rapid-ident virtual CNC (fadal-ppi)", "axes": "X,Y", "period_s": "0.001",
            "program": ["low.nc " + "a" * 64, "high.nc " + "b" * 64]}
    regs = encode_info(info, 256)
    assert len(regs) == 256 and all(0 <= r <= 0xFFFF for r in regs)
    assert decode_info(regs) == info
    short = decode_info(encode_info(info, 40))  # 78 bytes: room for the first lines only
    assert short["controller"] == info["controller"] and short.get("truncated") == "1"
    assert short["program"] == []

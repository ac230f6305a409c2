"""The serial wire formats: round trips, integrity checks, resynchronisation, exact counting."""

from __future__ import annotations

import random
import zlib

import pytest

from core.errors import InputError
from drivers.transports.serial_framing import (
    AsciiCodec,
    BinaryCodec,
    EndFrame,
    InfoFrame,
    SampleFrame,
    _line,
    codec_for,
)

INFO = InfoFrame(counter=7, period_ns=1_000_000, counts_per_mm=10_000, axes=("X", "Y", "Z"),
                 units=("mm", "mm", "mm"), controller="Acme CNC 5, fw 1.2, ünïcode, comma",
                 programs=({"name": "low speed,1.nc", "sha256": "ab" * 32}, {"name": "hi.nc", "sha256": "cd" * 32}))


def _samples(n: int, start: int = 0, axes: int = 3, seed: int = 0) -> list[SampleFrame]:
    rng = random.Random(seed)
    return [SampleFrame((start + k) & 0xFFFFFFFF, k // 50,
                        tuple(rng.randint(-2**31, 2**31 - 1) for _ in range(axes)),
                        tuple(rng.randint(-2**31, 2**31 - 1) for _ in range(axes))) for k in range(n)]


def _encode(codec, frame) -> bytes:
    if isinstance(frame, SampleFrame):
        return codec.encode_sample(frame.counter, frame.segment, frame.commanded, frame.actual)
    if isinstance(frame, InfoFrame):
        return codec.encode_info(frame)
    return codec.encode_end(frame.counter)


CODECS = [BinaryCodec, AsciiCodec]


@pytest.mark.parametrize("cls", CODECS)
def test_round_trip_of_info_samples_and_end(cls):
    frames = [INFO, *_samples(200), EndFrame(199)]
    enc, dec = cls(), cls()
    assert dec.feed(b"".join(_encode(enc, f) for f in frames)) == frames
    assert dec.corrupt == 0 and dec.skipped_bytes == 0


@pytest.mark.parametrize("cls", CODECS)
def test_frames_split_at_every_byte_boundary_still_decode(cls):
    frames = [INFO, *_samples(20)]
    data = b"".join(_encode(cls(), f) for f in frames)
    dec = cls()
    got = []
    for i in range(len(data)):
        got += dec.feed(data[i:i + 1])
    assert got == frames and dec.corrupt == 0


@pytest.mark.parametrize("cls", CODECS)
def test_each_damaged_frame_is_rejected_and_counted_once(cls):
    rng = random.Random(3)
    frames = [INFO, *_samples(500)]
    enc = cls()
    damaged = set(rng.sample(range(2, 501), 40)) | {100, 101, 102}  # include adjacent ones
    data = b"".join(enc.damage(_encode(enc, f), rng) if i in damaged else _encode(enc, f)
                    for i, f in enumerate(frames))
    dec = cls()
    got = dec.feed(data)
    assert dec.corrupt == len(damaged)
    assert got == [f for i, f in enumerate(frames) if i not in damaged]


def test_binary_crc_rejects_every_single_bit_flip_of_a_frame_body():
    enc = BinaryCodec()
    good = _encode(enc, _samples(1)[0])
    for i in range(2, len(good)):  # every byte after the sync word
        for bit in range(8):
            bad = bytearray(good)
            bad[i] ^= 1 << bit
            dec = BinaryCodec()
            dec.feed(_encode(enc, INFO))  # in sync
            frames = dec.feed(bytes(bad) + _encode(enc, EndFrame(0)))
            assert all(not isinstance(f, SampleFrame) for f in frames), (i, bit)


def test_binary_frame_layout_is_the_documented_one():
    data = BinaryCodec().encode_sample(0x01020304, 2, (10_000,), (-1,))
    assert data[:2] == b"\xa5\x5a" and data[2:3] == b"S"
    assert int.from_bytes(data[3:5], "little") == 8 + 8  # counter u32, segment u16, n u8, flags u8, 2 x int32
    assert data[5:9] == bytes([4, 3, 2, 1])
    assert data[11] == 1  # one axis
    assert int.from_bytes(data[13:17], "little", signed=True) == 10_000
    assert int.from_bytes(data[17:21], "little", signed=True) == -1
    assert int.from_bytes(data[-4:], "little") == zlib.crc32(data[2:-4])


def test_ascii_line_layout_is_the_documented_one():
    line = AsciiCodec().encode_sample(12, 0, (15_000, -3), (14_990, -4))
    assert line.startswith(b"$S,12,0,15000,14990,-3,-4*") and line.endswith(b"\r\n")
    body = line[1:line.index(b"*")]
    x = 0
    for b in body:
        x ^= b
    assert line[line.index(b"*") + 1:-2] == b"%02X" % x


def _binary_frame(ftype: bytes, payload: bytes) -> bytes:
    """A frame built from docs/serial-protocol.md alone: sync, type, length, payload, CRC-32."""
    body = ftype + len(payload).to_bytes(2, "little") + payload
    return b"\xa5\x5a" + body + zlib.crc32(body).to_bytes(4, "little")


def _info_payload(meta: dict, period_ns: int = 1_000_000, cpm: int = 10_000) -> bytes:
    import json
    return (0).to_bytes(4, "little") + period_ns.to_bytes(4, "little") + cpm.to_bytes(4, "little") + \
        json.dumps(meta).encode()


def test_binary_flags_and_reserved_are_ignored_whatever_their_value():
    codec = BinaryCodec()
    sample = (5).to_bytes(4, "little") + (0).to_bytes(2, "little") + bytes([1, 0xA7]) + \
        (15_000).to_bytes(4, "little", signed=True) + (-3).to_bytes(4, "little", signed=True)
    end = (9).to_bytes(4, "little") + (0xDEADBEEF).to_bytes(4, "little")
    frames = codec.feed(_binary_frame(b"S", sample) + _binary_frame(b"E", end))
    assert frames == [SampleFrame(5, 0, (15_000,), (-3,)), EndFrame(9)] and codec.corrupt == 0


def test_binary_info_needs_axes_period_and_scale_and_nothing_else():
    good = _binary_frame(b"I", _info_payload({"axes": ["X"]}))
    assert BinaryCodec().feed(good) == [InfoFrame(0, 1_000_000, 10_000, ("X",), (), "", ())]
    for bad in (_info_payload({"units": ["mm"]}), _info_payload({"axes": []}),
                _info_payload({"axes": ["X"]}, period_ns=0), _info_payload({"axes": ["X"]}, cpm=0)):
        codec = BinaryCodec()
        assert codec.feed(good + _binary_frame(b"I", bad)) == [InfoFrame(0, 1_000_000, 10_000, ("X",), (), "", ())]
        assert codec.corrupt == 1  # rejected like a damaged frame


def test_ascii_text_fields_decode_every_percent_escape():
    line = _line("I,0,1000000,10000,X,,50%25 load%2C %C2%B5m,a%3Ab.nc:" + "ab" * 32)
    (info,) = AsciiCodec().feed(line)
    assert info.controller == "50% load, µm" and info.programs[0]["name"] == "a:b.nc"
    assert info.units == ()


@pytest.mark.parametrize("cls", CODECS)
def test_resynchronises_after_random_garbage_without_inventing_frames(cls):
    rng = random.Random(11)
    enc = cls()
    before, after = _samples(30, 0), _samples(30, 1000, seed=1)
    garbage = bytes(rng.randrange(256) for _ in range(3000))
    dec = cls()
    got = dec.feed(_encode(enc, INFO) + b"".join(_encode(enc, f) for f in before) + garbage
                   + b"\n" + b"".join(_encode(enc, f) for f in after))
    samples = [f for f in got if isinstance(f, SampleFrame)]
    assert samples == before + after  # nothing from the garbage passes the checks
    assert dec.corrupt >= 1 and dec.skipped_bytes >= len(garbage)


def test_binary_damaged_length_field_costs_frames_but_resyncs():
    enc = BinaryCodec()
    frames = _samples(10)
    chunks = [_encode(enc, f) for f in frames]
    bad = bytearray(chunks[4])
    bad[3] ^= 0x08  # length field: the frame no longer ends where it says
    dec = BinaryCodec()
    got = dec.feed(_encode(enc, INFO) + b"".join(chunks[:4]) + bytes(bad) + b"".join(chunks[5:]))
    samples = [f for f in got if isinstance(f, SampleFrame)]
    assert samples[:4] == frames[:4] and samples[-5:] == frames[5:]
    assert dec.corrupt == 1


@pytest.mark.parametrize("cls", CODECS)
def test_joining_mid_frame_skips_silently(cls):
    enc = cls()
    data = b"".join(_encode(enc, f) for f in _samples(5))
    dec = cls()
    got = dec.feed(data[7:])  # pyserial's open() threw the first bytes away
    assert got == _samples(5)[1:]
    assert dec.corrupt == 0 and dec.skipped_bytes > 0
    dec.reset()
    assert dec.feed(data[3:])[-1] == _samples(5)[-1] and dec.corrupt == 0


def test_ascii_rejects_wrong_checksum_missing_star_and_odd_field_count():
    dec = AsciiCodec()
    dec.feed(AsciiCodec().encode_end(0))  # in sync
    assert dec.feed(b"$S,1,0,1,2*00\r\n") == []
    assert dec.feed(b"$S,1,0,1,2\r\n") == []
    assert dec.feed(_line("S,1,0,1,2,3")) == []  # valid checksum, odd number of positions
    assert dec.feed(_line("S,1,0,1,x")) == []  # not a number
    assert dec.corrupt == 4


def test_unknown_format_is_a_one_line_error():
    with pytest.raises(InputError, match="serial format 'hex' is not known"):
        codec_for("hex")

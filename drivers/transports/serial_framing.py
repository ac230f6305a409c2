"""Wire formats of the serial sample stream: a framed binary format and a line-based ASCII one.

Both carry the same three messages (full description with byte tables in
docs/serial-protocol.md):

* **info** — sample period, position scale, axis names and units, controller
  description, programs (name + SHA-256).  Sent when streaming starts and then
  periodically (every second by default), so a capture that opens the port late —
  pyserial's ``open()`` discards the bytes already queued — still learns them.
* **sample** — the controller's sample counter (uint32, wraps), the program/segment
  index, and per axis the commanded and actual position as scaled integers
  (int32 counts; mm = counts / ``counts_per_mm``, default 10 000 counts/mm = 0.1 µm).
* **end** — the program has ended; carries the last sample counter.

Binary frame (little endian)::

    A5 5A | type (1) | length L (uint16) | payload (L bytes) | CRC-32 (uint32)

CRC-32 is the IEEE/zlib polynomial over type, length and payload.  ``type`` is
``'S'`` (0x53), ``'I'`` (0x49) or ``'E'`` (0x45).

ASCII lines (NMEA-like, checksum = XOR of the bytes between ``$`` and ``*``, two hex
digits, line ends ``\\r\\n``)::

    $I,<counter>,<period_ns>,<counts_per_mm>,<axes ;-sep>,<units ;-sep>,<controller>,<programs>*HH
    $S,<counter>,<segment>,<cmd1>,<act1>,...,<cmdN>,<actN>*HH
    $E,<counter>*HH

Decoders are incremental (:meth:`feed` bytes as they arrive, get whole frames back)
and resynchronise after lost or damaged bytes.  What they count:

* ``corrupt`` — frames rejected after the stream was in sync: a binary frame whose
  header is intact but whose CRC fails counts once and is skipped whole; a stretch of
  bytes that cannot be framed at all (e.g. a damaged length field) counts once; an
  ASCII line with a bad checksum or bad fields counts once.
* ``rejected_info`` — info messages that passed their checksum but lack a required
  field (period, scale or axes): they are also counted like damaged frames.
* ``skipped_bytes`` — bytes thrown away while searching for a frame.  Bytes before the
  first good frame after :meth:`reset` (joining a stream mid-frame) are skipped but
  not counted as corrupt.

Nothing that fails a check is ever returned as a frame.
"""

from __future__ import annotations

import json
import random
import struct
import zlib
from dataclasses import dataclass, field
from typing import Union
from urllib.parse import quote, unquote

__all__ = [
    "DEFAULT_COUNTS_PER_MM",
    "InfoFrame",
    "SampleFrame",
    "EndFrame",
    "Frame",
    "BinaryCodec",
    "AsciiCodec",
    "CODECS",
    "codec_for",
]

#: default position scale: 10 000 counts per mm = 0.1 µm resolution, int32 range ±214 m
DEFAULT_COUNTS_PER_MM = 10_000


@dataclass(frozen=True)
class InfoFrame:
    """Stream description; ``period_ns`` = controller sample period in ns."""

    counter: int
    period_ns: int
    counts_per_mm: int
    axes: tuple[str, ...]
    units: tuple[str, ...] = ()
    controller: str = ""
    programs: tuple[dict, ...] = ()


@dataclass(frozen=True)
class SampleFrame:
    """One tick: raw uint32 counter, segment, and per-axis positions in counts."""

    counter: int
    segment: int
    commanded: tuple[int, ...]
    actual: tuple[int, ...]


@dataclass(frozen=True)
class EndFrame:
    """End of program; ``counter`` is the last sample counter sent."""

    counter: int


Frame = Union[InfoFrame, SampleFrame, EndFrame]

U32 = 0xFFFFFFFF


# ======================================================================================
# binary
# ======================================================================================

SYNC = b"\xa5\x5a"
T_SAMPLE, T_INFO, T_END = 0x53, 0x49, 0x45
_HDR = struct.Struct("<2sBH")  # sync, type, length
_SAMPLE_HEAD = struct.Struct("<IHBB")  # counter, segment, n_axes, flags
_INFO_HEAD = struct.Struct("<III")  # counter, period_ns, counts_per_mm
_END = struct.Struct("<II")  # counter, reserved
_CRC = struct.Struct("<I")
MAX_AXES = 32
MAX_INFO = 16384


@dataclass
class BinaryCodec:
    """Encoder and incremental decoder of the framed binary format."""

    name: str = "binary"
    corrupt: int = 0
    skipped_bytes: int = 0
    rejected_info: int = 0
    _buf: bytearray = field(default_factory=bytearray, repr=False)
    _synced: bool = False
    _in_garbage: bool = False

    # -- encoding --------------------------------------------------------------------
    @staticmethod
    def _frame(ftype: int, payload: bytes) -> bytes:
        body = bytes([ftype]) + struct.pack("<H", len(payload)) + payload
        return SYNC + body + _CRC.pack(zlib.crc32(body))

    def encode_sample(self, counter: int, segment: int, commanded, actual) -> bytes:
        n = len(commanded)
        inter = [v for pair in zip(commanded, actual) for v in pair]
        payload = _SAMPLE_HEAD.pack(counter & U32, segment & 0xFFFF, n, 0) + struct.pack(f"<{2 * n}i", *inter)
        return self._frame(T_SAMPLE, payload)

    def encode_info(self, info: InfoFrame) -> bytes:
        text = json.dumps({"axes": list(info.axes), "units": list(info.units), "controller": info.controller,
                           "programs": list(info.programs)}, separators=(",", ":")).encode()
        return self._frame(T_INFO, _INFO_HEAD.pack(info.counter & U32, info.period_ns, info.counts_per_mm) + text)

    def encode_end(self, counter: int) -> bytes:
        return self._frame(T_END, _END.pack(counter & U32, 0))

    @staticmethod
    def damage(frame: bytes, rng: random.Random) -> bytes:
        """Flip one bit of one position byte, as line noise would; the CRC then fails.

        Only the position bytes are touched, so the frame boundaries stay intact and a
        decoder counts exactly one corrupt frame (a damaged header is covered by the
        resynchronisation tests instead).
        """
        start = _HDR.size + _SAMPLE_HEAD.size
        end = len(frame) - _CRC.size
        if end <= start:  # no positions: damage the payload anywhere
            start = _HDR.size
        i = rng.randrange(start, end)
        out = bytearray(frame)
        out[i] ^= 1 << rng.randrange(8)
        return bytes(out)

    # -- decoding --------------------------------------------------------------------
    def reset(self) -> None:
        """Forget buffered bytes; the next bytes may start mid-frame (port re-opened)."""
        self._buf.clear()
        self._synced = False
        self._in_garbage = False

    def _garbage(self, nbytes: int) -> None:
        self.skipped_bytes += nbytes
        if self._synced and not self._in_garbage:
            self.corrupt += 1
            self._in_garbage = True

    @staticmethod
    def _plausible(ftype: int, length: int) -> bool:
        if ftype == T_SAMPLE:
            return length >= _SAMPLE_HEAD.size and (length - _SAMPLE_HEAD.size) % 8 == 0 and \
                length <= _SAMPLE_HEAD.size + 8 * MAX_AXES
        if ftype == T_INFO:
            return _INFO_HEAD.size <= length <= MAX_INFO
        if ftype == T_END:
            return length == _END.size
        return False

    def feed(self, data: bytes) -> list[Frame]:
        """Append received bytes; return the complete, CRC-checked frames in order."""
        buf = self._buf
        buf += data
        frames: list[Frame] = []
        p, n = 0, len(buf)
        while True:
            i = buf.find(SYNC, p)
            if i < 0:
                keep = n - 1 if n and buf[-1] == SYNC[0] else n  # a sync may straddle the next read
                if keep > p:
                    self._garbage(keep - p)
                p = max(p, keep)
                break
            if i > p:
                self._garbage(i - p)
                p = i
            if n - p < _HDR.size:
                break
            _, ftype, length = _HDR.unpack_from(buf, p)
            if not self._plausible(ftype, length):
                self._garbage(1)
                p += 1
                continue
            end = p + _HDR.size + length + _CRC.size
            if end > n:
                break
            body = memoryview(buf)[p + 2:end - _CRC.size]
            if zlib.crc32(body) == _CRC.unpack_from(buf, end - _CRC.size)[0]:
                frame = self._decode(ftype, bytes(body[3:]))
                body.release()
                if frame is None:  # CRC fine but contents impossible: a protocol error
                    self.rejected_info += ftype == T_INFO
                    self._garbage(end - p)
                else:
                    frames.append(frame)
                    self._synced, self._in_garbage = True, False
                p = end
                continue
            body.release()
            # CRC failed.  If the next frame starts right after, only the contents were
            # damaged: count one corrupt frame and skip it whole.
            if end + 2 > n:
                break  # wait to see what follows
            if buf[end:end + 2] == SYNC:
                self.skipped_bytes += end - p
                if self._synced:
                    self.corrupt += 1
                self._in_garbage = False
                p = end
            else:  # the header itself was hit: hunt for the next sync byte by byte
                self._garbage(1)
                p += 1
        del buf[:p]
        return frames

    @staticmethod
    def _decode(ftype: int, payload: bytes) -> Frame | None:
        if ftype == T_SAMPLE:
            counter, segment, n, _flags = _SAMPLE_HEAD.unpack_from(payload)
            if len(payload) != _SAMPLE_HEAD.size + 8 * n:
                return None
            vals = struct.unpack_from(f"<{2 * n}i", payload, _SAMPLE_HEAD.size)
            return SampleFrame(counter, segment, vals[0::2], vals[1::2])
        if ftype == T_INFO:
            counter, period_ns, cpm = _INFO_HEAD.unpack_from(payload)
            try:
                meta = json.loads(payload[_INFO_HEAD.size:].decode())
                axes = tuple(str(a) for a in meta["axes"])
            except (ValueError, KeyError, TypeError, UnicodeDecodeError):
                return None
            if not axes or period_ns == 0 or cpm == 0:
                return None
            return InfoFrame(counter, period_ns, cpm, axes, tuple(meta.get("units", ())),
                             str(meta.get("controller", "")), tuple(meta.get("programs", ())))
        counter, _ = _END.unpack_from(payload)
        return EndFrame(counter)


# ======================================================================================
# ASCII
# ======================================================================================

MAX_LINE = 4096


def _checksum(body: bytes) -> int:
    x = 0
    for b in body:
        x ^= b
    return x


def _checksum_ok(line: bytes) -> bool:
    """Whether a ``$...*HH`` line's checksum holds (its fields may still be wrong)."""
    try:
        return line[-3:-2] == b"*" and int(line[-2:], 16) == _checksum(line[1:-3])
    except ValueError:
        return False


def _line(body: str) -> bytes:
    raw = body.encode("ascii")
    return b"$" + raw + b"*%02X\r\n" % _checksum(raw)


def _text(s: str) -> str:
    # keep , ; : * $ and line ends out of text fields
    return quote(s, safe=" ./-_()+=#@[]{}<>!?'\"&")


@dataclass
class AsciiCodec:
    """Encoder and incremental decoder of the NMEA-like ASCII lines."""

    name: str = "ascii"
    corrupt: int = 0
    skipped_bytes: int = 0
    rejected_info: int = 0
    _buf: bytearray = field(default_factory=bytearray, repr=False)
    _synced: bool = False

    # -- encoding --------------------------------------------------------------------
    def encode_sample(self, counter: int, segment: int, commanded, actual) -> bytes:
        vals = ",".join(f"{c},{a}" for c, a in zip(commanded, actual))
        return _line(f"S,{counter & U32},{segment},{vals}")

    def encode_info(self, info: InfoFrame) -> bytes:
        progs = ";".join(f"{_text(p.get('name', ''))}:{p.get('sha256', '')}" for p in info.programs)
        return _line(
            f"I,{info.counter & U32},{info.period_ns},{info.counts_per_mm},{';'.join(info.axes)},"
            f"{';'.join(info.units)},{_text(info.controller)},{progs}"
        )

    def encode_end(self, counter: int) -> bytes:
        return _line(f"E,{counter & U32}")

    @staticmethod
    def damage(line: bytes, rng: random.Random) -> bytes:
        """Change one digit of a position to another digit; the checksum then fails."""
        star = line.rindex(b"*")
        commas = [i for i, b in enumerate(line[:star]) if b == ord(",")]
        start = commas[2] + 1 if len(commas) > 2 else 1
        digits = [i for i in range(start, star) if chr(line[i]).isdigit()]
        i = rng.choice(digits)
        out = bytearray(line)
        out[i] = ord(rng.choice([d for d in "0123456789" if d != chr(line[i])]))
        return bytes(out)

    # -- decoding --------------------------------------------------------------------
    def reset(self) -> None:
        self._buf.clear()
        self._synced = False

    def _reject(self, nbytes: int) -> None:
        self.skipped_bytes += nbytes
        if self._synced:
            self.corrupt += 1

    def feed(self, data: bytes) -> list[Frame]:
        """Append received bytes; return the frames of the complete, checked lines."""
        self._buf += data
        frames: list[Frame] = []
        *lines, rest = self._buf.split(b"\n")
        if len(rest) > MAX_LINE:  # no line end for far too long: garbage
            self._reject(len(rest))
            rest = b""
        self._buf = bytearray(rest)
        for raw in lines:
            line = raw.rstrip(b"\r")
            if not line:
                continue
            frame = self._parse(line)
            if frame is None:
                self.rejected_info += line.startswith(b"$I,") and _checksum_ok(line)
                self._reject(len(raw) + 1)
            else:
                frames.append(frame)
                self._synced = True
        return frames

    @staticmethod
    def _parse(line: bytes) -> Frame | None:
        if len(line) < 5 or line[:1] != b"$" or line[-3:-2] != b"*":
            return None
        body = line[1:-3]
        try:
            if int(line[-2:], 16) != _checksum(body):
                return None
            f = body.decode("ascii").split(",")
            kind = f[0]
            if kind == "S":
                n2 = len(f) - 3
                if n2 <= 0 or n2 % 2:
                    return None
                vals = [int(v) for v in f[3:]]
                return SampleFrame(int(f[1]), int(f[2]), tuple(vals[0::2]), tuple(vals[1::2]))
            if kind == "I" and len(f) == 8:
                axes = tuple(a for a in f[4].split(";") if a)
                units = tuple(u for u in f[5].split(";") if u)
                programs = []
                for item in filter(None, f[7].split(";")):
                    name, _, sha = item.partition(":")
                    programs.append({"name": unquote(name), "sha256": sha})
                period_ns, cpm = int(f[2]), int(f[3])
                if not axes or period_ns <= 0 or cpm <= 0:
                    return None
                return InfoFrame(int(f[1]), period_ns, cpm, axes, units, unquote(f[6]), tuple(programs))
            if kind == "E" and len(f) == 2:
                return EndFrame(int(f[1]))
        except (ValueError, UnicodeDecodeError):
            return None
        return None


#: format name (the ``format=`` URL option) -> codec class
CODECS: dict[str, type] = {"binary": BinaryCodec, "ascii": AsciiCodec}


def codec_for(fmt: str):
    """A fresh codec for ``format=binary|ascii``; a one-line error for anything else."""
    from core.errors import InputError

    try:
        return CODECS[fmt]()
    except KeyError:
        raise InputError(f"serial format {fmt!r} is not known (known: {', '.join(CODECS)})") from None

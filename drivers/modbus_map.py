"""The Modbus register map of a controller: where the sample counter, the positions and the trace buffer live.

A map is a TOML file (documented in docs/modbus.md; ``fixtures/modbus/default_map.toml``
is the default layout for axes X, Y, Z, the one the simulated endpoint serves)::

    [device]
    unit = 1                 # Modbus unit (slave) id; the URL's unit= overrides it
    table = "holding"        # "holding" (read with FC 3) or "input" (FC 4)
    word_order = "big"       # 32-bit values: "big" = high word at the lower address, "little" = low word first
    max_registers = 125      # registers per read request (the Modbus limit is 125)
    sample_period_s = 0.001  # controller sample period T_s, s (the info block's period_s overrides it)

    [info]                   # optional ASCII block, read once at open
    address = 0
    length = 256             # registers: 1 byte-count register, then 2 ASCII chars per register, high byte first

    [status]
    address = 256            # 16 bit: bit 0 = running, bit 1 = program ended (every sample is in the trace buffer)

    [counter]
    address = 257            # 32-bit unsigned sample counter of the live registers
    segment = 259            # optional 16-bit program/segment index of the live sample

    [trace]                  # optional: the trace buffer (ring of records)
    head = 260               # address of the 32-bit head: counter of the newest record + 1 (0 = empty)
    capacity = 262           # address of the 16-bit register holding the number of record slots
    base = 1024              # first register of slot 0 (counter c is in slot c mod slots); the ring
                             # fills every register from here up, so no other field may lie there

    [[axis]]
    name = "X"
    commanded = 264          # 32-bit signed position counts
    actual = 266
    scale_mm = 1e-6          # mm (deg for rotary) per count: 1e-6 = nm
    # word_order = "little" # optional per-axis override;  unit = "deg" for rotary axes

A trace record is ``counter`` (32 bit), ``segment`` (16 bit), then for every axis in map
order ``commanded``, ``actual`` (32 bit each, in that axis' word order):
``record_words = 3 + 4 * n_axes`` registers.  A value in mm is
``count / counts_per_unit(scale_mm)`` (:mod:`drivers.scaling`: the exact decimal when
1/scale_mm is an integer).

The info block is ``key=value`` lines (``controller=``, ``axes=X,Y,Z``, ``period_s=``,
``program=<name> <sha256>`` repeated), see :func:`encode_info` / :func:`decode_info`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

from core.errors import MachineError

__all__ = [
    "AxisRegisters",
    "TraceBlock",
    "RegisterMap",
    "load_map",
    "validate_map",
    "default_map",
    "plan_reads",
    "encode_u32",
    "decode_u32",
    "encode_info",
    "decode_info",
    "MAX_READ_REGISTERS",
    "STATUS_RUNNING",
    "STATUS_ENDED",
]

#: Modbus limit of registers per FC 3/4 read request.
MAX_READ_REGISTERS = 125
#: status register bits
STATUS_RUNNING = 0x0001
STATUS_ENDED = 0x0002

_TABLES = ("holding", "input")
_ORDERS = ("big", "little")
_UNITS = ("mm", "deg")


@dataclass(frozen=True)
class AxisRegisters:
    """Where one axis' positions are: 32-bit signed counts, ``scale_mm`` mm (deg) per count."""

    name: str
    commanded: int
    actual: int
    scale_mm: float
    word_order: str = "big"
    unit: str = "mm"


@dataclass(frozen=True)
class TraceBlock:
    """Addresses of the trace buffer: head counter (32 bit), capacity register (16 bit, holding the
    number of slots), ring base (the ring fills every register from there up)."""

    head: int
    capacity: int
    base: int


@dataclass(frozen=True)
class RegisterMap:
    """A validated register map (see the module docstring for the TOML layout)."""

    axes: tuple[AxisRegisters, ...]
    status: int
    counter: int
    segment: int | None = None
    trace: TraceBlock | None = None
    info_address: int | None = None
    info_length: int = 0
    unit: int = 1
    table: str = "holding"
    word_order: str = "big"
    max_registers: int = MAX_READ_REGISTERS
    sample_period_s: float = 0.001
    source: str = field(default="default", compare=False)  # file the map came from, for messages

    @property
    def axis_names(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.axes)

    @property
    def function_code(self) -> int:
        """The read function code of the map's table: 3 (holding) or 4 (input registers)."""
        return 3 if self.table == "holding" else 4

    @property
    def record_words(self) -> int:
        """Registers per trace record: counter (2) + segment (1) + 4 per axis."""
        return 3 + 4 * len(self.axes)

    def record_fields(self) -> list[tuple[str, int, int, str]]:
        """(field, offset in record, words, word order) of a trace record, in order."""
        out = [("counter", 0, 2, self.word_order), ("segment", 2, 1, self.word_order)]
        for i, ax in enumerate(self.axes):
            out.append((f"{ax.name}.commanded", 3 + 4 * i, 2, ax.word_order))
            out.append((f"{ax.name}.actual", 5 + 4 * i, 2, ax.word_order))
        return out

    def live_fields(self) -> list[tuple[str, int, int, str]]:
        """(field, address, words, word order) of the live registers a poll reads."""
        out = [("status", self.status, 1, self.word_order), ("counter", self.counter, 2, self.word_order)]
        if self.segment is not None:
            out.append(("segment", self.segment, 1, self.word_order))
        for ax in self.axes:
            out.append((f"{ax.name}.commanded", ax.commanded, 2, ax.word_order))
            out.append((f"{ax.name}.actual", ax.actual, 2, ax.word_order))
        return out

    def to_toml(self) -> str:
        """The map as a TOML document that :func:`load_map` reads back to an equal map."""
        lines = [
            "# rapid-ident Modbus register map (format: docs/modbus.md)",
            "[device]",
            f"unit = {self.unit}",
            f'table = "{self.table}"',
            f'word_order = "{self.word_order}"',
            f"max_registers = {self.max_registers}",
            f"sample_period_s = {self.sample_period_s!r}",
            "",
        ]
        if self.info_address is not None:
            lines += ["[info]", f"address = {self.info_address}", f"length = {self.info_length}", ""]
        lines += ["[status]", f"address = {self.status}", "", "[counter]", f"address = {self.counter}"]
        if self.segment is not None:
            lines.append(f"segment = {self.segment}")
        lines.append("")
        if self.trace is not None:
            lines += ["[trace]", f"head = {self.trace.head}", f"capacity = {self.trace.capacity}",
                      f"base = {self.trace.base}", ""]
        for ax in self.axes:
            lines += ["[[axis]]", f'name = "{ax.name}"', f"commanded = {ax.commanded}", f"actual = {ax.actual}",
                      f"scale_mm = {ax.scale_mm!r}"]
            if ax.word_order != self.word_order:
                lines.append(f'word_order = "{ax.word_order}"')
            if ax.unit != "mm":
                lines.append(f'unit = "{ax.unit}"')
            lines.append("")
        return "\n".join(lines)


# -- building and validating ----------------------------------------------------------------

def default_map(axes: Sequence[str], scale_mm: float = 1e-6, sample_period_s: float = 0.001,
                word_order: str = "big", units: Sequence[str] | None = None) -> RegisterMap:
    """The default layout (module docstring) for the given axis names.

    Parameters
    ----------
    axes : axis names in order (at most 30, so a live poll fits one 125-register read).
    scale_mm : mm (deg) per count of every axis; 1e-6 mm = 1 nm gives +-2147 mm of travel.
    sample_period_s : controller sample period T_s, s.
    word_order : "big" or "little" for every 32-bit value.
    units : per axis "mm" or "deg" (default all mm).
    """
    units = list(units) if units else ["mm"] * len(axes)
    regs = []
    for i, (name, unit) in enumerate(zip(axes, units)):
        regs.append(AxisRegisters(name, 264 + 4 * i, 266 + 4 * i, scale_mm, word_order, unit))
    rmap = RegisterMap(axes=tuple(regs), status=256, counter=257, segment=259,
                       trace=TraceBlock(head=260, capacity=262, base=1024), info_address=0, info_length=256,
                       unit=1, table="holding", word_order=word_order, sample_period_s=sample_period_s,
                       source="default")
    validate_map(rmap)
    return rmap


def _err(src: str, msg: str) -> MachineError:
    return MachineError(f"register map {src}: {msg}")


def validate_map(rmap: RegisterMap) -> None:
    """Check a map for consistency; raises a one-line MachineError naming the field."""
    src = rmap.source
    if not rmap.axes:
        raise _err(src, "no [[axis]] given")
    if rmap.table not in _TABLES:
        raise _err(src, f"device.table = {rmap.table!r}; use one of {', '.join(_TABLES)}")
    if rmap.word_order not in _ORDERS:
        raise _err(src, f"device.word_order = {rmap.word_order!r}; use big or little")
    if not 0 <= rmap.unit <= 247:
        raise _err(src, f"device.unit = {rmap.unit}; a Modbus unit id is 0..247")
    if not 1 <= rmap.max_registers <= MAX_READ_REGISTERS:
        raise _err(src, f"device.max_registers = {rmap.max_registers}; must be 1..{MAX_READ_REGISTERS}")
    if not (math.isfinite(rmap.sample_period_s) and rmap.sample_period_s > 0):
        raise _err(src, f"device.sample_period_s = {rmap.sample_period_s}; must be > 0 s")
    names = [a.name for a in rmap.axes]
    for a in rmap.axes:
        if not a.name or not a.name.isidentifier():
            raise _err(src, f"axis name {a.name!r} is not a plain name like X or C1")
        if names.count(a.name) > 1:
            raise _err(src, f"axis {a.name!r} given twice")
        if not (math.isfinite(a.scale_mm) and a.scale_mm > 0):
            raise _err(src, f"axis {a.name}: scale_mm = {a.scale_mm}; must be > 0 mm per count")
        if a.word_order not in _ORDERS:
            raise _err(src, f"axis {a.name}: word_order = {a.word_order!r}; use big or little")
        if a.unit not in _UNITS:
            raise _err(src, f"axis {a.name}: unit = {a.unit!r}; use mm or deg")
    # Registers occupied by every scalar field: overlaps are almost always a typo.
    fields: list[tuple[str, int, int]] = [("status.address", rmap.status, 1), ("counter.address", rmap.counter, 2)]
    if rmap.segment is not None:
        fields.append(("counter.segment", rmap.segment, 1))
    if rmap.trace is not None:
        fields += [("trace.head", rmap.trace.head, 2), ("trace.capacity", rmap.trace.capacity, 1)]
    for a in rmap.axes:
        fields += [(f"axis {a.name} commanded", a.commanded, 2), (f"axis {a.name} actual", a.actual, 2)]
    if rmap.info_address is not None:
        if rmap.info_length < 2:
            raise _err(src, f"info.length = {rmap.info_length}; needs >= 2 registers")
        fields.append(("info block", rmap.info_address, rmap.info_length))
    for name, addr, words in fields:
        if not (0 <= addr and addr + words <= 65536):
            raise _err(src, f"{name} = {addr} is outside the register space 0..65535")
    ordered = sorted(fields, key=lambda f: f[1])
    for (n1, a1, w1), (n2, a2, _) in zip(ordered, ordered[1:]):
        if a2 < a1 + w1:
            raise _err(src, f"{n2} (register {a2}) overlaps {n1} (registers {a1}..{a1 + w1 - 1})")
    if rmap.trace is not None:
        base = rmap.trace.base
        if not 0 <= base <= 65535 - rmap.record_words:
            raise _err(src, f"trace.base = {base} leaves no room for one {rmap.record_words}-register record")
        for name, addr, words in fields:
            if addr + words > base:
                raise _err(src, f"{name} (register {addr}) lies inside the trace ring starting at trace.base = {base}")
        if rmap.record_words > rmap.max_registers:
            raise _err(src, f"a trace record of {len(rmap.axes)} axes needs {rmap.record_words} registers, "
                            f"more than device.max_registers = {rmap.max_registers}")


_SECTIONS = {
    "device": {"unit", "table", "word_order", "max_registers", "sample_period_s"},
    "info": {"address", "length"},
    "status": {"address"},
    "counter": {"address", "segment"},
    "trace": {"head", "capacity", "base"},
    "axis": {"name", "commanded", "actual", "scale_mm", "word_order", "unit"},
}


def _get(src: str, table: dict, section: str, key: str, kind: type, default=None, required: bool = True):
    if key not in table:
        if required and default is None:
            raise _err(src, f"[{section}] has no {key}")
        return default
    value = table[key]
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if not isinstance(value, kind) or isinstance(value, bool):
        what = {int: "an integer", float: "a number", str: "a string"}[kind]
        raise _err(src, f"{section}.{key} = {value!r} is not {what}")
    return value


def load_map(path: str | Path) -> RegisterMap:
    """Read and validate a register map TOML file; any problem is a one-line MachineError."""
    path = Path(path)
    src = str(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise MachineError(f"register map {src}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MachineError(f"register map {src}: cannot read ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise MachineError(f"register map {src}: not valid TOML ({exc})") from None
    for section, body in data.items():
        if section not in _SECTIONS:
            raise _err(src, f"unknown section [{section}] (known: {', '.join(_SECTIONS)})")
        bodies = body if isinstance(body, list) else [body]
        for b in bodies:
            if not isinstance(b, dict):
                raise _err(src, f"{section} must be a table")
            unknown = sorted(set(b) - _SECTIONS[section])
            if unknown:
                raise _err(src, f"unknown key {section}.{unknown[0]} (known: {', '.join(sorted(_SECTIONS[section]))})")
    dev = data.get("device", {})
    word_order = _get(src, dev, "device", "word_order", str, "big")
    for needed in ("status", "counter"):
        if needed not in data:
            raise _err(src, f"missing section [{needed}]")
    axes_raw = data.get("axis", [])
    if not isinstance(axes_raw, list):
        raise _err(src, "axes are given as [[axis]] tables")
    axes = []
    for a in axes_raw:
        name = _get(src, a, "axis", "name", str)
        axes.append(AxisRegisters(
            name=name,
            commanded=_get(src, a, f"axis {name}", "commanded", int),
            actual=_get(src, a, f"axis {name}", "actual", int),
            scale_mm=_get(src, a, f"axis {name}", "scale_mm", float),
            word_order=_get(src, a, f"axis {name}", "word_order", str, word_order),
            unit=_get(src, a, f"axis {name}", "unit", str, "mm"),
        ))
    trace = None
    if "trace" in data:
        t = data["trace"]
        trace = TraceBlock(_get(src, t, "trace", "head", int), _get(src, t, "trace", "capacity", int),
                           _get(src, t, "trace", "base", int))
    info = data.get("info")
    cnt = data["counter"]
    rmap = RegisterMap(
        axes=tuple(axes),
        status=_get(src, data["status"], "status", "address", int),
        counter=_get(src, cnt, "counter", "address", int),
        segment=_get(src, cnt, "counter", "segment", int, required=False),
        trace=trace,
        info_address=_get(src, info, "info", "address", int) if info is not None else None,
        info_length=_get(src, info, "info", "length", int) if info is not None else 0,
        unit=_get(src, dev, "device", "unit", int, 1),
        table=_get(src, dev, "device", "table", str, "holding"),
        word_order=word_order,
        max_registers=_get(src, dev, "device", "max_registers", int, MAX_READ_REGISTERS),
        sample_period_s=_get(src, dev, "device", "sample_period_s", float, 0.001),
        source=src,
    )
    validate_map(rmap)
    return rmap


# -- reading plans and value codecs ---------------------------------------------------------

def plan_reads(fields: Iterable[tuple[int, int]], max_registers: int = MAX_READ_REGISTERS,
               max_gap: int = 16) -> list[tuple[int, int]]:
    """Group (address, words) fields into as few (start, count) read requests as possible.

    Fields closer than ``max_gap`` unused registers share a request; no request is longer
    than ``max_registers`` (the Modbus limit 125).
    """
    pieces = []
    for addr, words in fields:  # a field longer than one request (the info block) is split
        for a in range(addr, addr + words, max_registers):
            pieces.append((a, min(max_registers, addr + words - a)))
    spans: list[list[int]] = []
    for addr, words in sorted(pieces):
        end = addr + words
        if spans and addr - spans[-1][1] <= max_gap and max(end, spans[-1][1]) - spans[-1][0] <= max_registers:
            spans[-1][1] = max(end, spans[-1][1])
        else:
            spans.append([addr, end])
    return [(s, e - s) for s, e in spans]


def encode_u32(values: np.ndarray, word_order: str) -> np.ndarray:
    """32-bit integers (signed or unsigned, any shape) -> uint16 words, last axis (..., 2) in wire order."""
    u = np.asarray(values).astype(np.int64) & 0xFFFFFFFF
    hi = (u >> 16).astype(np.uint16)
    lo = (u & 0xFFFF).astype(np.uint16)
    return np.stack([hi, lo] if word_order == "big" else [lo, hi], axis=-1)


def decode_u32(first: np.ndarray, second: np.ndarray, word_order: str, signed: bool) -> np.ndarray:
    """Two uint16 word arrays (in address order) -> 32-bit values as int64 (signed if asked)."""
    first = np.asarray(first, dtype=np.int64)
    second = np.asarray(second, dtype=np.int64)
    u = (first << 16) | second if word_order == "big" else (second << 16) | first
    if signed:
        u = np.where(u >= 1 << 31, u - (1 << 32), u)
    return u


def encode_info(info: dict[str, str | list[str]], length: int) -> list[int]:
    """The info block registers: byte count, then ASCII ``key=value`` lines, 2 chars per register.

    List values repeat the key (``program=...`` once per program).  Lines that do not fit
    in ``length - 1`` registers are left out (a ``truncated=1`` line says so).
    """
    lines = []
    for key, value in info.items():
        for v in (value if isinstance(value, list) else [value]):
            lines.append(f"{key}={v}")
    room = 2 * (length - 1)
    text = ""
    for line in lines:
        candidate = text + line + "\n"
        if len(candidate.encode("ascii", "replace")) > room - len("truncated=1\n"):
            text += "truncated=1\n"
            break
        text = candidate
    raw = text.encode("ascii", "replace")
    if len(raw) % 2:
        raw += b"\0"
    words = [len(text)] + [(raw[i] << 8) | raw[i + 1] for i in range(0, len(raw), 2)]
    return words + [0] * (length - len(words))


def decode_info(registers: Sequence[int]) -> dict[str, str | list[str]]:
    """Inverse of :func:`encode_info`; ``program`` is always a list."""
    if len(registers) == 0:
        return {}
    nbytes = int(registers[0])
    raw = b"".join(int(r).to_bytes(2, "big") for r in registers[1:])[:nbytes]
    out: dict[str, str | list[str]] = {"program": []}
    for line in raw.decode("ascii", "replace").splitlines():
        if "=" not in line:
            continue
        key, value = line.split("=", 1)
        if key == "program":
            out["program"].append(value)  # type: ignore[union-attr]
        else:
            out[key] = value
    return out

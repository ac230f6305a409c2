"""CANopen object dictionaries and PDO layouts for the CAN driver (CiA 301 / CiA 402).

The ``canopen`` package parses the EDS and reads the TPDO mapping, either from the EDS
defaults (``sdo=0``) or from the drive by SDO upload (``sdo=1``, a read: see
docs/can.md for the exact objects).  This module turns a mapping into a compiled
:class:`PdoLayout` (COB-ID, expected length, a ``struct`` format) so that decoding a
frame at 1 kHz x n axes is one ``struct.unpack``.

Objects used:

* 0x6062:00 position demand value, 0x6064:00 position actual value (INTEGER32, in the
  drive's position units: CiA 402 user-defined units, set by its factor group; the
  increment values are 0x60FC and 0x6063, not read) - both in one synchronous TPDO per
  axis node; mm = value / scale, scale in position units per mm;
* 0x1005 COB-ID SYNC, 0x1006 communication cycle period (us) = the sample period,
  0x1019 synchronous counter overflow value (the SYNC counter runs 1..overflow; optional:
  without it, or 0/1, the SYNC carries no counter);
* 0x2100:01 segment, 0x2100:02 program state (0 idle, 1 running, 2 ended) of the
  controller's program-status node (fixtures/can/cnc_status.eds), event-driven TPDO.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import canopen
from canopen.objectdictionary import datatypes as dt

from core.errors import InputError, TransportError

__all__ = [
    "POSITION_DEMAND", "POSITION_ACTUAL", "PROGRAM_STATUS", "STATE_ENDED", "FIXTURES",
    "DEFAULT_AXIS_EDS", "DEFAULT_STATUS_EDS", "PdoLayout", "SyncParams", "load_od",
    "axis_pdo", "status_pdo", "sync_params",
]

POSITION_DEMAND = 0x6062
POSITION_ACTUAL = 0x6064
PROGRAM_STATUS = 0x2100
STATE_IDLE, STATE_RUNNING, STATE_ENDED = 0, 1, 2

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures" / "can"
DEFAULT_AXIS_EDS = FIXTURES / "cia402_axis.eds"
DEFAULT_STATUS_EDS = FIXTURES / "cnc_status.eds"

_STRUCT = {
    dt.BOOLEAN: "?", dt.INTEGER8: "b", dt.UNSIGNED8: "B", dt.INTEGER16: "h", dt.UNSIGNED16: "H",
    dt.INTEGER32: "i", dt.UNSIGNED32: "I", dt.INTEGER64: "q", dt.UNSIGNED64: "Q",
    dt.REAL32: "f", dt.REAL64: "d",
}


@dataclass(frozen=True)
class PdoLayout:
    """A compiled TPDO: which COB-ID, how many bytes, how to unpack, where each object sits.

    ``fields[i]`` = (index, subindex) of the i-th value of ``struct.unpack``.
    """

    node_id: int
    cob_id: int
    length: int  # bytes; a frame of another length is malformed
    fmt: str  # little-endian struct format, padding bytes as 'x'
    fields: tuple[tuple[int, int], ...]
    trans_type: int

    def position(self, index: int, subindex: int = 0) -> int:
        """Position of object (index, subindex) among the unpacked values."""
        try:
            return self.fields.index((index, subindex))
        except ValueError:
            raise InputError(f"node {self.node_id}: TPDO 0x{self.cob_id:X} does not map 0x{index:04X}:{subindex:02X}") from None

    def compiled(self) -> struct.Struct:
        return struct.Struct(self.fmt)


@dataclass(frozen=True)
class SyncParams:
    cob_id: int  # COB-ID of SYNC (0x80)
    overflow: int  # SYNC counter runs 1..overflow; 0 = SYNC carries no counter
    period_s: float  # communication cycle period, s (0 if unknown)


def load_od(path: str | Path, node_id: int) -> canopen.ObjectDictionary:
    """Parse an EDS/DCF for ``node_id`` (``$NODEID`` expanded); a bad file is a one-line InputError."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"EDS file {p} not found")
    try:
        return canopen.import_od(str(p), node_id)
    except Exception as exc:  # canopen raises several kinds for a malformed file
        raise InputError(f"EDS file {p} cannot be read: {exc}") from exc


def _compile(node_id: int, pdo_map) -> PdoLayout:
    fmt, fields = "<", []
    for var in pdo_map.map:
        nbytes = var.length // 8
        code = _STRUCT.get(var.od.data_type)
        if var.length % 8:
            raise InputError(f"node {node_id}: TPDO 0x{pdo_map.cob_id:X} maps a {var.length}-bit object; only whole bytes are supported")
        if code is not None and struct.calcsize("<" + code) == nbytes:
            fmt += code
            fields.append((var.od.index, var.od.subindex))
        else:
            fmt += "x" * nbytes  # mapped but not needed (or dummy): skip its bytes
    return PdoLayout(node_id, pdo_map.cob_id, struct.calcsize(fmt), fmt, tuple(fields), int(pdo_map.trans_type or 0))


def _read_maps(node, from_od: bool) -> list:
    maps = []
    for pdo_map in node.tpdo.map.values():
        try:
            pdo_map.read(from_od=from_od)
        except canopen.SdoAbortedError as exc:
            raise TransportError(f"node {node.id}: SDO upload of the TPDO mapping aborted: {exc}") from exc
        except canopen.SdoCommunicationError as exc:
            raise TransportError(
                f"node {node.id} did not answer the SDO upload of its TPDO mapping ({exc}); "
                "is it on the bus? (sdo=0 takes the mapping from the EDS instead)") from exc
        if pdo_map.enabled and pdo_map.cob_id:
            maps.append(pdo_map)
    return maps


def axis_pdo(node, from_od: bool) -> PdoLayout:
    """The synchronous TPDO of an axis node that carries both 0x6062 and 0x6064."""
    found = []
    for pdo_map in _read_maps(node, from_od):
        objs = {(v.od.index, v.od.subindex) for v in pdo_map.map}
        found.append(f"0x{pdo_map.cob_id:X}: " + ",".join(f"{i:04X}" for i, _ in sorted(objs)))
        if (POSITION_DEMAND, 0) in objs and (POSITION_ACTUAL, 0) in objs:
            if not 1 <= (pdo_map.trans_type or 0) <= 240:
                raise InputError(f"node {node.id}: TPDO 0x{pdo_map.cob_id:X} with 0x6062/0x6064 has transmission "
                                 f"type {pdo_map.trans_type}; the driver needs a SYNC-triggered TPDO (1..240)")
            layout = _compile(node.id, pdo_map)
            for obj in (POSITION_DEMAND, POSITION_ACTUAL):
                layout.position(obj)  # must have decoded as an integer
            return layout
    raise InputError(f"node {node.id}: no enabled TPDO maps both 0x6062 (position demand) and 0x6064 "
                     f"(position actual) ({'; '.join(found) or 'no TPDO'})")


def status_pdo(node, from_od: bool) -> PdoLayout:
    """The TPDO of the program-status node that carries 0x2100:01 (segment) and 0x2100:02 (state)."""
    for pdo_map in _read_maps(node, from_od):
        objs = {(v.od.index, v.od.subindex) for v in pdo_map.map}
        if (PROGRAM_STATUS, 1) in objs and (PROGRAM_STATUS, 2) in objs:
            return _compile(node.id, pdo_map)
    raise InputError(f"status node {node.id}: no TPDO maps 0x2100:01 and 0x2100:02 (program status)")


def _value(node, index: int, from_od: bool):
    obj = node.object_dictionary.get(index)
    if obj is None:
        return None
    if from_od:
        return obj.value if obj.value is not None else obj.default
    try:
        return node.sdo[index].raw
    except canopen.SdoAbortedError:
        return None
    except canopen.SdoCommunicationError as exc:
        raise TransportError(f"node {node.id} did not answer the SDO upload of 0x{index:04X} ({exc})") from exc


def sync_params(node, from_od: bool) -> SyncParams:
    """SYNC COB-ID (0x1005), counter overflow (0x1019) and cycle period (0x1006, us -> s) of a node.

    0x1006 is read last: the simulated controller takes that read as "a capture is listening".
    """
    cob = _value(node, 0x1005, from_od)
    overflow = _value(node, 0x1019, from_od)
    period_us = _value(node, 0x1006, from_od)
    return SyncParams(int(cob or 0x80) & 0x7FF, int(overflow or 0), float(period_us or 0) * 1e-6)

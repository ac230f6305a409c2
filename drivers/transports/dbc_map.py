"""Raw CAN frames described by a DBC file (``cantools``): which frame opens a tick, which carry which axis.

Signal naming convention (fixtures/can/positions.dbc is an example):

* ``counter`` - the controller's sample counter (unsigned, any bit length; it wraps at
  2**bits).  The frame holding it opens a tick and is sent first in every tick.
  Optional in the same frame: ``segment`` (program index) and ``state`` (0 idle,
  1 running, 2 program ended).
* ``<AXIS>_commanded`` and ``<AXIS>_actual`` - positions in mm (deg for rotary axes)
  after the DBC's factor/offset, e.g. ``X_commanded``.  Both signals of an axis must sit
  in the same frame; a frame may carry several axes.

A frame whose length differs from its DBC length is malformed (counted corrupt, never
decoded).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import cantools

from core.errors import InputError
from drivers.scaling import counts_per_unit

__all__ = ["DbcPart", "DbcLayout", "load_dbc", "per_mm", "DEFAULT_DBC"]

DEFAULT_DBC = Path(__file__).resolve().parents[2] / "fixtures" / "can" / "positions.dbc"
_AXIS_SIGNAL = re.compile(r"^(?P<axis>[A-Za-z][A-Za-z0-9]*)_(?P<kind>commanded|actual)$")


def per_mm(factor: float) -> float:
    """Increments per mm of a DBC factor (mm per bit): positions are raw / per_mm (drivers.scaling)."""
    return counts_per_unit(factor)


@dataclass(frozen=True)
class DbcPart:
    """One position frame: its id, its length in bytes and the axes it carries as (axis index, signals)."""

    frame_id: int
    length: int
    message: object  # cantools Message
    axes: tuple[tuple[int, str, str], ...]  # (index in the wanted axes, commanded signal, actual signal)
    per_mm: tuple[float, ...]  # increments per mm of each entry of ``axes``


@dataclass(frozen=True)
class DbcLayout:
    tick_id: int
    tick_length: int
    tick_message: object
    modulus: int  # counter values before it wraps
    axes: tuple[str, ...]
    parts: tuple[DbcPart, ...]
    has_segment: bool
    has_state: bool


def load_dbc(path: str | Path, axes: list[str] | None = None) -> DbcLayout:
    """Read a DBC and find the tick frame and the frames carrying ``axes`` (all axes found when None)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"DBC file {p} not found")
    try:
        db = cantools.database.load_file(str(p))
    except Exception as exc:  # cantools raises parser-specific errors
        raise InputError(f"DBC file {p} cannot be read: {exc}") from exc
    tick = None
    found: dict[str, dict[str, tuple[object, str]]] = {}
    for msg in db.messages:
        names = {s.name for s in msg.signals}
        if "counter" in names:
            if tick is not None:
                raise InputError(f"DBC file {p}: two frames carry a 'counter' signal ({tick.name}, {msg.name})")
            tick = msg
        for sig in msg.signals:
            m = _AXIS_SIGNAL.match(sig.name)
            if m:
                found.setdefault(m["axis"], {})[m["kind"]] = (msg, sig.name)
    if tick is None:
        raise InputError(f"DBC file {p}: no frame carries a 'counter' signal (the sample counter)")
    wanted = list(axes) if axes else [a for a in found if len(found[a]) == 2]
    if not wanted:
        raise InputError(f"DBC file {p}: no <AXIS>_commanded / <AXIS>_actual signal pairs")
    by_frame: dict[int, list[tuple[int, str, str]]] = {}
    messages = {}
    for i, axis in enumerate(wanted):
        sigs = found.get(axis, {})
        if len(sigs) != 2:
            known = ", ".join(sorted(found)) or "none"
            raise InputError(f"DBC file {p}: axis {axis!r} needs signals {axis}_commanded and {axis}_actual (axes found: {known})")
        (m_cmd, s_cmd), (m_act, s_act) = sigs["commanded"], sigs["actual"]
        if m_cmd is not m_act:
            raise InputError(f"DBC file {p}: {s_cmd} and {s_act} must be in the same frame")
        sc, sa = m_cmd.get_signal_by_name(s_cmd), m_cmd.get_signal_by_name(s_act)
        if sc.scale != sa.scale or sc.offset or sa.offset or not sc.scale > 0:
            raise InputError(f"DBC file {p}: {s_cmd} and {s_act} need the same positive factor and no offset")
        by_frame.setdefault(m_cmd.frame_id, []).append((i, s_cmd, s_act))
        messages[m_cmd.frame_id] = m_cmd
    parts = tuple(
        DbcPart(fid, messages[fid].length, messages[fid], tuple(v),
                tuple(per_mm(messages[fid].get_signal_by_name(c).scale) for _i, c, _a in v))
        for fid, v in by_frame.items())
    counter = tick.get_signal_by_name("counter")
    names = {s.name for s in tick.signals}
    return DbcLayout(tick.frame_id, tick.length, tick, 1 << counter.length, tuple(wanted), parts,
                     "segment" in names, "state" in names)

"""``agent tune`` as a workflow of files: result JSON + INI or gains → proposal, INI diff, JSON.

Never writes to a controller: the INI is read, and the lines to change are printed as a
unified diff the user applies.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Sequence

from agent.outputs import write_json
from core.errors import InputError
from core.reader import load_recording
from gcode_gen.commands import ProgramLike
from ident.tuning import Gains, Criterion, Tuning, tune
from ident.tuning.controllers import GAIN_NAMES
from ident.virtual_machine import load_virtual_machine

__all__ = ["tune_files", "parse_gains"]


def parse_gains(form: str, axes: Sequence[str], assignments: Sequence[str], flag: str) -> dict[str, dict[str, float]]:
    """``[AXIS.]NAME=VALUE`` assignments → {axis: {name: value}} (no axis: every axis)."""
    out: dict[str, dict[str, float]] = {a: {} for a in axes}
    for text in assignments:
        lhs, eq, rhs = text.partition("=")
        if not eq:
            raise InputError(f"{flag} {text!r}: expected [AXIS.]NAME=VALUE, e.g. X.Kp=30")
        axis, dot, name = lhs.strip().rpartition(".")
        targets = [axis] if dot else list(axes)
        if dot and axis not in out:
            raise InputError(f"{flag} {text!r}: no axis {axis} (axes: {', '.join(axes)})")
        if name not in GAIN_NAMES[form]:
            raise InputError(f"{flag} {text!r}: {form} has no gain {name!r} ({', '.join(GAIN_NAMES[form])})")
        try:
            value = float(rhs)
        except ValueError:
            raise InputError(f"{flag} {text!r}: {rhs.strip()!r} is not a number") from None
        for a in targets:
            out[a][name] = value
    return out


def tune_files(machine: Path, *, controller: str, ini: Path | None, gains: Sequence[str], propose: Sequence[str],
               programs: Sequence[ProgramLike], ballbar: bool, radius: float, feed: float, axes: Sequence[str] | None,
               u_max: float, json_out: Path | None,
               integration: str = "continuous", lead_deg: float | None = None,
               recording: Path | None = None) -> tuple[Tuning, list[str]]:
    """Run the tuning; returns it and the INI diff lines (empty without an INI).

    ``recording``: the capture ``machine`` was identified from; the plants are fitted to it.
    Without it the plants come from the identified models, and a note names the recording
    the result was identified from when that file is there to be given.
    With an INI the test is planned with its per-axis limits, as LinuxCNC plans it (and as
    ``agent predict --ini`` does); ``lead_deg``: the ballbar as one program with feed-in/out arcs."""
    vm = load_virtual_machine(machine)
    if ini is not None:
        from gcode_gen.planner_limits import read_linuxcnc_ini

        vm = vm.with_planner_limits(read_linuxcnc_ini(ini))
    if bool(programs) == bool(ballbar):
        raise InputError("give --program FILE or --ballbar (one of the two): what the tuning is judged on")
    if ballbar:
        plane = tuple(axes) if axes else tuple(a for a in ("X", "Y") if a in vm.axes)
        if len(plane) != 2:
            raise InputError.about("axes", f"the ballbar needs two axes; {vm.name} has {', '.join(vm.axes)}")
        test = Criterion.ballbar(vm, plane, radius, feed, lead_deg=lead_deg)
    else:
        test = Criterion.program(vm, programs)
    joints: dict[str, int] = {}
    units: dict[str, float] = {}  # mm per machine unit of each axis's gains (LinuxCNC INI)
    if controller == "linuxcnc-pid":
        if ini is None:
            raise InputError.about("ini", "--controller linuxcnc-pid reads the gains from the machine's INI: give --ini")
        from ident.tuning.ini import in_mm, read_joint_gains

        read = read_joint_gains(ini, list(test.axes))
        joints = {a: j for a, (j, _, _) in read.items()}
        # The INI's gains, and those given with --gain and --propose, are per machine unit (per
        # inch on an inch machine); the tuning works per mm, as the identified drives do.
        units = {a: mm for a, (_, _, mm) in read.items()}
        extra = parse_gains(controller, test.axes, gains, "--gain")
        current = {a: in_mm(Gains(controller, {**g.values, **extra[a]}, g.u_max), units[a])
                   for a, (_, g, _) in read.items()}
    else:
        if ini is not None:
            raise InputError.about("ini", f"--ini holds LinuxCNC pid gains; --controller {controller} takes --gain")
        given = parse_gains(controller, test.axes, gains, "--gain")
        for a, v in given.items():
            need = [k for k in GAIN_NAMES[controller][:3] if k not in v]
            if need:
                raise InputError.about("gain", f"axis {a}: no {need[0]} (give --gain {a}.{need[0]}=… or "
                                               f"--gain {need[0]}=… for every axis)")
        current = {a: Gains(controller, v, u_max) for a, v in given.items()}
    proposed = None
    if propose:
        changes = parse_gains(controller, test.axes, propose, "--propose")
        proposed = {a: _with(current[a], changes[a], units.get(a, 1.0)) for a in test.axes}
    rec = load_recording(recording) if recording is not None else None
    result = tune(vm, current, test, proposed, integration, rec)
    if any(mm != 1.0 for mm in units.values()):
        from ident.tuning.ini import in_machine_units

        result = replace(result, before={a: in_machine_units(g, units[a]) for a, g in result.before.items()},
                         after={a: in_machine_units(g, units[a]) for a, g in result.after.items()},
                         notes=result.notes + ("gains in the INI's units (per inch on a linear joint); the tuning "
                                               "converts them to mm, as the identified drives are",))
    if rec is None:
        source = _named_recording(machine)
        if source is not None:
            result = replace(result, notes=result.notes + (
                f"the plants come from the identified models; --recording {source} fits them to the recording "
                f"instead (docs/tuning.md)",))
    diff: list[str] = []
    if ini is not None:
        from ident.tuning.ini import ini_diff

        changes = {}
        for a, j in joints.items():
            b, n = result.before[a].values, result.after[a].values
            ch = {k: n[k] for k in GAIN_NAMES[controller] if abs(n[k] - b[k]) > 1e-12 * max(1.0, abs(b[k]))}
            if ch:
                changes[j] = ch
        diff = ini_diff(ini, changes)
    if json_out is not None:
        doc = result.to_dict()
        doc["machine"] = vm.name
        doc["controller"] = controller
        doc["ini_diff"] = diff
        write_json(json.dumps(doc, indent=2, allow_nan=False), json_out)
    return result, diff


def _with(g: Gains, changes: dict[str, float], mm: float) -> Gains:
    """``g`` (per mm) with ``changes`` given per machine unit of ``mm`` mm applied."""
    if mm == 1.0:
        return Gains(g.form, {**g.values, **changes}, g.u_max)
    from ident.tuning.ini import in_machine_units, in_mm

    return in_mm(Gains(g.form, {**in_machine_units(g, mm).values, **changes}, g.u_max), mm)


def _named_recording(machine: Path) -> str | None:
    """The recording the result JSON names as its source, when that file exists (as given, or
    beside the result), else None."""
    try:
        source = json.loads(Path(machine).read_text()).get("source")
    except (OSError, ValueError, AttributeError):
        return None
    if not isinstance(source, str) or not source or source.startswith("<"):
        return None
    for path in (Path(source), Path(machine).parent / source):
        if path.is_file():
            return str(path)
    return None

"""Agreement of our G-code interpreter with LinuxCNC's ``rs274`` on LinuxCNC's sample programs.

Usage::

    PYTHONPATH=. python scripts/compare_rs274.py [ncfiles folder] [--tool-table T.tbl]

For every ``*.ngc`` in the folder (default /usr/share/linuxcnc/ncfiles): skip lathe, plasma,
probing, remap and user-M-code programs (named with the reason), run ``rs274 -g`` with the
tool table (fixtures/rs274/tools.tbl, inches, as rs274 reads tables without an INI), skip
the programs rs274 itself refuses, run our interpreter with the same table, and compare the
moves (gcode_gen.ngc.rs274_canon.compare: end points within 5 µm, same arcs, dwells, feeds).
Prints one row per program and the totals; exit code 1 when any program disagrees.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from core.errors import ProgramError
from gcode_gen.ngc import interpret, read_tool_table
from gcode_gen.ngc.rs274_canon import RS274, compare, run_rs274

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_TABLE = ROOT / "fixtures" / "rs274" / "tools.tbl"
_USER_M = re.compile(r"(?<![a-z0-9#<_])m1\d\d(?!\d)", re.I)


def skip_reason(path: Path, text: str) -> str | None:
    """Why a sample is not a milling program we compare (None: compare it)."""
    name = path.name.lower()
    low = re.sub(r"\(.*?\)|;.*", "", text.lower())
    if "lathe" in name or name in ("g76.ngc", "threading.ngc") or re.search(r"\bg7\b|g8\s|\bg7[0-2]\b|\bg76\b", low):
        return "lathe program (diameter mode, lathe cycles G7x, threading)"
    if "plasma" in name:
        return "plasma program (torch height control M-codes, remapped)"
    if re.search(r"g38\.[2-5]", low) or "probe" in name:
        return "probing (G38.x needs a probe input)"
    if "remap" in name or name in ("m250.ngc", "m61demo.ngc", "m6demo.ngc", "testm6fail.ngc"):
        return "remap demo (needs a remap configuration)"
    if _USER_M.search(low):
        return "user M-code M1xx (runs an external program)"
    return None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", nargs="?", default="/usr/share/linuxcnc/ncfiles")
    ap.add_argument("--tool-table", default=str(DEFAULT_TABLE), help="LinuxCNC tool table in inches")
    args = ap.parse_args(argv)
    if RS274 is None:
        print("error: rs274 (LinuxCNC's interpreter, package linuxcnc-uspace) is not installed", file=sys.stderr)
        return 2
    tools = read_tool_table(args.tool_table, unit_mm=25.4)
    rows, counts = [], {"supported": 0, "refused": 0, "disagree": 0}
    with_feed = {"supported": 0, "refused": 0, "disagree": 0}
    for path in sorted(Path(args.folder).glob("*.ngc")):
        text = path.read_text(errors="replace")
        reason = skip_reason(path, text)
        if reason:
            rows.append((path.name, "skipped", "", reason))
            continue
        ref = run_rs274(path, tool_table=args.tool_table)
        if ref.returncode != 0:
            rows.append((path.name, "skipped", "", f"rs274 refuses it: {ref.message[:90]}"))
            continue
        feeds = sum(m.kind in ("G1", "G2", "G3") for m in ref.moves)
        try:
            blocks, _ = interpret(text, name=path.name, dialect="linuxcnc", tools=tools)
        except ProgramError as exc:
            status, detail = "refused", str(exc)
        else:
            if ref.unsupported:
                status, detail = "disagree", f"ours ran it, rs274 used {ref.unsupported}"
            else:
                agr = compare(blocks, ref.moves)
                if agr.problem is None:
                    status = "supported"
                    detail = f"{agr.n_moves} moves, max end error {agr.max_end_error_mm * 1000:.2f} µm"
                else:
                    status, detail = "disagree", agr.problem
        counts[status] += 1
        if feeds:
            with_feed[status] += 1
        rows.append((path.name, status, str(feeds), detail))
    width = max(len(r[0]) for r in rows)
    print(f"{'program':<{width}}  {'result':<9}  {'feeds':>5}  detail")
    for name, status, feeds, detail in rows:
        print(f"{name:<{width}}  {status:<9}  {feeds:>5}  {detail}")
    for title, c in (("all compared programs", counts), ("programs with feed moves", with_feed)):
        total = sum(c.values())
        share = 100.0 * c["supported"] / total if total else 0.0
        print(f"{title}: {total}: supported {c['supported']} ({share:.0f} %), refused with a line {c['refused']}, "
              f"disagreeing {c['disagree']}")
    return 1 if counts["disagree"] else 0


if __name__ == "__main__":
    sys.exit(main())

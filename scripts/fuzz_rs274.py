"""Random programs through LinuxCNC's ``rs274`` and our interpreter: do they agree?

Usage::

    PYTHONPATH=. python scripts/fuzz_rs274.py [--seed 1] [--count 200]

Each program mixes what part programs do — rapids and feeds in any axes, arcs in G17/G18/G19
(I/J/K and R, helices, full circles with P turns), G20/G21, G91 moves, work offsets G10 L2 and
G54–G56, G92 family, tool changes and G43/G49, G28, G53, canned cycles G73/G81–G83/G85/G89 with
G98/G99, G91 and L, dwells — and is compared move by move (gcode_gen.ngc.rs274_canon.compare).
With ``--kind comp`` the programs are random contours of lines and arcs under G41/G42 (many
gouge; then both must refuse).  Prints each disagreement and each program only one interpreter refuses, then the totals; exit
code 1 when any program disagrees.  Our deliberate refusal (G20/G21 with a tool length
offset active, which LinuxCNC mishandles) is counted apart.
"""

from __future__ import annotations

import argparse
import math
import random
import sys
import tempfile
from pathlib import Path

from core.errors import ProgramError
from gcode_gen.ngc import interpret, read_tool_table
from gcode_gen.ngc.rs274_canon import RS274, compare, run_rs274

TABLE = Path(__file__).resolve().parents[1] / "fixtures" / "rs274" / "tools.tbl"
_PLANES = {"G17": ("X", "Y", "Z", "I", "J"), "G18": ("Z", "X", "Y", "K", "I"), "G19": ("Y", "Z", "X", "J", "K")}


def _n(rng: random.Random, a: float = -20, b: float = 20) -> str:
    return f"{rng.uniform(a, b):.3f}"


def random_block(rng: random.Random) -> str:
    """One to three lines of a plausible program."""
    k = rng.random()
    plane = rng.choice(list(_PLANES))
    first, second, normal, l1, l2 = _PLANES[plane]
    if k < 0.25:
        axes = rng.sample("XYZ", rng.randint(1, 3))
        feed = f" F{rng.randint(50, 900)}" if rng.random() < 0.3 else ""
        return rng.choice(["G0", "G1"]) + " " + " ".join(f"{a}{_n(rng)}" for a in axes) + feed
    if k < 0.35:  # incremental I/J/K arc: centre at (a, b), end at (2a, 0) relative
        a, b = rng.uniform(-5, 5), rng.uniform(-5, 5)
        return f"{plane} G91 {rng.choice(['G2', 'G3'])} {first}{2 * a:.3f} {l1}{a:.3f} {l2}{b:.3f} {normal}{_n(rng, -2, 2)}\nG90"
    if k < 0.42:
        c = rng.uniform(1, 6)
        return f"{plane} G91 {rng.choice(['G2', 'G3'])} {first}{c:.3f} R{rng.choice([1, -1]) * rng.uniform(c / 2 + 0.1, 8):.3f}\nG90"
    if k < 0.48:
        turns = f" P{rng.randint(1, 3)}" if rng.random() < 0.3 else ""
        return f"G17 {rng.choice(['G2', 'G3'])} I{_n(rng, -4, 4)} J{_n(rng, -4, 4)}{turns}"
    if k < 0.53:
        return f"G10 L2 P{rng.randint(1, 3)} X{_n(rng)} Y{_n(rng)} Z{_n(rng, -5, 5)}"
    if k < 0.58:
        return rng.choice(["G54", "G55", "G56"])
    if k < 0.62:
        return f"G92 X{_n(rng)} Y{_n(rng)}"
    if k < 0.64:
        return rng.choice(["G92.1", "G92.2", "G92.3"])
    if k < 0.68:
        return rng.choice(["G43 H1\nG0 Z30", "G43 H2\nG0 Z30", "G49\nG0 Z30", "T3 M6\nG43\nG0 Z30", "T2 M6"])
    if k < 0.72:
        return rng.choice(["G20", "G21"])
    if k < 0.80:
        cycle = rng.choice(["G81", "G82 P0.1", "G83 Q0.7", "G73 Q0.5", "G85", "G89 P0.2"])
        z = _n(rng, -4, -1) if rng.random() < 0.7 else _n(rng, -1, 0)
        return (f"G17 {rng.choice(['G98', 'G99'])} {rng.choice(['G90', 'G91'])} {cycle} X{_n(rng, -5, 5)} "
                f"Y{_n(rng, -5, 5)} R{_n(rng, 1, 3)} Z{z} L{rng.randint(1, 3)}\nG90 G80")
    if k < 0.84:
        return rng.choice(["G28", "G28 X1", "G28 Z5"])
    if k < 0.87:
        return f"G53 G0 X{_n(rng)} Z{_n(rng, -3, 3)}"
    if k < 0.92:
        return f"G91 G0 X{_n(rng, -3, 3)}\nG90"
    return f"G4 P{rng.uniform(0, 0.5):.2f}"


def random_program(rng: random.Random) -> str:
    return "G21 G17 G90 F300 S1000 M3\n" + "\n".join(random_block(rng) for _ in range(rng.randint(3, 15))) + "\nM2\n"


def random_comp_program(rng: random.Random) -> str:
    """A random contour of lines, R arcs and I/J arcs under G41/G42 with tool 1 (3.175 mm)."""
    lines = ["G21 G17 G90 F500 S1000 M3", "T1 M6", "G0 X-40 Y-40 Z5",
             rng.choice(["G41", "G42"]) + (" D1" if rng.random() < 0.5 else "")]
    x, y = -40.0, -40.0
    for k in range(rng.randint(2, 8)):
        kind = rng.random()
        nx, ny = rng.uniform(-30, 30), rng.uniform(-30, 30)
        if k == 0 or kind < 0.5 or math.hypot(nx - x, ny - y) < 1:
            lines.append(f"G1 X{nx:.3f} Y{ny:.3f}" + (f" Z{rng.uniform(-2, 0):.3f}" if rng.random() < 0.2 else ""))
        elif kind < 0.75:
            chord = math.hypot(nx - x, ny - y)
            r = rng.choice([1, -1]) * rng.uniform(chord / 2 + 0.5, chord * 2)
            lines.append(f"{rng.choice(['G2', 'G3'])} X{nx:.3f} Y{ny:.3f} R{r:.3f}")
        else:  # I/J arc: a centre, the end on its circle
            cx, cy = x + rng.uniform(-15, 15), y + rng.uniform(-15, 15)
            radius, a = math.hypot(x - cx, y - cy), rng.uniform(0, 2 * math.pi)
            nx, ny = cx + radius * math.cos(a), cy + radius * math.sin(a)
            lines.append(f"{rng.choice(['G2', 'G3'])} X{nx:.4f} Y{ny:.4f} I{cx - x:.4f} J{cy - y:.4f}")
        x, y = nx, ny
    return "\n".join(lines + ["G40", "G0 X50 Y50", "M2"]) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--count", type=int, default=200)
    ap.add_argument("--kind", choices=("general", "comp"), default="general",
                    help="general: the mix above; comp: contours under cutter radius compensation")
    args = ap.parse_args(argv)
    if RS274 is None:
        print("error: rs274 (LinuxCNC's interpreter, package linuxcnc-uspace) is not installed", file=sys.stderr)
        return 2
    rng = random.Random(args.seed)
    tools = read_tool_table(TABLE, unit_mm=25.4)
    counts = {"agree": 0, "both refuse": 0, "refused by us on purpose": 0, "only rs274 refuses": 0,
              "only we refuse": 0, "disagree": 0}
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.count):
            text = random_program(rng) if args.kind == "general" else random_comp_program(rng)
            path = Path(tmp) / f"fuzz{args.seed}_{i}.ngc"
            path.write_text(text)
            ref = run_rs274(path, tool_table=TABLE)
            try:
                blocks, _ = interpret(text, tools=tools, name=path.name)
            except ProgramError as exc:
                if ref.returncode != 0:
                    counts["both refuse"] += 1
                elif "changes the units with a tool length offset" in str(exc):
                    counts["refused by us on purpose"] += 1
                else:
                    counts["only we refuse"] += 1
                    print(f"only we refuse: {exc}\n{text}")
                continue
            if ref.returncode != 0:
                counts["only rs274 refuses"] += 1
                print(f"only rs274 refuses {path.name}: {ref.message}\n{text}")
                continue
            problem = compare(blocks, ref.moves).problem
            if problem:
                counts["disagree"] += 1
                print(f"disagree {path.name}: {problem}\n{text}")
            else:
                counts["agree"] += 1
    print(f"{args.kind} seed {args.seed}, {args.count} programs: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    return 1 if counts["disagree"] or counts["only we refuse"] or counts["only rs274 refuses"] else 0


if __name__ == "__main__":
    sys.exit(main())

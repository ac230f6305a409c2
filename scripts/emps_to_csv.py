#!/usr/bin/env python3
"""Convert the EMPS benchmark recording (DATA_EMPS.mat) to the SPEC §4 CSV, in mm.

    python scripts/emps_to_csv.py ../shared/data/emps/DATA_EMPS.mat emps.csv
    agent identify emps.csv --report emps.html

qg (reference position, m) is the commanded and qm (motor encoder, m) the actual position.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.io import loadmat


def main(argv: list[str]) -> int:
    if len(argv) != 3:
        print(__doc__.strip().splitlines()[0], file=sys.stderr)
        print("usage: emps_to_csv.py DATA_EMPS.mat OUT.csv", file=sys.stderr)
        return 2
    src, out = Path(argv[1]), Path(argv[2])
    try:
        mat = loadmat(src)
    except (OSError, ValueError) as exc:
        print(f"error: {src}: cannot read ({exc})", file=sys.stderr)
        return 2
    t = mat["t"].ravel()
    t = t - t[0]
    data = np.column_stack([t, mat["qg"].ravel() * 1e3, mat["qm"].ravel() * 1e3])
    np.savetxt(out, data, delimiter=",", header="t_s,X_commanded_mm,X_actual_mm", comments="", fmt="%.10g")
    print(f"wrote {out}: {len(t)} samples, {t[-1]:.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv))

"""Same recording, same answer (issue 39, item 4).

``agent identify REC --validate VAL`` must give the same verdict and parameters (relative
1e-6) whatever the machine: the thread count of its BLAS, the BLAS kernels and numpy loops
its CPU selects; and when every position is moved by a constant (+0.5 mm keeps the encoder grid
and the physics; only a cyclic error's phase moves, by −2π·0.5 mm/P).  Cases: a concealed
cyclic error of fixtures/diagnosis (position enters its physics) and three drive-zoo-dev2
development cases where the offset flipped two verdicts and moved the third case's a1;
across CPUs, the fixture and drive-zoo-dev's case_018, whose verdict the BLAS kernels once
flipped (resonance with OpenBLAS's SkylakeX kernels, backlash with its Haswell ones).  The zoo
cases run when ../shared/data is present.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

import ident
from core.reader import load_recording
from core.recording import AxisTrace, Recording
from ident.model import BASE_KEYS

ROOT = Path(__file__).resolve().parents[1]
# ../shared/data beside a checkout (or beside the worktrees' directory)
ZOO = next((p / "shared" / "data" / "drive-zoo-dev2" for p in (ROOT.parent, ROOT.parent.parent)
            if (p / "shared" / "data" / "drive-zoo-dev2").is_dir()), ROOT.parent / "shared" / "data" / "drive-zoo-dev2")
DEV = ZOO.parent / "drive-zoo-dev"
OFFSET_MM = 0.5
REL = 1e-6

CASES = {
    "fixture cyclic_error": (ROOT / "fixtures" / "diagnosis" / "cyclic_error.csv",
                             ROOT / "fixtures" / "diagnosis" / "cyclic_error_validation.csv"),
    **{f"zoo-dev2 {c}": (ZOO / f"{c}.csv", ZOO / f"{c}_val.csv") for c in ("case_001", "case_004", "case_006")},
}


def shifted(rec: Recording, offset: float) -> Recording:
    """``rec`` with every position moved by ``offset`` mm."""
    axes = {a: AxisTrace(tr.commanded + offset, tr.actual + offset) for a, tr in rec.axes.items()}
    return Recording(t=rec.t, axes=axes, sample_period=rec.sample_period, segment=rec.segment,
                     metadata=dict(rec.metadata))


def outcome(rec: Recording, val: Recording, threads: int) -> dict:
    """Verdict, model and every candidate's numeric parameters of the first axis."""
    with threadpool_limits(limits=threads, user_api="blas"):
        r = next(iter(ident.identify(rec, validate=val).axes.values()))
    d = r.diagnosis
    params = {f"model.{k}": float(getattr(r.model, k)) for k in BASE_KEYS}
    for c in d.candidates:
        for k, v in c.parameters.items():
            if isinstance(v, float):
                params[f"{c.effect}.{k}"] = v
    return {"verdict": d.verdict, "accepted": [c.effect for c in d.candidates if c.accepted], "params": params}


def assert_same(a: dict, b: dict, *, offset: float = 0.0) -> None:
    assert a["verdict"] == b["verdict"]
    assert a["accepted"] == b["accepted"]
    assert a["params"].keys() == b["params"].keys()
    for k, va in a["params"].items():
        vb = b["params"][k]
        if k == "cyclic_error.phase_rad":  # the phase is of absolute position: it moves with the origin
            period = a["params"]["cyclic_error.period_mm"]
            moved = va - 2.0 * math.pi * offset / period
            assert math.sin(vb - moved) == pytest.approx(0.0, abs=REL), k
            continue
        assert vb == pytest.approx(va, rel=REL, abs=1e-12), k


@pytest.fixture(scope="module")
def runs():
    return {}


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES))
def test_the_same_recording_gives_the_same_answer_at_any_origin_and_thread_count(case, runs):
    rec_path, val_path = CASES[case]
    if not rec_path.exists():
        pytest.skip(f"development data not present: {rec_path}")
    rec, val = load_recording(rec_path), load_recording(val_path)
    base = outcome(rec, val, threads=1)
    assert_same(base, outcome(rec, val, threads=2))
    assert_same(base, outcome(shifted(rec, OFFSET_MM), shifted(val, OFFSET_MM), threads=1), offset=OFFSET_MM)


def test_removing_the_reference_keeps_the_encoder_grid_and_is_exact_for_any_origin():
    from ident.preprocessing import position_resolution, prepare_recording, remove_reference

    rec = prepare_recording(load_recording(CASES["fixture cyclic_error"][0]))
    a = rec.axis_names[0]
    rel = remove_reference(rec)
    moved = remove_reference(prepare_recording(shifted(rec, 1234.5678)))
    assert np.array_equal(rel.axes[a].actual, moved.axes[a].actual)
    assert np.array_equal(rel.axes[a].commanded, moved.axes[a].commanded)
    assert rel.axes[a].actual[0] == 0.0
    q = position_resolution(rec.axes[a].actual, rec.segment)
    assert q > 0 and position_resolution(rel.axes[a].actual, rel.segment) == pytest.approx(q, rel=1e-6)
    e = rec.axes[a].commanded - rec.axes[a].actual
    assert np.allclose(rel.axes[a].commanded - rel.axes[a].actual, e, rtol=0, atol=1e-9)
    # the validation recording in the identification's frame
    val = remove_reference(rec, rel.metadata["reference_mm"])
    assert val.metadata["reference_mm"] == rel.metadata["reference_mm"]


#: OpenBLAS's kernels for three generations of x86-64 CPU (``OPENBLAS_CORETYPE``), each with
#: the CPU flag it needs: their products and factorisations sum in different orders.
KERNELS = {"Sandybridge": "avx", "Haswell": "avx2", "SkylakeX": "avx512f"}
#: numpy's loops for AVX-512 CPUs, switched off to stand for a CPU without it (numpy's
#: float64 exp and log differ there in the last bits).
NUMPY_AVX512 = "X86_V4 AVX512_ICL AVX512_SPR"

#: Run in a child process: the outcome of one recording and the BLAS kernels it ran on.
_CHILD = """
import json, sys
sys.path.insert(0, sys.argv[1])
from threadpoolctl import threadpool_info
from core.reader import load_recording
from test_determinism import outcome
res = outcome(load_recording(sys.argv[2]), load_recording(sys.argv[3]), threads=1)
used = sorted({i.get("architecture") or "" for i in threadpool_info() if i.get("internal_api") == "openblas"})
print(json.dumps({"outcome": res, "kernels": used}))
"""


def _kernels_here() -> list[str]:
    """The kernels of KERNELS this CPU can run (empty where /proc/cpuinfo is not readable)."""
    try:
        flags = set(Path("/proc/cpuinfo").read_text().split())
    except OSError:
        return []
    return [k for k, flag in KERNELS.items() if flag in flags]


CROSS_MACHINE_CASES = {
    "fixture cyclic_error": CASES["fixture cyclic_error"],
    "zoo-dev case_018": (DEV / "case_018.csv", DEV / "case_018_val.csv"),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CROSS_MACHINE_CASES))
def test_the_same_recording_gives_the_same_answer_on_an_older_cpu(case):
    """This machine as it is, against an older CPU's BLAS kernels (the oldest of KERNELS it
    runs) and numpy without its AVX-512 loops: two machines, measured on one."""
    rec_path, val_path = CROSS_MACHINE_CASES[case]
    if not rec_path.exists():
        pytest.skip(f"development data not present: {rec_path}")
    kernels = _kernels_here()
    if len(kernels) < 2:
        pytest.skip("this CPU runs fewer than two of OpenBLAS's x86-64 kernels")
    base = {**os.environ, "OPENBLAS_NUM_THREADS": "1",
            "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    base.pop("OPENBLAS_CORETYPE", None)
    base.pop("NPY_DISABLE_CPU_FEATURES", None)
    envs = {"this": base, "older": {**base, "OPENBLAS_CORETYPE": kernels[0], "NPY_DISABLE_CPU_FEATURES": NUMPY_AVX512}}
    procs = {name: subprocess.Popen([sys.executable, "-c", _CHILD, str(ROOT / "tests"), str(rec_path), str(val_path)],
                                    env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for name, env in envs.items()}
    runs = {}
    for name, proc in procs.items():
        out, err = proc.communicate(timeout=900)
        assert proc.returncode == 0, err[-2000:]
        runs[name] = json.loads(out.strip().splitlines()[-1])
    if runs["older"]["kernels"] != [kernels[0]] or runs["this"]["kernels"] == runs["older"]["kernels"]:
        pytest.skip(f"numpy and scipy do not run OpenBLAS's selectable kernels here ({runs['older']['kernels']})")
    assert_same(runs["this"]["outcome"], runs["older"]["outcome"])

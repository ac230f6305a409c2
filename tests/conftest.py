"""Test-session settings shared by every test module."""

import os

# As the CLI does (agent/cli.py): single-threaded BLAS for the many tiny matrix operations.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

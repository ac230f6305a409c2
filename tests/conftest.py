"""Test-session settings shared by every test module, and the rule for tests that need data.

Tests marked ``needs_data`` read a data set kept outside the repository (``../shared/data``:
EMPS, the drive zoos).  Where it is missing they skip; in CI (``CI=true``) that skip fails
the run, so a CI without the data cannot pass by skipping them.
"""

import os

import pytest

# As the CLI does (agent/cli.py): single-threaded BLAS for the many tiny matrix operations.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

#: Values of the CI variable that mean "running in CI" (GitHub, GitLab and most set CI=true).
CI_VALUES = ("1", "true", "yes")


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "needs_data: reads a data set kept outside the repository (../shared/data); "
                   "where it is missing the test skips, except in CI (CI=true), where the skip fails the run")


def in_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() in CI_VALUES


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """In CI a test that needs data must run: its skip (the data are missing) becomes a failure."""
    outcome = yield
    report = outcome.get_result()
    if report.skipped and in_ci() and item.get_closest_marker("needs_data") is not None:
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        report.outcome = "failed"
        report.longrepr = (f"{item.nodeid} needs data that are missing ({reason.removeprefix('Skipped: ')}); "
                           "CI must provide ../shared/data (see README)")

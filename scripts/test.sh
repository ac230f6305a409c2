#!/usr/bin/env bash
# Install rapid-ident with its test extras into ./.venv and run the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
# pip's own output goes to a log, shown only if the install fails
.venv/bin/python -m pip install --upgrade pip > .venv/install.log 2>&1 || { cat .venv/install.log; exit 1; }
.venv/bin/python -m pip install -e '.[test]' >> .venv/install.log 2>&1 || { cat .venv/install.log; exit 1; }
exec .venv/bin/python -m pytest -q "$@"

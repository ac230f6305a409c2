#!/usr/bin/env bash
# TRANSPORT=linuxcnc bash scripts/demo.sh: the main job on a real LinuxCNC (the headless
# test machine of fixtures/linuxcnc/: interpreter, task, planner, motion, pid, a HAL plant):
#   generate → run the programs on LinuxCNC while capturing over HAL (linuxcnc://) → a
#   second run for validation → identify → report.  Results land in $OUT (runs/demo/).
# Called by scripts/demo.sh after it installed rapid-ident into .venv.
set -euo pipefail
cd "$(dirname "$0")/.."
AGENT=.venv/bin/agent
PY=.venv/bin/python
OUT=${OUT:-runs/demo}
MACHINE=fixtures/linuxcnc/machine.py
if ! $PY $MACHINE check; then
  echo "TRANSPORT=linuxcnc needs LinuxCNC on this computer: as root on Debian 12 / Ubuntu 23.04 or later,"
  echo "  apt-get install --no-install-recommends linuxcnc-uspace"
  echo "then run TRANSPORT=linuxcnc bash scripts/demo.sh again (bash scripts/demo.sh runs without it)."
  exit 1
fi
mkdir -p "$OUT/validation"

echo "== 1. generate the identification programs and a second set for validation (LinuxCNC dialect)"
$AGENT generate --axes X --dialect linuxcnc --seed 1 -o "$OUT"
$AGENT generate --axes X --dialect linuxcnc --seed 2 -o "$OUT/validation"

echo "== 2. start the headless LinuxCNC machine (fixtures/linuxcnc/machine.ini)"
RUN=$($PY $MACHINE start)
trap '$PY $MACHINE stop "$RUN" > /dev/null 2>&1 || true' EXIT

# capture LOG while LinuxCNC runs the programs; the capture stops by itself at the program end
capture_run() {
  local log=$1 pid
  shift
  rm -f "$log"
  $AGENT capture --port linuxcnc:// -o "$log" &
  pid=$!
  while [ ! -e "$log" ]; do
    kill -0 $pid 2> /dev/null || { wait $pid; return 1; }
    sleep 0.1
  done
  # --restart: machine off and on first, so that pid's integrator starts at 0 (docs/linuxcnc.md)
  $PY $MACHINE run --restart "$RUN" "$@"
  wait $pid
}

echo "== 3. run both programs on LinuxCNC while capturing over HAL (linuxcnc://), in real time"
capture_run "$OUT/capture.mcap" "$OUT/ident_low.ngc" "$OUT/ident_high.ngc"

echo "== 4. a validation run: the second set, captured the same way"
capture_run "$OUT/validation.mcap" "$OUT/validation/ident_low.ngc" "$OUT/validation/ident_high.ngc"

echo "== 5. identify, validate, diagnose and report"
$AGENT identify "$OUT/capture.mcap" --validate "$OUT/validation.mcap" \
    --json "$OUT/result.json" --report "$OUT/report.html"
echo "report: $OUT/report.html"

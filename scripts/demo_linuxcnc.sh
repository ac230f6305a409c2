#!/usr/bin/env bash
# TRANSPORT=linuxcnc bash scripts/demo.sh: the main job on a real LinuxCNC (the two-axis
# headless test machine of fixtures/linuxcnc/: interpreter, task, planner, motion, pid and
# a HAL plant per axis, X and Y tuned differently):
#   generate → run the programs on LinuxCNC while capturing over HAL (linuxcnc://) → a
#   second run for validation → identify → report → a circle predicted on the identified
#   drives with LinuxCNC's limits, then run on LinuxCNC: predicted vs measured.
# Results land in $OUT (runs/demo/).
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

PORT='linuxcnc://?joints=0,1&axes=X,Y'

echo "== 1. generate the identification programs and a second set for validation (LinuxCNC dialect)"
$AGENT generate --axes X,Y --dialect linuxcnc --seed 1 --n-high 30 -o "$OUT"
$AGENT generate --axes X,Y --dialect linuxcnc --seed 2 --n-high 30 -o "$OUT/validation"

echo "== 2. start the headless two-axis LinuxCNC machine (fixtures/linuxcnc/machine.ini, X and Y)"
RUN=$($PY $MACHINE start --axes XY)
trap '$PY $MACHINE stop "$RUN" > /dev/null 2>&1 || true' EXIT

# capture LOG while LinuxCNC runs the programs; the capture stops by itself at the program end
capture_run() {
  local log=$1 pid
  shift
  rm -f "$log"
  $AGENT capture --port "$PORT" -o "$log" &
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

echo "== 6. a 20 mm circle at 100 mm/s: predicted on the identified drives, planned with the INI's limits,"
echo "      then run on LinuxCNC and captured: predicted vs measured contour error and cycle time"
$AGENT generate --toolpath circle --size 20 --feed 100 --dialect linuxcnc -o "$OUT/circle"
cp "$RUN/machine.ini" "$OUT/machine.ini"
capture_run "$OUT/circle.mcap" "$OUT/circle/circle.ngc"
$AGENT predict "$OUT/circle/circle.ngc" --machine "$OUT/result.json" --ini "$OUT/machine.ini" \
    --against "$OUT/circle.mcap" --report "$OUT/circle.html"

#!/usr/bin/env bash
# The main job, end to end on the built-in simulated controller:
#   install → generate the identification programs → serve them from a simulated
#   controller (serial over a pseudo-terminal) → capture → identify → report.
# Results land in runs/demo/ (report.html, result.json, the logs and programs).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
[ -x .venv/bin/python ] || "$PY" -m venv .venv
# pip's own output goes to a log, shown only if the install fails
.venv/bin/python -m pip install --upgrade pip > .venv/install.log 2>&1 || { cat .venv/install.log; exit 1; }
.venv/bin/python -m pip install -e . >> .venv/install.log 2>&1 || { cat .venv/install.log; exit 1; }
AGENT=.venv/bin/agent
OUT=${OUT:-runs/demo}
TRANSPORT=${TRANSPORT:-serial}
MACHINE=${MACHINE:-fadal-ppi}
# LinuxCNC is a real controller, not a served simulation: its own script
[ "$TRANSPORT" = linuxcnc ] && exec bash scripts/demo_linuxcnc.sh
mkdir -p "$OUT/validation"

echo "== 1. generate the identification programs (low- and high-speed sets, LinuxCNC dialect)"
$AGENT generate --axes X --dialect linuxcnc --seed 1 -o "$OUT"

echo "== 2. serve them from a simulated $MACHINE controller over $TRANSPORT, in real time"
: > "$OUT/serve.log"
$AGENT serve --transport "$TRANSPORT" --machine "$MACHINE" \
    "$OUT/ident_low.ngc" "$OUT/ident_high.ngc" > "$OUT/serve.log" 2>&1 &
SERVE_PID=$!
trap 'kill $SERVE_PID 2>/dev/null || true' EXIT
for _ in $(seq 1 300); do
  PORT=$(sed -n "s/^port: //p" "$OUT/serve.log" | head -n1 | tr -d "'")  # printed shell-quoted
  [ -n "$PORT" ] && break
  kill -0 $SERVE_PID 2>/dev/null || { cat "$OUT/serve.log"; exit 1; }
  sleep 0.1
done
[ -n "$PORT" ] || { echo "the simulated controller did not start"; cat "$OUT/serve.log"; exit 1; }

echo "== 3. capture from $PORT until the program ends"
$AGENT capture --port "$PORT" -o "$OUT/capture.mcap"
wait $SERVE_PID || true

echo "== 4. a validation run: another random program, simulated on the same machine"
$AGENT generate --axes X --dialect linuxcnc --seed 2 -o "$OUT/validation"
$AGENT simulate "$OUT/validation/ident_low.ngc" "$OUT/validation/ident_high.ngc" \
    --machine "$MACHINE" --seed 2 -o "$OUT/validation.mcap"

echo "== 5. identify, validate, diagnose and report"
$AGENT identify "$OUT/capture.mcap" --validate "$OUT/validation.mcap" \
    --json "$OUT/result.json" --report "$OUT/report.html"
echo "report: $OUT/report.html"

#!/usr/bin/env bash
# Render an HTML report as a user sees it: headless Chromium → PNG.
#   bash scripts/screenshot.sh REPORT.html OUT.png [WIDTH,HEIGHT]
# Needs Debian's chromium (apt-get install --no-install-recommends chromium). The report must
# be self-contained: the browser gets no network (background networking off), so a report
# that loads anything from outside shows it missing in the picture.
set -euo pipefail
[ $# -ge 2 ] || { echo "usage: $0 REPORT.html OUT.png [WIDTH,HEIGHT]" >&2; exit 2; }
BROWSER=$(command -v chromium || command -v chromium-browser || true)
[ -n "$BROWSER" ] || { echo "error: chromium not found (apt-get install --no-install-recommends chromium)" >&2; exit 2; }
PROFILE=$(mktemp -d)
trap 'rm -rf "$PROFILE"' EXIT
"$BROWSER" --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
  --disable-background-networking --disable-component-update --disable-sync \
  --user-data-dir="$PROFILE" --window-size="${3:-1200,2400}" \
  --screenshot="$(realpath -m "$2")" "file://$(realpath "$1")" > /dev/null 2>&1
[ -s "$2" ] || { echo "error: no screenshot written" >&2; exit 1; }
echo "$2"

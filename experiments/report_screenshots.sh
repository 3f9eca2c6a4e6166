#!/usr/bin/env bash
# PNG screenshots of an inhand report in headless Chromium: the 3-D model view and the per-view
# curves (and the ranked grasps when the scan re-grasped).
#   experiments/report_screenshots.sh DIR/report.html OUT_PREFIX   →  OUT_PREFIX_model.png, …
set -euo pipefail
report="$(realpath "$1")"
prefix="$2"
chromium="${CHROMIUM:-/usr/bin/chromium}"
[ -x "$chromium" ] || { echo "report_screenshots: $chromium not found (apt-get install chromium)" >&2; exit 2; }
shot() {  # anchor, height, output
  "$chromium" --headless --no-sandbox --disable-gpu --enable-unsafe-swiftshader \
    --use-angle=swiftshader --hide-scrollbars --window-size=1100,"$2" \
    --virtual-time-budget=20000 --screenshot="$3" "file://$report$1" 2> /dev/null
  [ -s "$3" ] || { echo "report_screenshots: no screenshot for $1" >&2; exit 1; }
  echo "report_screenshots: $3"
}
shot "" 720 "${prefix}_model.png"
shot "#only-curves" 720 "${prefix}_curves.png"
shot "#only-grasps" 760 "${prefix}_grasps.png"

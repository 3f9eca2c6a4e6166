#!/usr/bin/env bash
# Closing the loop on the scan set (docs/asset.md): for every run of a scan_set.sh directory, the
# asset exported from it (`inhand export`), then `inhand regrasp-test` with the true object resting
# in another stable pose than the scan's (the next one; turned 30° about the vertical). Writes
# OUT/regrasp/NAME/{asset,report.json,log} and OUT/regrasp.md (experiments/regrasp_table.py).
# Usage: experiments/regrasp_set.sh OUT   (OUT: a scan_set.sh output directory; the build must exist)
set -uo pipefail
cd "$(dirname "$0")/.."
out="${1:?usage: experiments/regrasp_set.sh SCAN_SET_OUT}"
bin="$out/bin/inhand-regrasp"
cp build/inhand "$bin"  # the build may change while this runs
for run in "$out"/runs/*/; do
  run="${run%/}"
  name="$(basename "$run")"
  [ -f "$run/summary.json" ] || continue
  dir="$out/regrasp/$name"
  [ -f "$dir/report.json" ] && continue
  mkdir -p "$dir"
  read -r object pose poses < <(/usr/bin/python3 -c '
import json, sys
s = json.load(open(sys.argv[1]))
r = s["rest_pose"]
p = r.get("pose", 0) if isinstance(r.get("pose"), int) else 0
print(s["object"], p, r.get("stable_poses", 1))' "$run/summary.json")
  test_pose=$(( (pose + 1) % poses ))
  if [ ! -d "$dir/asset" ]; then
    "$bin" export "$run" --out "$dir/asset" --format mjcf,urdf > "$dir/export.log" 2>&1 || {
      echo "regrasp_set: $name: export failed"; continue; }
  fi
  "$bin" regrasp-test "$dir/asset" --object "$object" --rest-pose "$test_pose" --heading 30 \
    --out "$dir/report.json" > "$dir/log" 2>&1
  echo "regrasp_set: $name (scanned in pose $pose, tested in $test_pose) exit $?"
done
/usr/bin/python3 experiments/regrasp_table.py "$out"

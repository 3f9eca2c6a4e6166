#!/usr/bin/env bash
# The grasping test set: every mesh in ../shared/objects in its most probable resting poses
# (REST_POSES, default "0 1") and the procedural objects of experiments/make_test_objects.py (flat
# box, long thin ellipsoid, bowl, bottle, ring, L-bracket, cup, marker, pen, remote-like box,
# small flat hammer) in their most probable pose,
# each scanned from the table with default options. Writes OUT/results.md and OUT/results.csv
# (first grasp made, grasps, views, coverage, accuracy, seconds, termination) as runs finish.
# Usage: experiments/scan_set.sh [OUT]   (default out/scan_set; the build must exist)
# SCAN_CONFIG=FILE adds `--config FILE` to every scan (e.g. physics off: docs/test_set.md).
# SCAN_SEED=N adds `--seed N` (the noise and IK seed; 1 by default).
# SCAN_EXPORT=mjcf,urdf adds `--export mjcf,urdf` (each run's asset; experiments/asset_table.py OUT
# tabulates them: docs/asset.md).
set -uo pipefail
cd "$(dirname "$0")/.."
out="${1:-out/scan_set}"
poses="${REST_POSES:-0 1}"
mkdir -p "$out/runs" "$out/bin"
cp build/inhand "$out/bin/inhand"  # the build may change while this runs
config=()
[ -n "${SCAN_CONFIG:-}" ] && config=(--config "$SCAN_CONFIG")
[ -n "${SCAN_SEED:-}" ] && config+=(--seed "$SCAN_SEED")
[ -n "${SCAN_EXPORT:-}" ] && config+=(--export "$SCAN_EXPORT")
/usr/bin/python3 experiments/make_test_objects.py "$out/objects"
objects=()
for f in "$out"/objects/*.obj; do objects+=("$f:0"); done
if [ -d ../shared/objects ]; then
  for f in ../shared/objects/*.obj; do
    for p in $poses; do objects+=("$f:$p"); done
  done
else
  echo "scan_set: ../shared/objects not found; procedural objects only" >&2
fi
for entry in "${objects[@]}"; do
  mesh="${entry%:*}"
  pose="${entry##*:}"
  name="$(basename "$mesh" .obj)_pose$pose"
  dir="$out/runs/$name"
  if [ -f "$dir/summary.json" ]; then continue; fi
  rm -rf "$dir"
  start=$(date +%s)
  "$out/bin/inhand" scan --object "$mesh" --rest-pose "$pose" "${config[@]}" --out "$dir" \
    > "$out/runs/$name.log" 2>&1
  echo "$?" > "$out/runs/$name.status"
  end=$(date +%s)
  echo "$((end - start))" > "$out/runs/$name.seconds"
  echo "scan_set: $name exit $(cat "$out/runs/$name.status")"
  /usr/bin/python3 experiments/scan_set_table.py "$out"
done
/usr/bin/python3 experiments/scan_set_table.py "$out"

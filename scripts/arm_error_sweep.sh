#!/usr/bin/env bash
# The arm-error sweep (issue: arm error and tracking): whole scans at default settings of three
# objects with three seeds, the simulated arm's error at 0, 0.5, 1, 2, 3 and 5 cm, with and without
# tracking; then the table (docs/arm_error.md, .csv) and the plot (docs/arm_error.svg).
# Usage: scripts/arm_error_sweep.sh [OUT]   (default out/arm_error; about 25 minutes on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-out/arm_error}"
objects="${OBJECTS:-builtin:cracker_box,builtin:juice_bottle,builtin:coffee_can}"
mkdir -p "$out/bin"
# A copy of the binary: the sweep runs for a while, the build may change meanwhile.
cp build/inhand "$out/bin/inhand"
for error in 0 0.005 0.01 0.02 0.03 0.05; do
  for tracking in true false; do
    dir="$out/e${error}_t${tracking}"
    [ -f "$dir/results.csv" ] && continue
    rm -rf "$dir"
    # Every third sensor frame (SUBSAMPLE): the setting docs/arm_error.md was measured with.
    printf '{"sim": {"arm_error_m": %s, "frame_subsample": %s}, "tracking": {"enabled": %s}}\n' \
      "$error" "${SUBSAMPLE:-3}" "$tracking" > "$out/e${error}_t${tracking}.json"
    "$out/bin/inhand" eval --objects "$objects" --planners ig --seeds "${SEEDS:-3}" \
      --config "$out/e${error}_t${tracking}.json" --out "$dir" > "$dir.log" 2>&1 ||
      { echo "arm_error_sweep: $dir failed (see $dir.log)"; exit 1; }
    echo "arm_error_sweep: $dir done"
  done
done
/usr/bin/python3 scripts/arm_error_table.py "$out" docs

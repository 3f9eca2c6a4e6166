#!/usr/bin/env bash
# The arm-error sweep (issue: arm error and tracking): whole scans at default settings of three
# objects with three seeds, the simulated arm's error at 0, 0.5, 1, 2, 3 and 5 cm, with and without
# tracking; the arm's error at the pick-ups too (2 cm, tracking on, the object's pose in the hand
# registered or not); then the tables (docs/arm_error.md, .csv) and the plot (docs/arm_error.svg).
# Usage: experiments/arm_error_sweep.sh [OUT]   (default out/arm_error; about 30 minutes on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-out/arm_error}"
objects="${OBJECTS:-builtin:cracker_box,builtin:juice_bottle,builtin:coffee_can}"
mkdir -p "$out/bin"
# A copy of the binary: the sweep runs for a while, the build may change meanwhile.
cp build/inhand "$out/bin/inhand"
run() {  # run NAME CONFIG-JSON
  local dir="$out/$1"
  [ -f "$dir/results.csv" ] && return 0
  rm -rf "$dir"
  printf '%s\n' "$2" > "$out/$1.json"
  "$out/bin/inhand" eval --objects "$objects" --planners ig --seeds "${SEEDS:-3}" \
    --config "$out/$1.json" --out "$dir" > "$dir.log" 2>&1 ||
    { echo "arm_error_sweep: $dir failed (see $dir.log)"; exit 1; }
  echo "arm_error_sweep: $dir done"
}
# SUBSAMPLE: every n-th sensor frame fused (1, every frame, is the scan's default). The kinematic
# simulator (physics off), which docs/arm_error.md was measured with.
sub="${SUBSAMPLE:-1}"
for error in 0 0.005 0.01 0.02 0.03 0.05; do
  for tracking in true false; do
    run "e${error}_t${tracking}" \
      "{\"sim\": {\"arm_error_m\": $error, \"frame_subsample\": $sub, \"physics\": {\"enabled\": false}}, \"tracking\": {\"enabled\": $tracking}}"
  done
done
# The arm's error at the pick-ups too (sim.grasp_error), 2 cm, tracking on: the object's pose in
# the hand as the joints report it, and registered after each pick-up (tracking.in_hand).
for inhand in false true; do
  run "g0.02_inhand${inhand}" \
    "{\"sim\": {\"arm_error_m\": 0.02, \"grasp_error\": true, \"frame_subsample\": $sub, \"physics\": {\"enabled\": false}}, \"tracking\": {\"enabled\": true, \"in_hand\": $inhand}}"
done
/usr/bin/python3 experiments/arm_error_table.py "$out" docs

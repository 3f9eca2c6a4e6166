#!/usr/bin/env bash
# Every view planner in whole scans (issue: information gain earns its keep): multi-grasp scans
# from the table at default settings and with "initial_views": 1, every planner and seed; then
# the table (docs/planner_eval.md, .csv) and the plots (docs/planner_curves.svg,
# docs/planner_gain.svg).
# Usage: experiments/planner_sweep.sh [OUT]   (default out/planners)
#   OBJECTS=spec,spec…  PLANNERS=…  SEEDS=N  CONFIGS="default initial1"
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-out/planners}"
shared=../shared/objects
objects="${OBJECTS:-builtin:mug,builtin:pill_bottle,$shared/035_power_drill.obj,$shared/021_bleach_cleanser.obj,$shared/stanford_bunny.obj,$shared/006_mustard_bottle.obj}"
planners="${PLANNERS:-ig,ig-no-hand,ig-no-cost,random,area,unobserved-voxels,rear-side-entropy}"
mkdir -p "$out/bin"
# A copy of the binary: the sweep runs for a while, the build may change meanwhile.
cp build/inhand "$out/bin/inhand"
# The simulated sensor delivers every frame (what `inhand scan` does); SUBSAMPLE=n every n-th.
sub="${SUBSAMPLE:-1}"
# The kinematic simulator (physics off), which docs/planner_eval.md was measured with.
echo "{\"sim\": {\"frame_subsample\": $sub, \"physics\": {\"enabled\": false}}}" > "$out/default.json"
echo "{\"initial_views\": 1, \"sim\": {\"frame_subsample\": $sub, \"physics\": {\"enabled\": false}}}" > "$out/initial1.json"
for config in ${CONFIGS:-initial1 default}; do
  dir="$out/$config"
  if [ -f "$dir/results.csv" ]; then continue; fi
  if [ -f "$dir/eval.json" ]; then
    "$out/bin/inhand" eval --resume "$dir" > "$dir.log" 2>&1 ||
      { echo "planner_sweep: $dir failed (see $dir.log)"; exit 1; }
  else
    rm -rf "$dir"
    "$out/bin/inhand" eval --objects "$objects" --planners "$planners" --seeds "${SEEDS:-3}" \
      --config "$out/$config.json" --out "$dir" > "$dir.log" 2>&1 ||
      { echo "planner_sweep: $dir failed (see $dir.log)"; exit 1; }
  fi
  echo "planner_sweep: $dir done"
done
/usr/bin/python3 experiments/planner_table.py "$out" docs

#!/usr/bin/env bash
# Writes the record that Cli.RecordedFramesReplayToTheRecordedModel replays (tests/data/replay):
# the in-hand frames of a one-grasp coffee-can scan (every third of them: 10 frames, with the
# joints, camera poses and grasp the robot reported) and the model `inhand fuse --robot
# --tracking off` makes of them, and the view Alg. 1 chooses on that model (planner.json, which
# ViewSelection.TheRecordedChoiceIsANearTieOnThisCpu checks as a near-tie).
# Usage: bash tests/record_replay.sh [--model-only] [BUILD_DIR]
# --model-only keeps the recorded frames and fuses them again (after a change to fusion).
set -euo pipefail
cd "$(dirname "$0")/.."
model_only=0
if [ "${1:-}" = --model-only ]; then
  model_only=1
  shift
fi
build="${1:-build}"
inhand="$build/inhand"
out=tests/data/replay
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
if [ "$model_only" = 0 ]; then
cat > "$tmp/quick.json" <<'JSON'
{"voxel_m": 0.004, "initial_views": 2,
 "planner": {"directions": 40, "rolls": 4, "fallback_ranges_m": []},
 "grasp": {"approaches": 16, "rolls": 2, "max_candidates": 6,
           "ranking": {"directions": 24, "rolls": 2}},
 "sim": {"frame_subsample": 10, "physics": {"enabled": false}}, "eval": {"samples": 4000}}
JSON
"$inhand" scan --object builtin:coffee_can --max-grasps 1 --max-views 2 --save-frames \
  --config "$tmp/quick.json" --seed 5 --out "$tmp/scan" > /dev/null 2>&1
rm -rf "$out"
mkdir -p "$out"
/usr/bin/python3 - "$tmp/scan/frames" "$out" <<'PY'
import json, os, shutil, sys
src, dst = sys.argv[1], sys.argv[2]
j = json.load(open(os.path.join(src, "frames.json")))
j["frames"] = j["frames"][::3]
for f in j["frames"]:
    shutil.copy(os.path.join(src, f["file"]), dst)
json.dump(j, open(os.path.join(dst, "frames.json"), "w"), indent=1)
PY
fi
"$inhand" fuse --frames "$out" --robot data/robots/wam_barretthand.json --tracking off \
  --voxel 0.004 --out "$tmp/model.ply" > /dev/null 2>&1
cp "$tmp/model.ply" "$out/model.ply"
INHAND_WRITE_PLANNER_RECORD=1 "$build/tests/test_planning" \
  --gtest_filter=ViewSelection.TheRecordedChoiceIsANearTieOnThisCpu > /dev/null
echo "record written to $out: $(ls "$out" | wc -l) files"

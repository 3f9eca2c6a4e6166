#!/usr/bin/env bash
# How the first grasp's candidates hold over the grasping test set (the objects and poses of
# experiments/scan_set.sh): for each, build/bench/first_grasp_eval runs the scan's table-top stage
# with physics on and picks up each of its first CANDIDATES (default 12) in the scan's order,
# lifts and turns it (docs/physics.md). Writes OUT/runs/NAME.csv per object and prints the sums:
# the first candidate held, and the hold rates by the hold test's verdict.
# Usage: experiments/first_grasp_set.sh [OUT] [CANDIDATES]   (default out/first_grasp_set, 12)
# GRASP_CONFIG=FILE: a config over physics on; FIRST_GRASP_EVAL=BINARY: another build of the bench;
# REGRASP=1: the second grasp's candidates instead (the first grasp scanned and put down first).
# SEED=N: the noise and IK seed (as SCAN_SEED for scan_set.sh; 1 by default).
set -uo pipefail
cd "$(dirname "$0")/.."
out="${1:-out/first_grasp_set}"
candidates="${2:-12}"
poses="${REST_POSES:-0 1}"
mkdir -p "$out/runs" "$out/bin"
# A copy: the build may change while this runs.
cp "${FIRST_GRASP_EVAL:-build/bench/first_grasp_eval}" "$out/bin/first_grasp_eval"
config="$out/physics.json"
if [ -n "${GRASP_CONFIG:-}" ]; then
  /usr/bin/python3 - "$GRASP_CONFIG" "$config" <<'PY'
import json, sys
c = json.load(open(sys.argv[1]))
c.setdefault("sim", {}).setdefault("physics", {})["enabled"] = True
json.dump(c, open(sys.argv[2], "w"))
PY
else
  echo '{"sim": {"physics": {"enabled": true}}}' > "$config"
fi
/usr/bin/python3 experiments/make_test_objects.py "$out/objects"
objects=()
for f in "$out"/objects/*.obj; do objects+=("$f:0"); done
for f in ../shared/objects/*.obj; do
  [ -f "$f" ] || continue
  for p in $poses; do objects+=("$f:$p"); done
done
for entry in "${objects[@]}"; do
  mesh="${entry%:*}"
  pose="${entry##*:}"
  name="$(basename "$mesh" .obj)_pose$pose"
  [ -f "$out/runs/$name.csv" ] && continue
  "$out/bin/first_grasp_eval" "$mesh" "$pose" "$candidates" "$config" \
    ${REGRASP:+regrasp} > "$out/runs/$name.tmp" \
    2> "$out/runs/$name.log" && mv "$out/runs/$name.tmp" "$out/runs/$name.csv"
  tail -n 1 "$out/runs/$name.csv" 2> /dev/null || echo "$name: failed (see $out/runs/$name.log)"
done
# Sums of the last lines: "... first OUTCOME; hold test yes: A of B held; no: C of D held".
cat "$out"/runs/*.csv | awk '
  / pose [0-9]+: first / {
    n++; if ($0 ~ /: first held;/) first++
    split($0, s, "yes: "); split(s[2], y, " "); ya += y[1]; yb += y[3]
    split($0, t, "no: "); split(t[2], z, " "); na += z[1]; nb += z[3]
  }
  END { printf "%d objects: first candidate held %d; said holds: held %d of %d; said not: held %d of %d\n", n, first, ya, yb, na, nb }'

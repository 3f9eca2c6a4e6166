#!/usr/bin/env bash
# Scans every built-in object from the table top with the default options (after scripts/build.sh)
# and prints, per object, the σ = 5 cm (unknown) area after each grasp and the final line of the
# scan (grasps, views, termination, coverage, accuracy, time). Models in ./out/scans/<object>.
# The figures of the README's per-object table come from this script. Extra arguments (e.g.
# --config FILE) are passed to every scan.
set -uo pipefail
cd "$(dirname "$0")/.."
[ -x build/inhand ] || { echo "build first: bash scripts/build.sh" >&2; exit 1; }
mkdir -p out/scans
status=0
for object in cracker_box coffee_can juice_bottle mug pill_bottle; do
  rm -rf "out/scans/$object"
  log=$(./build/inhand scan --object "builtin:$object" --out "out/scans/$object" "$@" 2>&1)
  code=$?
  # Exit 4 is a scan that ended without a grasp (a termination word, not a crash).
  [ $code -eq 0 ] || [ $code -eq 4 ] || status=1
  areas=$(printf '%s\n' "$log" | sed -n 's/.*grasp [0-9]*: .*unknown area \([0-9.]*\) m².*/\1/p' |
    paste -sd' ' | sed 's/ / -> /g')
  printf '%-13s unknown area per grasp (m²): %s\n' "$object" "${areas:-none}"
  printf '%s\n' "$log" | grep "^scan: builtin:" | sed 's/^scan: /              /'
done
exit $status

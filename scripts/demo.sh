#!/usr/bin/env bash
# The README's main command: installs what is missing, builds, and scans the built-in cracker box
# with the simulated WAM + BarrettHand, re-grasping as needed (3 grasps). Output in ./out/cracker_box
# (model.ply, summary.json, report.html, model.png, truth.ply, grasps/).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
bash scripts/build.sh
rm -rf out/cracker_box
mkdir -p out
./build/inhand scan --object builtin:cracker_box --out out/cracker_box
./build/inhand snapshot out/cracker_box/model.ply --out out/cracker_box/model.png

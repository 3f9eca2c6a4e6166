#!/usr/bin/env bash
# The README's main command: installs what is missing, builds, and scans the built-in juice bottle
# held by the simulated WAM + BarrettHand (single grasp). Output in ./out/juice_bottle
# (model.ply, summary.json, model.png).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
bash scripts/build.sh
rm -rf out/juice_bottle
mkdir -p out
./build/inhand scan --object builtin:juice_bottle --max-grasps 1 --out out/juice_bottle
./build/inhand snapshot out/juice_bottle/model.ply --out out/juice_bottle/model.png

#!/usr/bin/env bash
# The README's main command: installs what is missing, builds, and models the built-in mug from
# 40 simulated depth views. Output in ./out/mug (depth PNGs, frames.json, model.ply, model.json).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
bash scripts/build.sh
rm -rf out/mug
./build/inhand render --object builtin:mug --views 40 --out out/mug
./build/inhand fuse --frames out/mug --out out/mug/model.ply

#!/usr/bin/env bash
# Real Kinect RGB-D frames with colour (docs/colour.md): the 50 frames of ../shared/data/sevenscenes
# written as frames.json (every frame, and 40 with every 5th held out), the 40 fused with their
# colours by `inhand fuse` (1 cm voxels, the observed surface), and held-out frame 24 shown beside
# the model rendered from its camera. Usage: experiments/sevenscenes_colour.sh [OUT] (default
# out/sevenscenes; the build must exist).
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-out/sevenscenes}"
data="$(cd ../shared/data/sevenscenes && pwd)"
mkdir -p "$out/all" "$out/fused"
/usr/bin/python3 - "$data" "$out" <<'PY'
import json, sys
import numpy as np
data, out = sys.argv[1], sys.argv[2]
K = {"width": 640, "height": 480, "fx": 585, "fy": 585, "cx": 320, "cy": 240}
frames = []
for f in range(0, 1000, 20):
    M = np.loadtxt(f"{data}/frame-{f:06d}.pose.txt")  # camera to world: T_O_C with O the world
    U, _, Vt = np.linalg.svd(M[:3, :3])
    M[:3, :3] = U @ Vt  # orthonormal to ~1e-4 in the files: the nearest rotation
    frames.append({"file": f"{data}/frame-{f:06d}.depth.png",
                   "colour": f"{data}/frame-{f:06d}.color.jpg", "T_O_C": M.flatten().tolist()})
for name, kept in (("all", frames), ("fused", [fr for i, fr in enumerate(frames) if i % 5 != 4])):
    json.dump({"depth_scale_m": 0.001, "intrinsics": K, "colour_intrinsics": K, "frames": kept},
              open(f"{out}/{name}/frames.json", "w"), indent=1)
PY
./build/inhand fuse --frames "$out/fused" --out "$out/scene.ply" --voxel 0.01 --surface observed
./build/inhand snapshot "$out/scene.ply" --view-from "$out/all:24" --out "$out/frame24.png"

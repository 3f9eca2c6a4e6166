#!/usr/bin/env python3
"""Fuse recorded depth frames (frames.json + 16-bit PNGs, as `inhand render` writes and as you
record from your own robot) into a model with per-vertex variance, from Python.

    PYTHONPATH=build/python /usr/bin/python3 examples/python/fuse_frames.py FRAMES_DIR OUT.ply
"""
import sys

import numpy as np

import inhand


def main(frames_dir, out_ply):
    frames = inhand.load_frames(frames_dir)
    lo, hi = frames.bounds_min, frames.bounds_max
    if lo is None:  # no bounds_O in frames.json: a 30 cm cube around the origin of frame O
        lo, hi = np.full(3, -0.15), np.full(3, 0.15)
    volume = inhand.Volume(lo, hi, voxel_m=0.002)
    for frame in frames:
        volume.integrate(frame.depth_m, frame.T_O_C, frames.camera)
    model = volume.extract()  # closed over what was never seen; surface="observed": measured only
    model.save_ply(out_ply)
    unseen = model.variance >= 0.05 ** 2 * 0.99
    print(f"{len(frames)} frames -> {out_ply}: {len(model.vertices)} vertices, "
          f"{len(model.faces)} faces, observed {100 * model.observed_fraction():.1f}% of the "
          f"surface, {unseen.sum()} vertices never seen, mean entropy {model.mean_entropy():.3f}")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    try:
        main(sys.argv[1], sys.argv[2])
    except inhand.Error as e:
        sys.exit(f"fuse_frames: error: {e}")

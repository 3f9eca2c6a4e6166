#!/usr/bin/python3
"""Writes the procedural objects of the grasping test set as OBJ files (metres) into a folder:
classes the built-in and YCB objects do not cover. Deterministic; no dependencies."""
import math
import os
import sys


def write_obj(path, verts, faces):
    with open(path + ".tmp", "w") as f:
        for v in verts:
            f.write("v %.6f %.6f %.6f\n" % v)
        for t in faces:
            f.write("f %d %d %d\n" % (t[0] + 1, t[1] + 1, t[2] + 1))
    os.replace(path + ".tmp", path)


def box(sx, sy, sz, cx=0.0, cy=0.0, cz=0.0, base=0):
    v = [(cx + sx * (i - 0.5), cy + sy * (j - 0.5), cz + sz * (k - 0.5))
         for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    f = []
    for a, b, c, d in quads:
        f += [(base + a, base + b, base + c), (base + a, base + c, base + d)]
    return v, f


def revolve(profile, segments=64, closed_loop=False):
    """profile: (r, z) points; a surface of revolution about z. Open profiles that start and end
    on the axis (r = 0) give closed solids; closed_loop joins the last point to the first."""
    verts, faces, rings = [], [], []
    for r, z in profile:
        if r < 1e-9:
            rings.append([len(verts)])
            verts.append((0.0, 0.0, z))
        else:
            ring = []
            for s in range(segments):
                a = 2 * math.pi * s / segments
                ring.append(len(verts))
                verts.append((r * math.cos(a), r * math.sin(a), z))
            rings.append(ring)
    pairs = list(zip(rings[:-1], rings[1:]))
    if closed_loop:
        pairs.append((rings[-1], rings[0]))
    for a, b in pairs:
        for s in range(segments):
            t = (s + 1) % segments
            if len(a) == 1:
                faces.append((a[0], b[t], b[s]))
            elif len(b) == 1:
                faces.append((a[s], a[t], b[0]))
            else:
                faces += [(a[s], a[t], b[t]), (a[s], b[t], b[s])]
    return verts, faces


def main(out):
    os.makedirs(out, exist_ok=True)
    # A flat box (a book-like 150 x 110 x 28 mm).
    write_obj(os.path.join(out, "flat_box.obj"), *box(0.15, 0.11, 0.028))
    # A long thin fruit-like object: an ellipsoid 220 x 34 x 34 mm.
    prof = [(0.017 * math.sin(math.pi * k / 24), 0.11 * math.cos(math.pi * k / 24)) for k in range(25)]
    v, f = revolve(prof, 32)
    v = [(z, x, y) for x, y, z in v]  # long axis along x
    write_obj(os.path.join(out, "long_thin.obj"), v, f)
    # A shallow thin-walled bowl: outer radius 75 mm, 45 mm high, 4 mm wall.
    outer = [(0.0, 0.0), (0.04, 0.0), (0.06, 0.012), (0.072, 0.03), (0.075, 0.045)]
    inner = [(0.071, 0.045), (0.068, 0.032), (0.056, 0.016), (0.037, 0.004), (0.0, 0.004)]
    write_obj(os.path.join(out, "bowl.obj"), *revolve(outer + inner, 64))
    # A bottle: body radius 35 mm, 150 mm; shoulder; neck radius 13 mm, to 215 mm.
    prof = [(0.0, 0.0), (0.035, 0.0), (0.035, 0.15), (0.025, 0.175), (0.013, 0.185),
            (0.013, 0.215), (0.0, 0.215)]
    write_obj(os.path.join(out, "bottle.obj"), *revolve(prof, 48))
    # A ring (torus): 45 mm to the tube's centre, tube radius 9 mm.
    prof = [(0.045 + 0.009 * math.cos(2 * math.pi * k / 16), 0.009 * math.sin(2 * math.pi * k / 16))
            for k in range(16)]
    write_obj(os.path.join(out, "ring.obj"), *revolve(prof, 48, closed_loop=True))
    # An L-shaped bracket of 6 mm plate: 120 x 50 mm base, 80 mm upright.
    v1, f1 = box(0.12, 0.05, 0.006, 0.0, 0.0, 0.003)
    v2, f2 = box(0.006, 0.05, 0.08, -0.057, 0.0, 0.046, base=8)
    write_obj(os.path.join(out, "bracket.obj"), v1 + v2, f1 + f2)
    # A mug-like open cup without a handle: radius 40 mm, 95 mm high, 4 mm wall.
    prof = [(0.0, 0.0), (0.04, 0.0), (0.04, 0.095), (0.036, 0.095), (0.036, 0.005), (0.0, 0.005)]
    write_obj(os.path.join(out, "cup.obj"), *revolve(prof, 48))
    # Thin objects that lie flat: a marker (19 mm across, 130 mm) and a pen (12 mm, 140 mm), each
    # a capped cylinder along x; a remote-control-like box 180 x 50 x 20 mm; a small flat hammer
    # (a 180 x 18 x 12 mm handle, a 22 x 80 x 22 mm head across its end).
    for name, r, length in (("marker", 0.0095, 0.13), ("pen", 0.006, 0.14)):
        prof = [(0.0, -length / 2), (r, -length / 2), (r, length / 2), (0.0, length / 2)]
        v, f = revolve(prof, 32)
        write_obj(os.path.join(out, name + ".obj"), [(z, x, y) for x, y, z in v], f)
    write_obj(os.path.join(out, "remote.obj"), *box(0.18, 0.05, 0.02))
    v1, f1 = box(0.18, 0.018, 0.012, -0.01, 0.0, 0.0)
    v2, f2 = box(0.022, 0.08, 0.022, 0.091, 0.0, 0.0, base=8)
    write_obj(os.path.join(out, "flat_hammer.obj"), v1 + v2, f1 + f2)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "out/test_objects")

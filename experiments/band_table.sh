#!/usr/bin/env bash
# The reach behind each measurement (scan/fuse option band_sigmas) and depth smoothing against the
# paper's full band: each object rendered from 40 views all around (`inhand render`, 0.7 m, seeded
# noise), fused at 2 mm voxels with band_sigmas 0 and raw depths (the full 8 mm band), band_sigmas
# 2 and raw depths, and band_sigmas 2 with smoothed depths (the default), scored against its mesh
# (`inhand compare`). Writes OUT.md (default docs/volume_band.md) and OUT.csv.
# Usage: experiments/band_table.sh [OUT.md]   (the build must exist; meshes from ../shared/objects)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-docs/volume_band.md}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
inhand=./build/inhand
/usr/bin/python3 experiments/make_test_objects.py "$work/objects" > /dev/null
objects=()
for n in 003_cracker_box 006_mustard_bottle 019_pitcher_base 025_mug 035_power_drill stanford_bunny; do
  [ -f "../shared/objects/$n.obj" ] && objects+=("../shared/objects/$n.obj")
done
for n in bowl cup bracket; do [ -f "$work/objects/$n.obj" ] && objects+=("$work/objects/$n.obj"); done
# Thinner still: a 1.5 mm plate (100 x 100 mm) and a cup with 2 mm walls (radius 40 mm, 80 mm).
/usr/bin/python3 - "$work/objects" << 'PY'
import math, os, sys
out = sys.argv[1]
def write(name, v, f):
    with open(os.path.join(out, name), "w") as o:
        o.writelines("v %.6f %.6f %.6f\n" % p for p in v)
        o.writelines("f %d %d %d\n" % (a + 1, b + 1, c + 1) for a, b, c in f)
v = [(x * 0.05, y * 0.05, z * 0.00075) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
f = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7), (2, 7, 6),
     (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
write("plate_1p5mm.obj", v, f)
prof = [(0.04, 0.0), (0.04, 0.08), (0.038, 0.08), (0.038, 0.002)]  # bottom pole (0,0), top (0,0.002)
n = 96
v = [(0.0, 0.0, 0.0)]
for r, z in prof:
    v += [(r * math.cos(2 * math.pi * k / n), r * math.sin(2 * math.pi * k / n), z) for k in range(n)]
v.append((0.0, 0.0, 0.002))
f = [(0, 1 + (k + 1) % n, 1 + k) for k in range(n)]
for ring in range(len(prof) - 1):
    a, b = 1 + ring * n, 1 + (ring + 1) * n
    for k in range(n):
        k1 = (k + 1) % n
        f += [(a + k, a + k1, b + k1), (a + k, b + k1, b + k)]
top, last = len(v) - 1, 1 + (len(prof) - 1) * n
f += [(top, last + k, last + (k + 1) % n) for k in range(n)]
write("cup_2mm.obj", v, f)
PY
objects+=("$work/objects/plate_1p5mm.obj" "$work/objects/cup_2mm.obj")
csv="${out%.md}.csv"
echo "object,band_sigmas,smooth_depth,coverage,accuracy_mean_mm,accuracy_p95_mm,fscore_2mm" > "$csv.tmp"
{
  echo "# Thin walls: the band behind each measurement"
  echo
  echo "\`bash experiments/band_table.sh\`: each object rendered from 40 views all around at 0.7 m"
  echo "(\`inhand render\`), fused at 2 mm voxels (\`inhand fuse --band-sigmas K --smooth-depth S\`),"
  echo "scored by \`inhand compare\` (coverage within 3 mm; accuracy of the observed surface). Each"
  echo "cell: the paper's full band on raw depths (K 0, S false) / the reach of 2σ behind the smoothed"
  echo "surface on raw depths (2, false) / the same on smoothed depths (2, true: the default)."
  echo
  echo "| object | coverage % | mean mm | p95 mm | F-score 2 mm |"
  echo "|---|---|---|---|---|"
} > "$out.tmp"
for f in "${objects[@]}"; do
  name="$(basename "$f" .obj)"
  "$inhand" render --object "$f" --views 40 --out "$work/$name" > /dev/null 2>&1
  row=()
  for setting in "0 false" "2 false" "2 true"; do
    read -r k smooth <<< "$setting"
    ply="$work/$name/k$k-$smooth.ply"
    "$inhand" fuse --frames "$work/$name" --band-sigmas "$k" --smooth-depth "$smooth" --out "$ply" \
      > /dev/null 2>&1
    j="$("$inhand" compare "$ply" --truth "$f" --json)"
    vals="$(/usr/bin/python3 -c 'import json,sys; d=json.loads(sys.argv[1]); print("%.1f %.2f %.2f %.3f" % (100*d["coverage"], d["accuracy_mm"]["mean"], d["accuracy_mm"]["p95"], d["fscore"]["2mm"]["f"]))' "$j")"
    row+=($vals)
    echo "$name,$k,$smooth,${vals// /,}" >> "$csv.tmp"
  done
  echo "| $name | ${row[0]} / ${row[4]} / ${row[8]} | ${row[1]} / ${row[5]} / ${row[9]} | ${row[2]} / ${row[6]} / ${row[10]} | ${row[3]} / ${row[7]} / ${row[11]} |" >> "$out.tmp"
  echo "band_table: $name done" >&2
done
mv "$csv.tmp" "$csv"
mv "$out.tmp" "$out"
echo "band_table: $out"

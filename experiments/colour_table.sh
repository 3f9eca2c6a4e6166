#!/usr/bin/env bash
# Colour accuracy table (docs/colour.md): every textured mesh in ../shared/objects/textured and
# the built-in objects (2 cm checkerboard) scanned autonomously from the table with the colour
# camera on, as configured (shading and noise on), and with shading and noise off. Writes
# OUT/results.md. Usage: experiments/colour_table.sh [OUT]   (default out/colour; the build must exist)
set -uo pipefail
cd "$(dirname "$0")/.."
out="${1:-out/colour}"
mkdir -p "$out/runs"
cp build/inhand "$out/inhand"
# The kinematic simulator (physics off), which docs/colour.md was measured with.
echo '{"sim": {"physics": {"enabled": false}, "colour": {"enabled": true}}}' > "$out/on.json"
echo '{"sim": {"physics": {"enabled": false}, "noise": false, "colour": {"enabled": true, "ambient": 1, "noise_sigma": 0, "exposure_sigma": 0}}}' > "$out/flat.json"
objects=(builtin:cracker_box builtin:coffee_can builtin:juice_bottle)
if [ -d ../shared/objects/textured ]; then
  for f in ../shared/objects/textured/*/textured.obj; do objects+=("$f"); done
fi
row() {  # name config -> one table row
  /usr/bin/python3 - "$1" "$2" <<'PY'
import json, sys
d = sys.argv[1]
try:
    s = json.load(open(d + "/summary.json"))
except Exception:
    print("| %s | %s | (failed) |" % (d.split("/")[-1], sys.argv[2])); sys.exit()
c = s.get("colour", {})
print("| %s | %s | %.1f | %.2f | %.1f | %.1f | %.0f %% | %.1f | %.1f | %.1f | %.1f |" % (
    d.split("/")[-1].rsplit("_", 1)[0], sys.argv[2], 100 * s["coverage"], s["accuracy_mm"]["mean"],
    c.get("delta_e76_mean", 0), c.get("delta_e76_p95", 0), 100 * c.get("colour_edge_share", 0),
    c.get("delta_e76_mean_at_edges", 0), c.get("delta_e76_mean_off_edges", 0),
    c.get("psnr_db_8_views", 0), c.get("fusion_ms_per_frame", 0)))
PY
}
{
  echo "| object | lighting and noise | coverage % | accuracy mm | ΔE76 mean | ΔE76 p95 | at edges | ΔE76 there | ΔE76 off edges | PSNR dB | colour ms/frame |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|"
} > "$out/results.md"
for o in "${objects[@]}"; do
  if [[ "$o" == builtin:* ]]; then name="${o#builtin:}"; else name="$(basename "$(dirname "$o")")"; fi
  for cfg in on flat; do
    dir="$out/runs/${name}_$cfg"
    [ -f "$dir/summary.json" ] || "$out/inhand" scan --object "$o" --config "$out/$cfg.json" \
      --out "$dir" > "$dir.log" 2>&1
    label="shaded, noise"; [ "$cfg" = flat ] && label="unlit, no noise"
    row "$dir" "$label" >> "$out/results.md"
    echo "colour_table: $name $cfg done"
  done
done
cat "$out/results.md"

#!/usr/bin/python3
"""Tabulates the assets of a scan set run with SCAN_EXPORT (experiments/scan_set.sh): per object the
mass the arm weighed against the simulated truth, the centre of mass, the asset's volume against
the true solid's, its convex pieces, and its grasp set (the grasps the scan tried, and the
ranked ones that held the model in the hold test). Writes OUT/assets.md.
Usage: experiments/asset_table.py OUT"""
import json
import math
import pathlib
import sys

out = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "out/scan_set")
rows = []
errors = []
for run in sorted((out / "runs").iterdir()):
    if run.name.startswith(".") or not run.is_dir() or not (run / "summary.json").exists():
        continue
    s = json.loads((run / "summary.json").read_text())
    asset_file = run / "asset" / "asset.json"
    a = json.loads(asset_file.read_text()) if asset_file.exists() else None
    p = s.get("payload")
    density = s["options"]["sim"]["physics"]["density_kg_m3"]
    row = [run.name, s["termination"]]
    if p:
        err = 100 * (p["mass_kg"] / p["true_mass_kg"] - 1)
        errors.append((abs(err), abs(p["mass_kg"] - p["true_mass_kg"]) <= 2 * p["sigma_kg"],
                       p["true_mass_kg"]))
        com = "–"
        if p.get("com_O") is not None:
            com = "%.0f" % (1000 * math.dist(p["com_O"], p["true_com_O"]))
        row += ["%.4f ± %.4f" % (p["mass_kg"], p["sigma_kg"]), "%.4f" % p["true_mass_kg"],
                "%+.1f" % err, com, str(p["readings"])]
        true_volume = p["true_mass_kg"] / density
    else:
        row += ["–"] * 5
        true_volume = None
    if a:
        vol = "%+.1f" % (100 * (a["volume_m3"] / true_volume - 1)) if true_volume else "–"
        g = json.loads((run / "asset" / "grasps.json").read_text())
        tried = [x for x in g if x.get("source", "tried") == "tried"]
        held = sum(1 for x in tried if x["outcome"] == "held")
        row += [vol, str(a["collision_pieces"]),
                "%d (%d held) + %d ranked" % (len(tried), held, len(g) - len(tried))]
    else:
        row += ["no asset", "–", "–"]
    rows.append(row)

head = ["run", "termination", "weighed kg", "true kg", "mass error %", "centre of mass error mm",
        "readings", "asset volume vs true %", "convex pieces", "grasp set: tried + ranked"]
lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
lines += ["| " + " | ".join(r) + " |" for r in rows]
if errors:
    e = sorted(x[0] for x in errors)
    heavy = [x for x in errors if x[2] >= 0.1]
    lines.append("")
    lines.append("Mass error over %d runs: median %.1f %%, largest %.1f %%; within 10 %%: %d; "
                 "within 2 σ: %d. Objects of 0.1 kg or more: %d runs, within 10 %%: %d, largest "
                 "%.1f %%." %
                 (len(e), e[len(e) // 2], e[-1], sum(1 for x in e if x <= 10),
                  sum(1 for x in errors if x[1]), len(heavy),
                  sum(1 for x in heavy if x[0] <= 10), max([x[0] for x in heavy] or [0])))
(out / "assets.md").write_text("\n".join(lines) + "\n")
print("\n".join(lines[-3:]))

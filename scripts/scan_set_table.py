#!/usr/bin/python3
"""Tabulates scripts/scan_set.sh runs: OUT/results.md and OUT/results.csv."""
import csv
import json
import os
import sys

out = sys.argv[1]
runs = os.path.join(out, "runs")
rows = []
for name in sorted(os.listdir(runs)):
    if not name.endswith(".status"):
        continue
    run = name[: -len(".status")]
    status = open(os.path.join(runs, name)).read().strip()
    seconds = open(os.path.join(runs, run + ".seconds")).read().strip()
    s = {}
    path = os.path.join(runs, run, "summary.json")
    if os.path.exists(path):
        s = json.load(open(path))
    grasps = len(s.get("grasps", []))
    attempts = s.get("table_top", {}).get("pick_up_attempts", [])
    rows.append({
        "object": run,
        "exit": status,
        "first_grasp": "yes" if grasps > 0 else "no",
        "pick_attempts": len(attempts),
        "grasps": grasps,
        "views": len(s.get("views", [])),
        "coverage_pct": "%.1f" % (100 * s["coverage"]) if "coverage" in s else "",
        "accuracy_mm": "%.2f" % s["accuracy_mm"]["mean"] if "accuracy_mm" in s else "",
        "p95_mm": "%.2f" % s["accuracy_mm"]["p95"] if "accuracy_mm" in s else "",
        "detached_cm2": "%.1f" % (1e4 * s["detached_area_m2"]) if "detached_area_m2" in s else "",
        "seconds": "%.0f" % float(seconds or 0),
        "termination": s.get("termination", "(no summary)"),
    })
keys = ["object", "exit", "first_grasp", "pick_attempts", "grasps", "views", "coverage_pct", "accuracy_mm",
        "p95_mm", "detached_cm2", "seconds", "termination"]
with open(os.path.join(out, "results.csv.tmp"), "w", newline="") as f:
    w = csv.DictWriter(f, keys)
    w.writeheader()
    w.writerows(rows)
os.replace(os.path.join(out, "results.csv.tmp"), os.path.join(out, "results.csv"))
n = len(rows)
first = sum(r["first_grasp"] == "yes" for r in rows)
cov97 = sum(r["coverage_pct"] != "" and float(r["coverage_pct"]) >= 97 for r in rows)
le3 = sum(r["grasps"] <= 3 for r in rows)
picks = sum(r["pick_attempts"] for r in rows)
firstHeld = sum(r["pick_attempts"] == 1 and r["first_grasp"] == "yes" for r in rows)
acc1 = sum(r["accuracy_mm"] != "" and float(r["accuracy_mm"]) <= 1.0 for r in rows)
p95 = sum(r["p95_mm"] != "" and float(r["p95_mm"]) <= 3.0 for r in rows)
detached = sum(r["detached_cm2"] != "" and float(r["detached_cm2"]) > 0 for r in rows)
with open(os.path.join(out, "results.md.tmp"), "w") as f:
    f.write("| " + " | ".join(keys) + " |\n|" + "---|" * len(keys) + "\n")
    for r in rows:
        f.write("| " + " | ".join(str(r[k]) for k in keys) + " |\n")
    f.write("\n%d objects: first grasp on %d (%.0f %%), coverage >= 97 %% on %d (%.0f %%), "
            "<= 3 grasps on %d; %d first-grasp pick-up attempts, the first candidate held on %d; "
            "mean accuracy <= 1 mm on %d, p95 <= 3 mm on %d, a detached piece on %d.\n"
            % (n, first, 100.0 * first / max(n, 1), cov97, 100.0 * cov97 / max(n, 1), le3, picks,
               firstHeld, acc1, p95, detached))
os.replace(os.path.join(out, "results.md.tmp"), os.path.join(out, "results.md"))

#!/usr/bin/python3
"""Tabulates experiments/scan_set.sh runs: OUT/results.md and OUT/results.csv."""
import csv
import json
import os
import sys

out = sys.argv[1]
runs = os.path.join(out, "runs")
rows = []
all_attempts = []
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
    # Every pick-up of the scan, one list per grasp (the first grasp's are the table top's).
    per_grasp = [attempts] + [g.get("pick_up_attempts", []) for g in s.get("grasps", [])[1:]]
    per_grasp.append(s.get("failed_regrasp_attempts", []))
    for lst in per_grasp:
        all_attempts.extend(a for a in lst if isinstance(a, dict))
    failed_max = max([sum(isinstance(a, dict) and a["outcome"] != "picked" for a in lst)
                      for lst in per_grasp] or [0])
    rows.append({
        "object": run,
        "exit": status,
        "first_grasp": "yes" if grasps > 0 else "no",
        "pick_attempts": len(attempts),
        "failed_picks_max": failed_max,
        "slips": len(s.get("slips_found", [])),
        "grasps": grasps,
        "views": len(s.get("views", [])),
        "coverage_pct": "%.1f" % (100 * s["coverage"]) if "coverage" in s else "",
        "accuracy_mm": "%.2f" % s["accuracy_mm"]["mean"] if "accuracy_mm" in s else "",
        "p95_mm": "%.2f" % s["accuracy_mm"]["p95"] if "accuracy_mm" in s else "",
        "detached_cm2": "%.1f" % (1e4 * s["detached_area_m2"]) if "detached_area_m2" in s else "",
        "seconds": "%.0f" % float(seconds or 0),
        "termination": s.get("termination", "(no summary)"),
    })
keys = ["object", "exit", "first_grasp", "pick_attempts", "failed_picks_max", "slips", "grasps", "views",
        "coverage_pct", "accuracy_mm",
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


def rate(sel):
    held = sum(a["outcome"] == "picked" for a in sel)
    return "%d of %d" % (held, len(sel))


with open(os.path.join(out, "results.md.tmp"), "a") as f:
    ranks = ", ".join("rank %d: %s" % (k, rate([a for a in all_attempts if a["rank"] == k]))
                      for k in range(3))
    f.write("\nPick-ups that held, over every attempt of every grasp (%s): %s, rank 3 and later: %s; "
            "enveloping %s, fingertips %s; the hold test said it holds %s (with its margin %s), "
            "said not %s, untested %s.\n"
            % (rate(all_attempts), ranks, rate([a for a in all_attempts if a["rank"] >= 3]),
               rate([a for a in all_attempts if a["kind"] == "enveloping"]),
               rate([a for a in all_attempts if a["kind"] == "fingertips"]),
               rate([a for a in all_attempts if a["hold_test"] is True]),
               rate([a for a in all_attempts if a.get("hold_margin") is True]),
               rate([a for a in all_attempts if a["hold_test"] is False]),
               rate([a for a in all_attempts if a["hold_test"] is None])))
os.replace(os.path.join(out, "results.md.tmp"), os.path.join(out, "results.md"))

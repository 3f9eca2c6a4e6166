#!/usr/bin/env python3
"""Tabulates experiments/regrasp_set.sh's reports: OUT/regrasp/*/report.json -> OUT/regrasp.md."""
import json
import pathlib
import sys

out = pathlib.Path(sys.argv[1])
rows, held, found, n = [], 0, 0, 0
for report in sorted(out.glob("regrasp/*/report.json")):
    r = json.loads(report.read_text())
    f = r.get("found") or {}
    n += 1
    held += bool(r["held"])
    found += bool(f.get("within_3mm_3deg"))
    rows.append("| %s | %d | %s | %s | %s | %s | %d of %d | %d | %s | %s | %s |" % (
        report.parent.name, r["rest_pose"],
        "%.1f" % (1000 * f["centre_error_m"]) if f else "-",
        "%.1f" % f["rotation_error_deg"] if f else "-",
        "%.2f" % (1000 * f["adds_m"]) if f else "-",
        "yes" if f.get("within_3mm_3deg") else "no",
        r["made_here"], r["working_grasps"], r["held_in_hold_test"],
        "%.3f / %.3f" % (r["weighed_kg"], r["asset_mass_kg"]) if r["weighed_kg"] >= 0 else "-",
        "held" if r["held"] else "NOT held (%s)" % (r["failure"] or "fell"),
        "%.1f" % (r["find_s"] + r["plan_s"] + r["pick_s"])))
text = ["| run | test pose | centre error mm | rotation error ° | ADD-S mm | found within 3 mm / 3° "
        "| set grasps made here | held in hold test | arm weighs kg / asset kg | first grasp | s |",
        "|---|---|---|---|---|---|---|---|---|---|---|"] + rows
text.append("")
text.append("%d runs: the first grasp from the asset held on %d (%.0f %%); found within 3 mm / 3° "
            "on %d (%.0f %%)." % (n, held, 100.0 * held / max(1, n), found, 100.0 * found / max(1, n)))
(out / "regrasp.md").write_text("\n".join(text) + "\n")
print("\n".join(text[-1:]))

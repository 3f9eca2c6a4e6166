#!/usr/bin/env python3
"""Creeps followed over a scan set (docs/test_set_physics.md): for each OUT of
experiments/scan_set.sh, the creeps in summary.json's tracking.creep_grasp_error_mm, how many
brought the grasp nearer where the simulator holds the object, and the error summed over them
before and after. Usage: /usr/bin/python3 experiments/creep_table.py OUT [OUT ...]"""
import glob
import json
import sys

for out in sys.argv[1:]:
    scans = with_creeps = creeps = nearer = 0
    before = after = 0.0
    for path in sorted(glob.glob(out + "/runs/*/summary.json")):
        errors = json.load(open(path)).get("tracking", {}).get("creep_grasp_error_mm", [])
        scans += 1
        with_creeps += bool(errors)
        creeps += len(errors)
        nearer += sum(e["after"] < e["before"] for e in errors)
        before += sum(e["before"] for e in errors)
        after += sum(e["after"] for e in errors)
    print("%s: %d scans, %d with creeps followed, %d creeps, %d brought the grasp nearer; "
          "its error summed over them %.1f -> %.1f mm" %
          (out, scans, with_creeps, creeps, nearer, before, after))

#!/usr/bin/env python3
"""Tabulates experiments/planner_sweep.sh: whole scans of every object with every planner and seed,
for each configuration of the sweep (default; "initial_views": 1). Writes DOCS/planner_eval.md,
planner_eval.csv, planner_curves.svg (coverage against trajectory time) and planner_gain.svg
(eq. 9's predicted gain of each chosen view against the gain the model realised).

    /usr/bin/python3 experiments/planner_table.py OUT DOCS
"""
import csv
import glob
import json
import math
import os
import statistics
import sys

PLANNERS = ["ig", "ig-no-hand", "ig-no-cost", "random", "area", "unobserved-voxels",
            "rear-side-entropy"]
COLOURS = {"ig": "#d62728", "ig-no-hand": "#ff9896", "ig-no-cost": "#8c564b", "random": "#7f7f7f",
           "area": "#1f77b4", "unobserved-voxels": "#2ca02c", "rear-side-entropy": "#9467bd"}


def load(out):
    """config -> list of runs (dicts)."""
    configs = {}
    for d in sorted(glob.glob(os.path.join(out, "*"))):
        if not os.path.isfile(os.path.join(d, "eval.json")):
            continue
        name = os.path.basename(d)
        runs = []
        for path in sorted(glob.glob(os.path.join(d, "runs", "*", "*", "seed*", "summary.json"))):
            s = json.load(open(path))
            views = s["views"]
            runs.append({
                "object": os.path.splitext(os.path.basename(s["object"].replace("builtin:", "")))[0],
                "planner": s["planner"], "seed": s["seed"], "coverage": s["coverage"],
                "accuracy_mm": s["accuracy_mm"]["mean"], "views": len(views),
                "grasps": len(s["grasps"]), "trajectory_s": s.get("trajectory_s", float("nan")),
                "termination": s["termination"],
                "curve": [(v["trajectory_s"], v["coverage"]) for v in views],
                "gains": gain_pairs(views),
            })
        configs[name] = runs
    return configs


def gain_pairs(views):
    """(predicted, realised, coverage gained) for each Alg. 1 view with a prediction."""
    out = []
    for i, v in enumerate(views):
        p = v.get("predicted_gain")
        if v["initial"] or p is None or i == 0 or views[i - 1].get("grasp") != v.get("grasp"):
            continue
        out.append((p, views[i - 1]["unresolved"] - v["unresolved"],
                    v["coverage"] - views[i - 1]["coverage"]))
    return out


def time_to(curve, level):
    for t, c in curve:
        if c >= level:
            return t
    return float("nan")


def ms(values, digits=1):
    v = [x for x in values if not math.isnan(x)]
    if not v:
        return "–"
    m = statistics.mean(v)
    sd = statistics.stdev(v) if len(v) > 1 else 0.0
    tail = "" if len(v) == len(values) else f" ({len(v)}/{len(values)})"
    return f"{m:.{digits}f} ± {sd:.{digits}f}{tail}"


def spearman(xs, ys):
    def ranks(v):
        order = sorted(range(len(v)), key=lambda i: v[i])
        r = [0.0] * len(v)
        for k, i in enumerate(order):
            r[i] = float(k)
        return r
    if len(xs) < 3:
        return float("nan")
    a, b = ranks(xs), ranks(ys)
    ma, mb = statistics.mean(a), statistics.mean(b)
    num = sum((x - ma) * (y - mb) for x, y in zip(a, b))
    den = math.sqrt(sum((x - ma) ** 2 for x in a) * sum((y - mb) ** 2 for y in b))
    return num / den if den else float("nan")


def table(name, runs, csv_rows):
    objects = sorted({r["object"] for r in runs})
    planners = [p for p in PLANNERS if any(r["planner"] == p for r in runs)]
    seeds = len({r["seed"] for r in runs})
    lines = [f"### {name} ({seeds} seeds)\n",
             "| object | planner | final coverage % | trajectory s to target | views | grasps | "
             "accuracy mm | trajectory s |", "|---|---|---|---|---|---|---|---|"]
    wins = {b: [0, 0] for b in ("random", "area")}
    short = []
    for o in objects:
        mine = [r for r in runs if r["object"] == o]
        # The target: the best final coverage of any planner (mean over seeds) less 0.5 point.
        best = max(statistics.mean(r["coverage"] for r in mine if r["planner"] == p)
                   for p in planners if any(r["planner"] == p for r in mine))
        target = best - 0.005
        times = {}
        for p in planners:
            rs = [r for r in mine if r["planner"] == p]
            if not rs:
                continue
            t = [time_to(r["curve"], target) for r in rs]
            times[p] = t
            lines.append(f"| {o} | {p} | {ms([100 * r['coverage'] for r in rs])} | {ms(t)} | "
                         f"{ms([r['views'] for r in rs])} | {ms([r['grasps'] for r in rs])} | "
                         f"{ms([r['accuracy_mm'] for r in rs], 2)} | "
                         f"{ms([r['trajectory_s'] for r in rs])} |")
            for r in rs:
                csv_rows.append([name, o, p, r["seed"], r["coverage"], time_to(r["curve"], target),
                                 r["views"], r["grasps"], r["accuracy_mm"], r["trajectory_s"],
                                 r["termination"]])
        # ig against each baseline: a run that never reaches the target takes infinite time.
        def mean_time(p):
            t = [x if not math.isnan(x) else math.inf for x in times.get(p, [])]
            return statistics.mean(t) if t else math.nan
        ig = mean_time("ig")
        for b in wins:
            if b not in times:
                continue
            tb = mean_time(b)
            if ig == tb:
                continue
            wins[b][1] += 1
            wins[b][0] += 1 if ig < tb else 0
        ig_cov = statistics.mean(r["coverage"] for r in mine if r["planner"] == "ig")
        for b in ("random", "area"):
            rs = [r for r in mine if r["planner"] == b]
            if rs and statistics.mean(r["coverage"] for r in rs) > ig_cov + 0.005:
                short.append(f"{o} (ig {100 * ig_cov:.1f} %, {b} "
                             f"{100 * statistics.mean(r['coverage'] for r in rs):.1f} %)")
    pairs = sum(w[1] for w in wins.values())
    won = sum(w[0] for w in wins.values())
    lines.append("")
    lines.append(f"ig first to the target on {won} of {pairs} (object, baseline) pairs where ig "
                 f"and the baseline differ (random {wins['random'][0]}/{wins['random'][1]}, "
                 f"area {wins['area'][0]}/{wins['area'][1]}); mean over seeds, a seed that never "
                 "reaches the target counting as never.")
    lines.append("Objects where ig ends more than 0.5 point below random or area: "
                 + ("; ".join(short) if short else "none") + ".\n")
    return lines


def curves_svg(configs, path):
    names = list(configs)
    objects = sorted({r["object"] for runs in configs.values() for r in runs})
    cw, ch, pad = 230, 200, 40
    W = pad + len(objects) * cw + 150
    H = len(names) * (ch + pad) + pad
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" '
           'font-family="sans-serif" font-size="11">', f'<rect width="{W}" height="{H}" fill="white"/>']
    tmax = 20.0  # s: where the planners differ (every mean curve is flat long before)
    for gi, name in enumerate(names):
        y0 = pad + gi * (ch + pad)
        for oi, o in enumerate(objects):
            x0 = pad + oi * cw
            w, h = cw - 30, ch - 30
            out.append(f'<rect x="{x0}" y="{y0}" width="{w}" height="{h}" fill="none" stroke="#999"/>')
            out.append(f'<text x="{x0}" y="{y0 - 4}">{name}: {o}</text>')
            for lvl in (0.5, 0.75, 1.0):
                yy = y0 + h - (lvl - 0.5) / 0.5 * h
                out.append(f'<text x="{x0 - 26}" y="{yy + 4}">{int(lvl * 100)}%</text>')
            out.append(f'<text x="{x0 + w - 30}" y="{y0 + h + 14}">{tmax:.0f} s</text>')
            out.append(f'<text x="{x0}" y="{y0 + h + 14}">0</text>')
            for p in PLANNERS:
                rs = [r for r in configs[name] if r["object"] == o and r["planner"] == p and r["curve"]]
                if not rs:
                    continue
                grid = [tmax * k / 60 for k in range(61)]
                pts = []
                for t in grid:
                    cs = []
                    for r in rs:
                        c = 0.0
                        for tt, cc in r["curve"]:
                            if tt <= t:
                                c = cc
                        cs.append(c)
                    cov = statistics.mean(cs)
                    x = x0 + t / tmax * w
                    y = y0 + h - max(0.0, cov - 0.5) / 0.5 * h
                    pts.append(f"{x:.1f},{y:.1f}")
                width = 2.2 if p == "ig" else 1.2
                out.append(f'<polyline points="{" ".join(pts)}" fill="none" stroke="{COLOURS[p]}" '
                           f'stroke-width="{width}"/>')
    lx = pad + len(objects) * cw
    for k, p in enumerate(PLANNERS):
        out.append(f'<line x1="{lx}" y1="{pad + 14 * k}" x2="{lx + 20}" y2="{pad + 14 * k}" '
                   f'stroke="{COLOURS[p]}" stroke-width="2"/>')
        out.append(f'<text x="{lx + 24}" y="{pad + 14 * k + 4}">{p}</text>')
    out.append(f'<text x="{pad}" y="{H - 8}">coverage (mean over seeds) against the robot\'s '
               'trajectory time, s</text>')
    out.append("</svg>")
    open(path, "w").write("\n".join(out) + "\n")


def gain_svg(pairs, path):
    W, H, pad = 560, 360, 50
    PW = W - 2 * pad - 130  # plot width; the legend to its right
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" '
           'font-family="sans-serif" font-size="11">', f'<rect width="{W}" height="{H}" fill="white"/>']
    lo, hi = -4.0, 0.0  # log10 nats·m²
    def xy(p, r):
        x = pad + (math.log10(max(p, 1e-4)) - lo) / (hi - lo) * PW
        y = H - pad - (math.log10(max(r, 1e-4)) - lo) / (hi - lo) * (H - 2 * pad)
        return x, y
    out.append(f'<rect x="{pad}" y="{pad}" width="{PW}" height="{H - 2 * pad}" '
               'fill="none" stroke="#999"/>')
    a, b = xy(1e-4, 1e-4), xy(1, 1)
    out.append(f'<line x1="{a[0]}" y1="{a[1]}" x2="{b[0]}" y2="{b[1]}" stroke="#bbb"/>')
    for k in range(int(lo), int(hi) + 1):
        x, _ = xy(10 ** k, 1e-4)
        _, y = xy(1e-4, 10 ** k)
        out.append(f'<text x="{x - 10}" y="{H - pad + 14}">1e{k}</text>')
        out.append(f'<text x="{pad - 34}" y="{y + 4}">1e{k}</text>')
    lx = pad + PW + 20
    for k, planner in enumerate(PLANNERS):
        out.append(f'<circle cx="{lx}" cy="{pad + 10 + 13 * k}" r="3" fill="{COLOURS[planner]}"/>')
        out.append(f'<text x="{lx + 6}" y="{pad + 14 + 13 * k}">{planner}</text>')
    for planner, p, r in pairs:
        x, y = xy(p, r)
        out.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="2" fill="{COLOURS.get(planner, "#000")}" '
                   'fill-opacity="0.6"/>')
    out.append(f'<text x="{pad}" y="{H - 12}">predicted eq. 9 gain of the chosen view, nats·m²</text>')
    out.append(f'<text x="{pad}" y="{pad - 24}">realised: drop in unresolved information, nats·m²</text>')
    out.append(f'<text x="{pad}" y="{pad - 10}">(≤ 1e-4 drawn at 1e-4; grey line: realised = predicted)</text>')
    out.append("</svg>")
    open(path, "w").write("\n".join(out) + "\n")


def main(out, docs):
    configs = load(out)
    csv_rows = []
    lines = ["# View planners in whole scans\n",
             "Generated by `experiments/planner_sweep.sh` (table and plots by "
             "`experiments/planner_table.py`). Whole multi-grasp scans from the table top with the kinematic simulator (physics off) at default "
             "settings (every frame fused, the volume's thin-wall defaults) (`default`) and with `\"initial_views\": 1` (`initial1`); every planner stops on the same rule (the relative rule: no reachable "
             "view's eq. 9 gain reaches 0.036 nats per m² of the model's surface) and re-grasps on "
             "the same eq. 9 ranking. \"Target\": the best final coverage of any planner on that "
             "object (mean over seeds) less 0.5 point; trajectory time is the robot's motion, "
             "table-top stage and pick-ups excluded. Mean ± sd over seeds; \"(k/n)\": k of n "
             "seeds reached it.\n"]
    for name, runs in configs.items():
        lines += table(name, runs, csv_rows)
    # Predicted against realised gain, over every configuration and planner.
    pairs = [(r["planner"], p, q) for runs in configs.values() for r in runs for p, q, _ in r["gains"]]
    lines.append("## Predicted and realised gain\n")
    lines.append("For each view a planner chose (Alg. 1 views; the view before it of the same "
                 "grasp), eq. 9's predicted gain against the realised gain: the drop in the "
                 "model's unresolved information ∫ max(0, ½ ln(σ²/σ_ref²)) dA, σ_ref the sensor's "
                 "σ at the view range (`unresolved` in summary.json; the same units, nats·m²).\n")
    lines.append("| planner | views | median realised / predicted | share realised < ½ predicted "
                 "| Spearman ρ |")
    lines.append("|---|---|---|---|---|")
    for p in PLANNERS + ["all"]:
        sel = [(a, b) for pl, a, b in pairs if pl == p or p == "all"]
        if not sel:
            continue
        ratios = [b / a for a, b in sel if a > 0]
        lines.append(f"| {p} | {len(sel)} | {statistics.median(ratios):.2f} | "
                     f"{sum(1 for r in ratios if r < 0.5) / len(ratios):.2f} | "
                     f"{spearman([a for a, _ in sel], [b for _, b in sel]):.2f} |")
    lines.append("\n![predicted against realised gain](planner_gain.svg)\n")
    lines.append("![coverage against trajectory time](planner_curves.svg)\n")
    open(os.path.join(docs, "planner_eval.md"), "w").write("\n".join(lines) + "\n")
    with open(os.path.join(docs, "planner_eval.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["config", "object", "planner", "seed", "coverage", "trajectory_s_to_target",
                    "views", "grasps", "accuracy_mean_mm", "trajectory_s", "termination"])
        w.writerows(csv_rows)
    curves_svg(configs, os.path.join(docs, "planner_curves.svg"))
    gain_svg(pairs, os.path.join(docs, "planner_gain.svg"))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])

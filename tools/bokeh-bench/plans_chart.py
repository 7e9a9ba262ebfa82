#!/usr/bin/python3
"""Chart bokeh-bench --task plans: per shot, every measured plan's PSNR against the
reference over its time (the default, the budget's steps, as x; planner=predicted's choice
ringed), and predicted against measured PSNR.

    plans_chart.py docs/bench/plans.csv docs/bench
writes plans.png into the folder and prints the figures the docs quote: per shot, the
default's and planner=predicted's measured PSNR and time, the cheapest measured plan that meets the budget, and
the prediction's error (predicted - measured, dB) over the plans below 90 dB."""
import csv
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

src, out = sys.argv[1], sys.argv[2]
budget = float(sys.argv[3]) if len(sys.argv) > 3 else 40.0
shots = defaultdict(list)
for r in csv.DictReader(open(src)):
    shots[r["scene"]].append(r)

fig, axes = plt.subplots(2, len(shots), figsize=(4.2 * len(shots), 8), squeeze=False)
for col, (name, rows) in enumerate(shots.items()):
    ax, bx = axes[0][col], axes[1][col]
    def db(r, key):
        return min(float(r[key]), 100.0)
    steps = [r for r in rows if r["chosen"] == "steps"]
    for r in steps:
        ax.scatter(float(r["median_ms"]), db(r, "psnr_db"), s=90, marker="x", color="black")
        print(f"{name}: default (steps, {r['layers']} layers): {float(r['psnr_db']):.1f} dB in "
              f"{float(r['median_ms']):.0f} ms")
    rows = [r for r in rows if r["chosen"] != "steps"]
    for r in rows:
        colour = "tab:blue" if r["ladder_ratio"] == "1" else "tab:orange"
        ax.scatter(float(r["median_ms"]), db(r, "psnr_db"), s=14, color=colour, alpha=0.7)
        bx.scatter(db(r, "psnr_db"), db(r, "predicted_psnr_db"), s=14, color=colour, alpha=0.7)
        if r["chosen"] == "predicted":
            ax.scatter(float(r["median_ms"]), db(r, "psnr_db"), s=120, facecolors="none", edgecolors="black")
            bx.scatter(db(r, "psnr_db"), db(r, "predicted_psnr_db"), s=120, facecolors="none", edgecolors="black")
    ax.axhline(budget, color="grey", lw=0.8, ls="--")
    ax.set_title(name)
    ax.set_xlabel("median ms (in-process, 2 threads)")
    ax.set_ylabel("PSNR against the reference (dB, 100 = exact)")
    bx.plot([20, 100], [20, 100], color="grey", lw=0.8)
    bx.set_xlabel("measured PSNR (dB)")
    bx.set_ylabel("predicted PSNR (dB)")
    meets = [r for r in rows if float(r["psnr_db"]) >= budget]
    cheapest = min(meets, key=lambda r: float(r["median_ms"])) if meets else None
    chosen = [r for r in rows if r["chosen"] == "predicted"]
    errs = [float(r["predicted_psnr_db"]) - float(r["psnr_db"]) for r in rows if float(r["psnr_db"]) < 90]
    for r in chosen:
        print(f"{name}: planner=predicted: ratio {r['ladder_ratio']} q {r['min_reduced_coc_px']}: "
              f"{float(r['psnr_db']):.1f} dB in {float(r['median_ms']):.0f} ms")
    if cheapest:
        print(f"{name}: cheapest measured plan meeting {budget:g} dB: ratio {cheapest['ladder_ratio']} "
              f"q {cheapest['min_reduced_coc_px']}: {float(cheapest['psnr_db']):.1f} dB in "
              f"{float(cheapest['median_ms']):.0f} ms")
    if errs:
        print(f"{name}: predicted - measured over {len(errs)} plans: {min(errs):+.1f} .. {max(errs):+.1f} dB")
fig.suptitle("Flat plans: blue the exact rungs, orange geometric ladders; x the default (steps), "
             "ringed planner=predicted's choice")
fig.tight_layout()
fig.savefig(f"{out}/plans.png", dpi=80)

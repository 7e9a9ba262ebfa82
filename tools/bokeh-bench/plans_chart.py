#!/usr/bin/python3
"""Chart bokeh-bench --task plans: per shot, every measured plan's PSNR against the
reference over its time (the default, the budget's steps, as x; planner=predicted's choice
ringed), predicted against measured PSNR, and (on the built-in scenes) PSNR against the
thin-lens truth over time, with the floor two truths agree to.

    plans_chart.py docs/bench/plans.csv docs/bench
writes plans.png into the folder and prints the figures the docs quote: per shot, the
default's and planner=predicted's measured PSNR and time, the cheapest measured plan that meets the budget, and
the prediction's error (predicted - measured, dB) over the plans below 90 dB; against the
truth, the floor, the default's distance from it, and the cheapest plan within 1 dB of the
best any plan reaches."""
import csv
import math
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

src, out = sys.argv[1], sys.argv[2]
budget = float(sys.argv[3]) if len(sys.argv) > 3 else 40.0
shots = defaultdict(list)
floors = {}
for r in csv.DictReader(open(src)):
    if r["chosen"] == "floor":
        floors[r["scene"]] = float(r["truth_psnr_db"])
    else:
        shots[r["scene"]].append(r)


def noiseless_db(raw_db, floor_db):
    """PSNR against the noiseless truth: the truth's rays add their noise's variance (half
    the two truths' mean square difference) to a plan's mean square error against it, so
    it is taken away (None when the plan is within that noise)."""
    mse = 10.0 ** (-raw_db / 10.0) - 0.5 * 10.0 ** (-floor_db / 10.0)
    return 10.0 * math.log10(1.0 / mse) if mse > 0.0 else None


def truth_panel(tx, name, rows):
    """PSNR against the truth over time, the floor dashed; prints the figures."""
    have = [r for r in rows if r.get("truth_psnr_db")]
    if not have:
        tx.text(0.5, 0.5, "no truth (a file, not a built-in scene)", ha="center", va="center",
                transform=tx.transAxes, fontsize=9)
        tx.set_axis_off()
        return
    for r in have:
        colour = ("black" if r["chosen"] == "steps" else
                  "tab:blue" if r["ladder_ratio"] == "1" else "tab:orange")
        marker = "x" if r["chosen"] == "steps" else "o"
        tx.scatter(float(r["median_ms"]), float(r["truth_psnr_db"]), s=90 if marker == "x" else 14,
                   marker=marker, color=colour, alpha=1.0 if marker == "x" else 0.7)
        if r["chosen"] == "predicted":
            tx.scatter(float(r["median_ms"]), float(r["truth_psnr_db"]), s=120, facecolors="none",
                       edgecolors="black")
    floor = floors.get(name)
    if floor is not None:
        tx.axhline(floor, color="grey", lw=0.8, ls="--")
    tx.set_xlabel("median ms (in-process, 2 threads)")
    tx.set_ylabel("PSNR against the thin-lens truth (dB)")
    best = max(float(r["truth_psnr_db"]) for r in have)
    near = [r for r in have if float(r["truth_psnr_db"]) >= best - 1.0]
    cheapest = min(near, key=lambda r: float(r["median_ms"]))
    steps = [r for r in have if r["chosen"] == "steps"]
    def clean(r):
        v = noiseless_db(float(r["truth_psnr_db"]), floor)
        return "within the rays' noise" if v is None else f"{v:.1f} dB"
    print(f"{name}: against the truth: two truths agree to {floor:.1f} dB; best plan {best:.1f} dB "
          f"(noiseless {clean(max(have, key=lambda r: float(r['truth_psnr_db'])))}); "
          f"the cheapest within 1 dB of it: ratio {cheapest['ladder_ratio']} q {cheapest['min_reduced_coc_px']} "
          f"({cheapest['layers']} layers), {float(cheapest['truth_psnr_db']):.1f} dB against the truth "
          f"(noiseless {clean(cheapest)}), {float(cheapest['psnr_db']):.1f} dB against the reference, "
          f"{float(cheapest['median_ms']):.0f} ms")
    for r in steps:
        print(f"{name}: against the truth: default {float(r['truth_psnr_db']):.1f} dB (noiseless {clean(r)}; "
              f"{float(r['psnr_db']):.1f} against the reference) in {float(r['median_ms']):.0f} ms")


fig, axes = plt.subplots(3, len(shots), figsize=(4.2 * len(shots), 12), squeeze=False)
for col, (name, rows) in enumerate(shots.items()):
    ax, bx = axes[0][col], axes[1][col]
    truth_panel(axes[2][col], name, rows)
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
             "ringed planner=predicted's choice; bottom row against the thin-lens truth (dashed: two truths)")
fig.tight_layout()
fig.savefig(f"{out}/plans.png", dpi=80)

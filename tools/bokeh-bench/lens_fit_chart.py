#!/usr/bin/python3
"""Chart bokeh-bench --task lensfit's round trips: each fitted parameter against its true
value (one point a random lens; colour: the peak SNR), the blade counts as a table.

    lens_fit_chart.py docs/bench/lens_fit.csv docs/bench
writes lens_fit.png into the folder and prints the figures the docs quote."""
import csv
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

src, out = sys.argv[1], sys.argv[2]
rows = [r for r in csv.DictReader(open(src)) if r["task"] == "lensfit"]
trials = defaultdict(dict)
for r in rows:
    trials[int(r["trial"])][r["parameter"]] = r

params = [("coc", "CoC (px)"), ("rotation", "rotation (deg, mod one blade)"), ("curvature", "curvature"),
          ("monochromatic", "monochromatic (spherical aberration)"), ("chromatic", "chromatic (axial colour)"),
          ("onion", "onion-ring contrast")]
colours = {"20": "tab:red", "50": "tab:orange", "100": "tab:green"}
fig, axes = plt.subplots(2, 3, figsize=(13, 8.5))
for ax, (name, label) in zip(axes.flat, params):
    lo, hi = 1e9, -1e9
    for t, p in sorted(trials.items()):
        r = p[name]
        x, y = float(r["true_value"]), float(r["fitted"])
        if name == "rotation":
            blades_true, blades_fit = int(float(p["blades"]["true_value"])), int(float(p["blades"]["fitted"]))
            if blades_true == 0 or blades_true != blades_fit:
                continue
            period = 360.0 / blades_true
            d = (y - x + 0.5 * period) % period - 0.5 * period
            y = x + d
        if name in ("curvature",) and int(float(p["blades"]["true_value"])) == 0:
            continue
        ax.scatter([x], [y], s=18, color=colours.get(r["peak_snr"].split(".")[0], "k"))
        lo, hi = min(lo, x, y), max(hi, x, y)
    ax.plot([lo, hi], [lo, hi], color="0.6", lw=0.8)
    ax.set_title(label, fontsize=10)
    ax.set_xlabel("true")
    ax.set_ylabel("fitted")
for snr, c in colours.items():
    axes.flat[0].scatter([], [], color=c, label=f"peak SNR {snr}")
axes.flat[0].legend(fontsize=8)

# Blades: how many right.
right = sum(1 for p in trials.values() if p["blades"]["true_value"] == p["blades"]["fitted"]
            or float(p["blades"]["true_value"]) == float(p["blades"]["fitted"]))
times = sorted(float(p["coc"]["seconds"]) for p in trials.values())
psnr = sorted(float(p["coc"]["psf_psnr_db"]) for p in trials.values())
fig.suptitle(f"Lens fit round trips: {len(trials)} random lenses, 127 px crops; blade count right in "
             f"{right}/{len(trials)}; median fit {times[len(times) // 2]:.2f} s; refit PSF against the "
             f"truth's: median {psnr[len(psnr) // 2]:.1f} dB", fontsize=10)
fig.tight_layout(rect=(0, 0, 1, 0.96))
fig.savefig(f"{out}/lens_fit.png", dpi=90)
good = sum(1 for v in psnr if v >= 35.0)
print(f"{len(trials)} lenses: blades right {right}; median time {times[len(times) // 2]:.2f} s; "
      f"PSF PSNR median {psnr[len(psnr) // 2]:.1f} dB, >= 35 dB in {good}")
for r in csv.DictReader(open(src)):
    if r["task"] == "lensfit-time":
        print(f"speed: {r['crops']} crop(s) of {r['crop_px']} px: {float(r['seconds']):.2f} s ({r['trial']})")

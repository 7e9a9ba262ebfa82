#!/usr/bin/env python3
"""Time-vs-error chart of the diffraction task (bokeh-bench --task diffraction).

    python3 tools/bokeh-bench/diffraction_chart.py CSV OUTDIR

Writes OUTDIR/diffraction.png and OUTDIR/diffraction.svg with two panels:

  left   error vs time: median ms (log x) against the area-weighted RMS difference from the
         exact PSF's ring profile, relative to the flat disc's level (log y), one marker per
         method, each point labelled with its CoC in pixels; the exact method, the reference
         itself, sits on a band labelled "exact".
  right  time vs CoC per method (log-log).

Needs the standard library and matplotlib (Debian: python3-matplotlib).
"""

import csv
import os
import sys

REQUIRED = ("method", "size_px", "median_ms", "rms_rel_flat")


def main():
    if len(sys.argv) != 3:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        sys.exit(2)
    path, outdir = sys.argv[1], sys.argv[2]
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        print(f"diffraction_chart.py: {path}: {e.strerror or e}", file=sys.stderr)
        sys.exit(1)
    if not rows or any(c not in rows[0] for c in REQUIRED):
        print(f"diffraction_chart.py: {path}: needs the columns {', '.join(REQUIRED)}", file=sys.stderr)
        sys.exit(1)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = []
    for r in rows:
        if r["method"] not in methods:
            methods.append(r["method"])
    markers = "o^sDvP*X"
    errors = [float(r["rms_rel_flat"]) for r in rows if float(r["rms_rel_flat"]) > 0]
    floor = min(errors) / 4 if errors else 1e-4
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 5))
    for i, m in enumerate(methods):
        pts = [r for r in rows if r["method"] == m]
        t = [float(r["median_ms"]) for r in pts]
        e = [max(float(r["rms_rel_flat"]), floor) for r in pts]
        s = [float(r["size_px"]) for r in pts]
        ax.plot(t, e, markers[i % len(markers)] + "-", label=m, alpha=0.85)
        for x, y, c in zip(t, e, s):
            ax.annotate(f"{c:g}", (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
        bx.plot(s, [max(v, 1e-4) for v in t], markers[i % len(markers)] + "-", label=m)
    ax.axhline(floor, color="grey", lw=0.5, ls=":")
    ax.text(1e-3, floor * 1.1, "exact (the reference)", fontsize=8, color="grey")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("median time per radial profile, ms (one thread)")
    ax.set_ylabel("RMS difference from the exact PSF / flat level")
    ax.set_title("Bokeh rim fringes: error vs time (labels: CoC px)")
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=8)
    bx.set_xscale("log")
    bx.set_yscale("log")
    bx.set_xlabel("CoC, px (f/2, 550 nm, 0.006 mm pixel)")
    bx.set_ylabel("median ms")
    bx.set_title("time vs CoC")
    bx.grid(True, which="both", lw=0.3)
    bx.legend(fontsize=8)
    fig.tight_layout()
    os.makedirs(outdir, exist_ok=True)
    for ext in ("png", "svg"):
        fig.savefig(os.path.join(outdir, f"diffraction.{ext}"), dpi=110)
    print(f"wrote {os.path.join(outdir, 'diffraction.png')} and .svg")


if __name__ == "__main__":
    main()

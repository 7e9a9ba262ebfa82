#!/usr/bin/env python3
"""Artifact bar charts from the table that `bokeh-bench --task resample` writes.

Reads <stem>_artifacts.csv (one row per enlargement method and factor: Mach bands,
ringing, shimmer, detail, as bokeh::enlargement_artifacts measures them) and writes
OUTDIR/<stem>.png and OUTDIR/<stem>.svg: four panels, one per metric, with the bars
grouped by reduction factor (1/2 .. 1/16), one bar per method in every group; OIIO's
IBA::resize (the peer) hatched. Lower is better in every panel. Mach bands are drawn on a
log scale (nearest scores ~200, the C2 filters below 1).

With --timings CSV (the task's main CSV: tasks "enlarge <scene>" and "enlarge <scene>
pipeline")
it also prints, per factor, a Markdown table for the docs: enlargement and pipeline
times, PSNR against the full-resolution effect per scene, and the artifact figures.

    python3 tools/bokeh-bench/artifact_chart.py ARTIFACTS_CSV OUTDIR [--timings CSV]

Columns are read by header name; columns it does not know are ignored. Needs only the
standard library and matplotlib (Debian: python3-matplotlib).
"""

import argparse
import math
import os

import chart  # its CSV reading and error messages, under this program's name

PROG = "artifact_chart.py"
chart.PROG = PROG
fail = chart.fail
REQUIRED = ("method", "peer", "factor", "mach", "overshoot_pct", "shimmer", "detail_pct")
TIMING_REQUIRED = ("task", "method", "peer", "size_px", "median_ms", "psnr_db_tonemapped")
PANELS = (  # column, title, log scale
    ("mach", "Mach bands (slope jumps, % of slope RMS)", True),
    ("overshoot_pct", "ringing: overshoot on a step, % of the step", False),
    ("shimmer", "shimmer (change under 1/4-texel moves, % RMS)", False),
    ("detail_pct", "detail error on a fine pattern, % of its contrast", False),
)


def read_csv(path, required, numbers):
    """Rows as dicts, the `numbers` columns parsed; exits with one line on bad input."""
    rows = []
    for line, out in chart.csv_rows(path, required):
        for col in numbers:
            if col not in out:
                continue
            try:
                out[col] = float(out[col]) if out[col] else None
            except ValueError:
                fail(path, f"line {line}: {col} is not a number: {out[col]!r}")
        rows.append(out)
    if not rows:
        fail(path, "no data rows")
    return rows


def label_of(method, peer):
    return f"{method} (peer)" if peer else method


def factor_text(f):
    return f"1/{f:g}"


def draw(plt, rows, base):
    factors = sorted({r["factor"] for r in rows})
    methods = []   # (method, peer) in order of appearance, ours first
    for r in rows:
        key = (r["method"], r["peer"])
        if key not in methods:
            methods.append(key)
    methods.sort(key=lambda k: bool(k[1]))   # stable: keeps CSV order within
    value = {(r["method"], r["peer"], r["factor"]): r for r in rows}

    cmap = plt.get_cmap("tab20")
    ours = [m for m in methods if not m[1]]
    colour = {m: cmap(i % 20) for i, m in enumerate(ours)}
    # A peer takes the colour of our method with the same filter, hatched.
    peer_filter = {"triangle": "bilinear"}
    for m in methods:
        if m[1]:
            name = m[0].split()[-1]
            same = next((o for o in ours if o[0] == peer_filter.get(name, name)), None)
            colour[m] = colour[same] if same else "0.5"

    fig, axes = plt.subplots(len(PANELS), 1, figsize=(13, 3.1 * len(PANELS)))
    n = len(methods)
    width = 0.84 / n
    handles = {}
    for ax, (col, title, log) in zip(axes, PANELS):
        for i, m in enumerate(methods):
            xs, ys = [], []
            for j, f in enumerate(factors):
                r = value.get((m[0], m[1], f))
                if r is None or r.get(col) is None:
                    continue
                xs.append(j - 0.42 + width * (i + 0.5))
                ys.append(r[col])
            if log:   # a log axis cannot show 0: such a bar is drawn at the axis floor
                ys = [max(y, 1e-2) for y in ys]
            style = dict(color="white", edgecolor=colour[m], hatch="////", linewidth=0.8) \
                if m[1] else dict(color=colour[m], edgecolor="none")
            h = ax.bar(xs, ys, width=width * 0.92, label=label_of(*m), zorder=3, **style)
            handles.setdefault(m, h)
        ax.set_xticks(range(len(factors)))
        ax.set_xticklabels([f"reduced {factor_text(f)}, enlarged {f:g}x" for f in factors])
        ax.set_xlim(-0.5, len(factors) - 0.5)
        if log:
            ax.set_yscale("log")
            ax.yaxis.set_major_formatter(plt.FuncFormatter(lambda v, _p: f"{v:g}"))
        ax.set_title(title + " — lower is better", fontsize=10, loc="left")
        ax.grid(True, axis="y", which="major", color="0.9", linewidth=0.6, zorder=0)
        for j in range(1, len(factors)):
            ax.axvline(j - 0.5, color="0.75", linewidth=0.8)
    fig.suptitle("Enlargement artifacts per method, grouped by reduction factor "
                 "(bokeh::enlargement_artifacts)", fontsize=13)
    ncol = 6
    nrows = math.ceil(len(handles) / ncol)
    fig.legend(handles=[handles[m] for m in methods], loc="lower center", ncol=ncol, fontsize=9,
               frameon=False)
    height = 3.1 * len(PANELS) + 0.3 * nrows + 0.6
    fig.set_size_inches(13, height)
    fig.subplots_adjust(left=0.06, right=0.99, top=1 - 0.75 / height, hspace=0.42,
                        bottom=(0.45 + 0.3 * nrows) / height)
    fig.savefig(base + ".png", dpi=100, metadata={"Software": None})
    fig.savefig(base + ".svg", metadata={"Date": None})
    plt.close(fig)


def ms_text(ms):
    return "" if ms is None else f"{ms:.0f}" if ms >= 100 else f"{ms:.1f}"


def markdown(rows, timing_rows):
    """Per factor: method | enlarge ms | per scene pipeline ms and PSNR | artifacts."""
    scenes = []
    for r in timing_rows:
        kind, _, scene = r["task"].partition(" ")
        if kind == "enlarge" and scene and " " not in scene and scene not in scenes:
            scenes.append(scene)
    t = {(r["task"], r["method"], r["peer"], r["size_px"]): r for r in timing_rows}
    out = []
    for f in sorted({r["factor"] for r in rows}):
        head = ["method", "enlarge ms"]
        for s in scenes:
            head += [f"{s}: pipeline ms", f"{s}: PSNR dB"]
        head += ["Mach", "overshoot %", "shimmer", "detail %"]
        out += [f"#### reduced {factor_text(f)}, enlarged {f:g}x", "",
                "| " + " | ".join(head) + " |",
                "|---|" + "---:|" * (len(head) - 1)]
        for r in rows:
            if r["factor"] != f:
                continue
            key = (r["method"], r["peer"])
            first = t.get((f"enlarge {scenes[0]}", *key, f)) if scenes else None
            cells = [label_of(*key).replace("|", "\\|"), ms_text(first and first["median_ms"])]
            for s in scenes:
                p = t.get((f"enlarge {s} pipeline", *key, f))
                e = t.get((f"enlarge {s}", *key, f))
                cells += [ms_text(p and p["median_ms"]),
                          "" if not e else f"{e['psnr_db_tonemapped']:.1f}"]
            cells += [f"{r['mach']:.2f}", f"{r['overshoot_pct']:.1f}", f"{r['shimmer']:.1f}",
                      f"{r['detail_pct']:.1f}"]
            out.append("| " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("csv", help="<stem>_artifacts.csv written by bokeh-bench --task resample")
    ap.add_argument("outdir", help="directory for <stem>.png and <stem>.svg")
    ap.add_argument("--timings", help="the task's main CSV, for the Markdown tables")
    args = ap.parse_args()

    rows = read_csv(args.csv, REQUIRED,
                    ("factor", "mach", "overshoot_pct", "undershoot_pct", "most_negative",
                     "negative_values", "shimmer", "detail_pct"))
    for r in rows:
        if r["factor"] is None or r["factor"] <= 0:
            fail(args.csv, f"method {r['method']!r}: factor must be a positive number")
    timing_rows = None
    if args.timings:
        timing_rows = read_csv(args.timings, TIMING_REQUIRED,
                               ("size_px", "median_ms", "psnr_db_tonemapped"))

    plt = chart.pyplot()

    if os.path.exists(args.outdir) and not os.path.isdir(args.outdir):
        fail(args.outdir, "not a directory")
    try:
        os.makedirs(args.outdir, exist_ok=True)
        base = os.path.join(args.outdir, os.path.splitext(os.path.basename(args.csv))[0])
        draw(plt, rows, base)
    except OSError as e:
        fail(args.outdir, e.strerror.lower() if e.strerror else str(e))
    if timing_rows is not None:
        print(markdown(rows, timing_rows))


if __name__ == "__main__":
    main()

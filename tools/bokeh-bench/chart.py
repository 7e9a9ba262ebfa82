#!/usr/bin/env python3
"""Speed/accuracy charts from the CSV that bokeh-bench writes.

For each task in the CSV (box, disk, gaussian, ...) this writes OUTDIR/<task>.png and
OUTDIR/<task>.svg with two panels:

  left   error vs time: median ms (log x) against PSNR after tone mapping (higher is
         better), one colour/marker per method, peers hollow, every point labelled with its
         kernel size; for each kernel size, the Pareto front (points no other point of
         that size beats on both speed and accuracy) is ringed and joined by a dashed
         line; a dotted line marks the 40 dB budget. Bit-exact results (PSNR written as
         999) sit on a band labelled "exact"; when the PSNRs fall into two groups far
         apart (approximations, float round-off), the upper one is drawn compressed.
  right  time vs kernel size per method (log-log), so a flat line means a cost that does
         not grow with the kernel.

It also prints, per task, a Markdown table of the Pareto-front points for the docs.

Tasks with rows "METHOD vs truth", "METHOD vs truth (mask)" and "METHOD vs truth (held)"
(bokeh-bench --task deep) go into one chart instead, OUTDIR/deep_truth.png and .svg: a
panel per frame, each method's PSNR against the thin-lens truth over the frame (filled),
the disocclusion mask (hollow) and the held pixels (a bar) against its median time, and
the truth at its own time and
noise floor (the "truth N spp" row; a dotted line); with a Markdown table per frame.
Methods are compared at equal kernel size: a small kernel is no substitute for a large
one, so a front across sizes would mostly list the smallest size of the fastest method.

    python3 tools/bokeh-bench/chart.py CSV OUTDIR [--title-suffix TEXT] [--size-label TEXT]

--size-label names what size_px holds where it is not a kernel size (the resample task
writes the reduction factor there: --size-label "reduction factor").

Columns are read by header name; columns it does not know are ignored. Needs only the
standard library and matplotlib (Debian: python3-matplotlib).
"""

import argparse
import csv
import math
import os
import re
import sys

REQUIRED = ("task", "method", "peer", "size_px", "median_ms", "psnr_db_tonemapped")
EXACT_PSNR = 999.0   # what bokeh-bench writes when the result is identical to the reference
BUDGET_DB = 40.0
SIZE_LABEL = "kernel size, px"   # what size_px holds, for the labels
PROG = "chart.py"


def fail(path, reason):
    print(f"{PROG}: {path}: {reason}", file=sys.stderr)
    sys.exit(1)


def note(msg):
    print(f"{PROG}: {msg}", file=sys.stderr)


def csv_rows(path, required):
    """(line number, row with its values stripped) for each row of a CSV whose header has
    the `required` columns; exits with a one-line message on a file that cannot be read, a
    missing header or column, or a row with more fields than the header has columns."""
    try:
        f = open(path, newline="", encoding="utf-8")
    except OSError as e:
        fail(path, e.strerror.lower() if e.strerror else str(e))
    with f:
        reader = csv.DictReader(f)
        header = [h.strip() for h in (reader.fieldnames or [])]
        if not header:
            fail(path, "empty file (no header line)")
        reader.fieldnames = header
        missing = [c for c in required if c not in header]
        if missing:
            fail(path, "missing column(s) " + ", ".join(missing))
        for row in reader:
            if None in row:   # more fields than the header: a comma inside an unquoted name
                fail(path, f"line {reader.line_num}: more fields than the header has columns")
            yield reader.line_num, {k: (v or "").strip() for k, v in row.items()}


def pyplot():
    """matplotlib.pyplot drawing to files (Agg) with stable SVG ids; exits with one line
    when matplotlib is missing."""
    try:
        import matplotlib
    except ImportError:
        note(f"matplotlib is not available to {sys.executable} "
             "(Debian: apt install python3-matplotlib, then run with /usr/bin/python3)")
        sys.exit(1)
    matplotlib.use("Agg")
    matplotlib.rcParams["svg.hashsalt"] = "openbokeh"
    import matplotlib.pyplot as plt
    return plt


def read_rows(path):
    """(task names in order of appearance, rows as dicts with numbers parsed); exits with
    a one-line message on bad input. A task whose rows were all skipped is still named."""
    rows, tasks = [], {}
    for line, row in csv_rows(path, REQUIRED):
        task = row["task"]
        if not task:
            note(f"{path}: line {line}: no task name, row skipped")
            continue
        tasks[task] = None
        values = {}
        for col in ("size_px", "median_ms", "psnr_db_tonemapped"):
            text = row[col]
            if not text:
                values = None   # a case that did not run; not an error in the file
                break
            try:
                values[col] = float(text)
            except ValueError:
                fail(path, f"line {line}: {col} is not a number: {text!r}")
        if values is None:
            note(f"{path}: line {line}: empty value, row skipped")
            continue
        if not values["median_ms"] > 0:
            note(f"{path}: line {line}: median_ms {values['median_ms']} cannot go "
                 "on a log axis, row skipped")
            continue
        psnr = values["psnr_db_tonemapped"]
        if math.isnan(psnr) or psnr == -math.inf:
            # bokeh-bench writes -inf where the result held NaN or an infinity the
            # reference did not: no accuracy to draw, and never "exact".
            note(f"{path}: line {line}: {row['method']} returned non-finite values "
                 f"(PSNR {psnr}), row skipped")
            continue
        rows.append({
            "task": task,
            "method": row["method"],
            "peer": row["peer"],
            "threads": row.get("threads", ""),
            "size": values["size_px"],
            "ms": values["median_ms"],
            "psnr": psnr,
            "exact": not math.isfinite(psnr) or psnr >= EXACT_PSNR,
        })
    return list(tasks), rows


def pareto_front(points):
    """Points not dominated by another: a point is dominated when another one is at least
    as fast and at least as accurate, and strictly better in one of the two. (Requiring
    strictly better in both would keep every slower bit-exact point on the front.)"""
    def beats(q, p):
        return (q["ms"] <= p["ms"] and q["acc"] >= p["acc"]
                and (q["ms"] < p["ms"] or q["acc"] > p["acc"]))
    front = [p for p in points if not any(beats(q, p) for q in points)]
    return sorted(front, key=lambda p: p["ms"])


def psnr_knee(finite):
    """Where to change the PSNR scale, or None to keep it linear: just above the lower
    side of a gap of at least 60 dB between finite PSNRs, when there are points on both
    sides of it (the 40 dB budget counts as one below)."""
    values = sorted(set(finite + [BUDGET_DB]))
    gaps = [(b - a, a) for a, b in zip(values, values[1:])]
    if not gaps or not finite or min(finite) > max(gaps)[1]:
        return None
    gap, below = max(gaps)
    return below + 10 if gap >= 60 else None


def series_of(rows):
    """Group a task's rows into series (one per method), ours first, then peers, each in
    order of first appearance. If a method was run with several thread counts, each count
    becomes its own series, since its timings are not comparable."""
    many_threads = {}
    for r in rows:
        many_threads.setdefault((r["method"], r["peer"]), set()).add(r["threads"])
    series = {}
    for r in rows:
        key = (r["method"], r["peer"])
        if len(many_threads[key]) > 1:
            key += (r["threads"],)
        series.setdefault(key, []).append(r)
    keys = sorted(series, key=lambda k: bool(k[1]))   # stable: keeps CSV order within
    return [(k, series[k]) for k in keys]


def label_of(key):
    method, peer = key[0], key[1]
    if peer:
        # The peer's name is usually in the method name already ("OIIO IBA::convolve").
        if peer.lower() not in method.lower():
            method = f"{peer}: {method}"
        method += " (peer)"
    if len(key) > 2:
        method += f", {key[2]} thread" + ("" if key[2] == "1" else "s")
    return method


def ms_text(ms):
    return f"{ms:.0f}" if ms >= 100 else f"{ms:.1f}" if ms >= 10 else f"{ms:.2f}"


def markdown_front(task, front, labels, size_label=SIZE_LABEL):
    if not front:
        name = size_label.split(",")[0]   # "kernel size, px" -> "kernel size"
        return f"### {task}\n\nNo Pareto front: one result per {name}, nothing to compare."
    size_head = "size px" if size_label == SIZE_LABEL else size_label
    lines = [f"### {task}", "", f"| method | {size_head} | median ms | PSNR dB |",
             "|---|---:|---:|---:|"]
    for p in front:
        db = "exact" if p["exact"] else f"{p['psnr']:.1f}"
        method = labels[id(p)].replace("|", "\\|")   # a bare | would end the cell
        lines.append(f"| {method} | {p['size']:g} | {ms_text(p['ms'])} | {db} |")
    return "\n".join(lines)


def plain_number(x, _pos=None):
    """Tick labels like 30, 300, 3000 instead of 10^x: readers compare milliseconds."""
    return f"{x:g}"


def log_ticks(axis, ticker, values):
    """Plain-number ticks on a log axis. Timings often span less than a decade, where the
    default locator leaves no labelled tick at all, so use finer steps the narrower it is."""
    span = math.log10(max(values) / min(values)) if values else 2
    subs = ((1,) if span >= 2 else (1, 2, 5) if span >= 1 else (1, 2, 3, 5) if span >= 0.5
            else range(1, 10))
    subs = tuple(float(s) for s in subs)
    axis.set_major_locator(ticker.LogLocator(base=10, subs=subs))
    axis.set_major_formatter(ticker.FuncFormatter(plain_number))
    axis.set_minor_formatter(ticker.NullFormatter())


class Placer:
    """Places text next to points so that it overlaps neither markers nor text placed
    before (near-equal timings are common, so labels would pile up otherwise). Works in
    points on the figure, so call it only once the axes limits and layout are final."""

    def __init__(self, ax, points, marker_pt=10):
        self.ax = ax
        self.to_points = 72 / ax.figure.dpi
        half = marker_pt / 2
        x0, y0, x1, y1 = ax.get_window_extent().extents * self.to_points
        self.inside = (x0, y0, x1, y1)
        self.taken = [(x - half, y - half, x + half, y + half)
                      for x, y in (self.at(p) for p in points)]

    def at(self, xy, transform=None):
        t = transform or self.ax.transData
        return tuple(v * self.to_points for v in t.transform(xy))

    def free(self, box):
        x0, y0, x1, y1 = self.inside
        if box[0] < x0 or box[1] < y0 or box[2] > x1 or box[3] > y1:
            return False   # out of the axes: into the title, ticks or the other panel
        return not any(box[0] < b[2] and b[0] < box[2] and box[1] < b[3] and b[1] < box[3]
                       for b in self.taken)

    def place(self, text, candidates, fontsize, transform=None, **kw):
        """Annotate text at the first candidate (xy, (dx, dy)) whose box is free, or at the
        first one if none is. xy is in the transform's coordinates (data by default), the
        offset in points: a positive dx puts the text right of xy, a negative one left of
        it; dy is where the text's bottom goes."""
        w, h = 0.6 * fontsize * len(text), fontsize   # a digit or letter is ~0.6 em wide
        boxes = []
        for xy, (dx, dy) in candidates:
            px, py = self.at(xy, transform)
            x0 = px + dx if dx >= 0 else px + dx - w
            boxes.append((x0, py + dy, x0 + w, py + dy + h))
        i = next((i for i, b in enumerate(boxes) if self.free(b)), 0)
        self.taken.append(boxes[i])
        xy, (dx, dy) = candidates[i]
        self.ax.annotate(text, xy, xycoords=transform or "data", xytext=(dx, dy),
                         textcoords="offset points", fontsize=fontsize,
                         ha="left" if dx >= 0 else "right", va="bottom", **kw)


SIZE_LABEL_OFFSETS = [(5, 3), (5, -11), (-5, 3), (-5, -11), (5, 11), (5, -19), (-5, 11),
                      (-5, -19), (9, -4), (-9, -4)]


def draw_task(plt, ticker, task, rows, base, suffix, size_label=SIZE_LABEL):
    """Write base.png and base.svg for one task; return its Markdown front table."""
    series = series_of(rows)
    # tab10 without its grey, which the grid and budget line use; peers are hollow, so
    # they get bold shapes (a hollow star or plus is hard to see).
    colours = [c for i, c in enumerate(plt.get_cmap("tab10").colors) if i != 7]
    ours_markers, peer_markers = "o^sDvPXph<>", "sDo^v"
    n_ours = 0

    finite = [r["psnr"] for r in rows if not r["exact"]]
    # Bit-exact points have no finite PSNR; draw them on a ceiling 10 dB above the best
    # finite one (and above the budget line) so they stay visibly on top, never dropped.
    top_finite = max(finite + [BUDGET_DB])
    ceiling = top_finite + 10
    for r in rows:
        r["acc"] = ceiling if r["exact"] else r["psnr"]

    fig, (ax, ax_size) = plt.subplots(1, 2, figsize=(12, 5.2),
                                      gridspec_kw={"width_ratios": [1.35, 1]})
    handles, labels, size_labels = [], {}, []
    for i, (key, pts) in enumerate(series):
        peer = bool(key[1])
        colour = colours[i % len(colours)]
        if peer:
            marker = peer_markers[(i - n_ours) % len(peer_markers)]
        else:
            marker = ours_markers[i % len(ours_markers)]
            n_ours += 1
        style = dict(marker=marker, color=colour, markersize=8 if peer else 7,
                     markeredgewidth=1.8 if peer else 1,
                     markerfacecolor="none" if peer else colour)
        label = label_of(key)
        for p in pts:
            labels[id(p)] = label

        h, = ax.plot([p["ms"] for p in pts], [p["acc"] for p in pts], linestyle="none",
                     label=label, zorder=3, **style)
        handles.append(h)
        size_labels += [(p["ms"], p["acc"], f"{p['size']:g}", colour) for p in pts]

        by_size = sorted(pts, key=lambda p: p["size"])
        ax_size.plot([p["size"] for p in by_size], [p["ms"] for p in by_size],
                     linestyle="--" if peer else "-", linewidth=1.3, zorder=3, **style)

    # One front per kernel size: methods compete at the same size, not across sizes. A size
    # measured with one method only has no competition, so nothing to ring or list.
    front, h_front = [], None
    for size in sorted({r["size"] for r in rows}):
        at_size = [r for r in rows if r["size"] == size]
        if len(at_size) < 2:
            continue
        f = pareto_front(at_size)
        front += f
        # Light, so several sizes' fronts don't hide the points they join.
        h_front, = ax.plot([p["ms"] for p in f], [p["acc"] for p in f], linestyle="--",
                           color="0.45", linewidth=0.9, marker="o", markersize=15,
                           markerfacecolor="none", markeredgecolor="black",
                           markeredgewidth=0.9, zorder=2, label="Pareto front (per size)")
    if h_front:
        handles.append(h_front)

    # Left panel: error vs time.
    ax.set_xscale("log")
    log_ticks(ax.xaxis, ticker, [r["ms"] for r in rows])
    ax.set_xlabel("median time, ms (log; left is faster)")
    ax.set_ylabel("PSNR after tone map x/(1+x), dB (up is more accurate)")
    ax.axhline(BUDGET_DB, color="0.35", linestyle=":", linewidth=1.2, zorder=1)

    low = min(finite + [BUDGET_DB]) - 8
    has_exact = any(r["exact"] for r in rows)
    high = ceiling + 6 if has_exact else top_finite + 8
    knee = psnr_knee(finite)
    nice = lambda n, lo, hi: ticker.MaxNLocator(n, steps=[1, 2, 5, 10]).tick_values(lo, hi)
    if knee is None:
        ticks = [t for t in nice(7, low, top_finite) if low <= t <= top_finite + 2]
    else:
        # Approximations (30-70 dB) and float round-off (150+ dB) with nothing between:
        # on one linear axis the approximations, which are what a reader compares, would
        # be squeezed into the bottom fifth. Give the range below the knee most of the
        # height, compress the range above it, and mark the change of scale on both spines.
        frac = 0.62
        below = lambda y: (y - low) / (knee - low) * frac
        above = lambda y: frac + (y - knee) / (high - knee) * (1 - frac)
        below_inv = lambda v: low + v / frac * (knee - low)
        above_inv = lambda v: knee + (v - frac) / (1 - frac) * (high - knee)
        # Arithmetic on booleans keeps these elementwise for matplotlib's arrays.
        ax.set_yscale("function", functions=(
            lambda y: (y <= knee) * below(y) + (y > knee) * above(y),
            lambda v: (v <= frac) * below_inv(v) + (v > frac) * above_inv(v)))
        ticks = [t for t in nice(6, low, knee) if low <= t < knee - 3]
        ticks += [t for t in nice(3, knee, top_finite) if knee + 8 < t <= top_finite + 2]
        ax.axhline(knee, color="0.7", linewidth=0.8, zorder=1)
        ax.plot([0, 1], [knee, knee], transform=ax.get_yaxis_transform(), linestyle="none",
                marker=[(-1, -0.6), (1, 0.6)], markersize=9, color="0.3", clip_on=False)
    if has_exact:
        ax.axhspan(ceiling - 4, ceiling + 4, color="0.92", zorder=0)
        ax.axhline(top_finite + 5, color="0.7", linewidth=0.8, zorder=1)  # finite | exact
    ax.set_yticks(ticks + ([ceiling] if has_exact else []))
    ax.set_yticklabels([f"{t:g}" for t in ticks] + (["exact"] if has_exact else []))
    ax.yaxis.set_minor_locator(ticker.NullLocator())
    ax.set_ylim(low, high)
    ax.grid(True, which="major", color="0.9", linewidth=0.6)
    ax.set_title(f"error vs time (labels: {size_label})", fontsize=10)

    # Right panel: cost vs kernel size. Sizes usually double from case to case, so a log x
    # axis spaces them evenly, and on log-log a slope of 1 or 2 reads as O(size), O(size^2).
    ax_size.set_xscale("log")
    ax_size.set_yscale("log")
    # Tick the sizes measured, minus any too close to the previous one to be read apart
    # (15 next to 17).
    ticks = []
    for s in sorted({r["size"] for r in rows}):
        if not ticks or math.log10(s / ticks[-1]) >= 0.08:
            ticks.append(s)
    if len(ticks) <= 12:
        ax_size.set_xticks(ticks)
        ax_size.xaxis.set_major_formatter(ticker.FuncFormatter(plain_number))
        ax_size.xaxis.set_minor_formatter(ticker.NullFormatter())
    else:
        log_ticks(ax_size.xaxis, ticker, ticks)
    # Show at least a decade of time: zoomed into 40..48 ms, timing noise would look like
    # a cost that depends on size, which is what this panel is there to answer.
    times = [r["ms"] for r in rows]
    lo, hi = min(times), max(times)
    if hi / lo < 10:
        mid = math.sqrt(lo * hi)
        lo, hi = mid / math.sqrt(10), mid * math.sqrt(10)
    ax_size.set_ylim(lo / 1.25, hi * 1.25)
    log_ticks(ax_size.yaxis, ticker, [lo, hi])
    ax_size.set_xlabel(f"{size_label} (log)")
    ax_size.set_ylabel("median time, ms (log)")
    ax_size.grid(True, which="major", color="0.9", linewidth=0.6)
    size_name = size_label.split(",")[0]   # "kernel size, px" -> "kernel size"
    ax_size.set_title(f"time vs {size_name}"
                      + (" (flat = cost independent of size)" if size_label == SIZE_LABEL else ""),
                      fontsize=10)

    fig.suptitle(f"{task}: speed vs accuracy" + (f" {suffix}" if suffix else ""),
                 fontsize=13)
    # Legend below both panels, outside the data; the figure grows with its rows.
    ncol = min(len(handles), 3)
    nrows = math.ceil(len(handles) / ncol)
    fig.legend(handles=handles, loc="lower center", ncol=ncol, fontsize=9, frameon=False,
               numpoints=1)
    fig.set_size_inches(12, 4.6 + 0.25 * nrows)
    fig.subplots_adjust(left=0.07, right=0.985, top=0.87, wspace=0.22,
                        bottom=(0.55 + 0.25 * nrows) / (4.6 + 0.25 * nrows))

    # Text last, once limits and layout are final: sizes next to their points, then the
    # budget label wherever along its line it is clear of both.
    ax.autoscale_view()
    placer = Placer(ax, [(r["ms"], r["acc"]) for r in rows])
    for x, y, text, colour in size_labels:
        placer.place(text, [((x, y), off) for off in SIZE_LABEL_OFFSETS], 7.5, color=colour)
    # Budget label: under the line at the right end if clear (cheap methods that just
    # make the budget tend to sit above it on the left), else another spot along it.
    budget = [((fx, BUDGET_DB), (dx, dy)) for fx, dx in ((0.99, -2), (0.01, 2), (0.5, 2))
              for dy in (-10, 2)]
    placer.place(f"{BUDGET_DB:g} dB budget", budget, 8, transform=ax.get_yaxis_transform(),
                 color="0.3")

    # No dates or random ids in the files, so a re-run with the same data changes nothing.
    fig.savefig(base + ".png", dpi=100, metadata={"Software": None})
    fig.savefig(base + ".svg", metadata={"Date": None})
    plt.close(fig)
    return markdown_front(task, front, labels, size_label)


TRUTH_SUFFIX = " vs truth"
MASK_SUFFIX = " vs truth (mask)"
HELD_SUFFIX = " vs truth (held)"


def is_truth_task(task_rows):
    """A deep task measured against the thin-lens truth (bokeh-bench --task deep)."""
    return any(r["method"].endswith(TRUTH_SUFFIX) for r in task_rows)


def draw_truth(plt, ticker, frames, base, suffix):
    """Write base.png and base.svg: per deep frame, each method's PSNR against the truth
    over the frame (filled), over the disocclusion mask (hollow) and over the held pixels
    (a bar), joined, against its median time, and the truth itself at its time and noise
    floor. Return the Markdown tables."""
    colours = [c for i, c in enumerate(plt.get_cmap("tab10").colors) if i != 7]
    markers = "o^sDvP"
    fig, axes = plt.subplots(1, len(frames), figsize=(6.2 * len(frames), 5.2), squeeze=False)
    tables, handles, seen = [], {}, []
    for ax, (task, rows) in zip(axes[0], frames):
        methods = []
        for r in rows:
            m = r["method"]
            name = (m[:-len(MASK_SUFFIX)] if m.endswith(MASK_SUFFIX)
                    else m[:-len(HELD_SUFFIX)] if m.endswith(HELD_SUFFIX)
                    else m[:-len(TRUTH_SUFFIX)] if m.endswith(TRUTH_SUFFIX) else None)
            if name is not None and name not in methods:
                methods.append(name)
        truth = [r for r in rows if r["method"].startswith("truth ")]
        values, lines = [], [f"### {task}", "",
                             "| method | median ms | PSNR vs truth, frame | disocclusion mask | held |",
                             "|---|---:|---:|---:|---:|"]
        for name in methods:
            if name not in seen:
                seen.append(name)
            i = seen.index(name)
            colour, marker = colours[i % len(colours)], markers[i % len(markers)]
            frame = next((r for r in rows if r["method"] == name + TRUTH_SUFFIX), None)
            mask = next((r for r in rows if r["method"] == name + MASK_SUFFIX), None)
            held = next((r for r in rows if r["method"] == name + HELD_SUFFIX), None)
            pts = [p for p in (frame, mask, held) if p]
            if not pts:
                continue
            if len(pts) > 1:
                ax.plot([pts[0]["ms"]] * 2, [min(p["psnr"] for p in pts), max(p["psnr"] for p in pts)],
                        color=colour, linewidth=1, zorder=2)
            if frame:
                h, = ax.plot([frame["ms"]], [frame["psnr"]], marker=marker, color=colour,
                             markersize=8, linestyle="none", zorder=3)
                handles.setdefault(name, h)
            if mask:
                ax.plot([mask["ms"]], [mask["psnr"]], marker=marker, color=colour, markersize=8,
                        markerfacecolor="white", markeredgewidth=1.6, linestyle="none", zorder=3)
            if held:
                ax.plot([held["ms"]], [held["psnr"]], marker="_", color=colour, markersize=14,
                        markeredgewidth=2.2, linestyle="none", zorder=3)
            values += pts
            fmt = lambda r: f"{r['psnr']:.1f}" if r else ""
            lines.append(f"| {name} | {ms_text(pts[0]['ms'])} | {fmt(frame)} | {fmt(mask)} | {fmt(held)} |")
        for t in truth:
            h, = ax.plot([t["ms"]], [t["psnr"]], marker="*", color="black", markersize=13,
                         linestyle="none", zorder=3)
            handles.setdefault(f"{t['method']}: its noise floor, at its time", h)
            ax.axhline(t["psnr"], color="0.35", linestyle=":", linewidth=1.1, zorder=1)
            values.append(t)
            lines.append(f"| {t['method']} (its noise) | {ms_text(t['ms'])} | {t['psnr']:.1f} | | |")
        ax.set_xscale("log")
        log_ticks(ax.xaxis, ticker, [v["ms"] for v in values])
        lo = min(v["psnr"] for v in values)
        hi = max(v["psnr"] for v in values)
        ax.set_ylim(lo - 3, hi + 3)
        ax.set_xlim(min(v["ms"] for v in values) / 1.6, max(v["ms"] for v in values) * 1.6)
        ax.grid(True, which="major", color="0.9", linewidth=0.6)
        ax.set_xlabel("median time, ms (log; left is faster)")
        ax.set_ylabel("PSNR against the truth, dB (up is closer)")
        ax.set_title(task.removeprefix("deep "), fontsize=10)
        placer = Placer(ax, [(v["ms"], v["psnr"]) for v in values])
        for v in values:
            placer.place(f"{v['psnr']:.1f}", [((v["ms"], v["psnr"]), off) for off in SIZE_LABEL_OFFSETS],
                         7.5, color="0.2")
        tables.append("\n".join(lines))
    # A legend entry for the two fills, drawn as grey markers.
    h_frame, = axes[0][0].plot([], [], marker="o", color="0.4", linestyle="none")
    h_mask, = axes[0][0].plot([], [], marker="o", color="0.4", markerfacecolor="white",
                               linestyle="none")
    h_held, = axes[0][0].plot([], [], marker="_", color="0.4", markersize=14, markeredgewidth=2.2,
                               linestyle="none")
    labels = list(handles) + ["filled: over the frame", "hollow: over the disocclusion mask",
                              "bar: over the held pixels (the file records all their rays meet)"]
    fig.legend(list(handles.values()) + [h_frame, h_mask, h_held], labels, loc="lower center",
               ncol=3, fontsize=9, frameon=False, numpoints=1)
    fig.suptitle("deep defocus against the thin-lens truth: accuracy vs time"
                 + (f" {suffix}" if suffix else ""), fontsize=13)
    fig.subplots_adjust(left=0.07, right=0.985, top=0.86, bottom=0.25, wspace=0.22)
    fig.savefig(base + ".png", dpi=100, metadata={"Software": None})
    fig.savefig(base + ".svg", metadata={"Date": None})
    plt.close(fig)
    return tables


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("csv", help="CSV written by bokeh-bench --csv")
    ap.add_argument("outdir", help="directory for <task>.png and <task>.svg")
    ap.add_argument("--title-suffix", default="", help="text appended to every chart title")
    ap.add_argument("--size-label", default=SIZE_LABEL,
                    help=f"what size_px holds (default: {SIZE_LABEL!r})")
    args = ap.parse_args()

    task_names, rows = read_rows(args.csv)
    if not rows:
        fail(args.csv, "no usable data rows")

    plt = pyplot()
    from matplotlib import ticker

    if os.path.exists(args.outdir) and not os.path.isdir(args.outdir):
        fail(args.outdir, "not a directory")
    try:
        os.makedirs(args.outdir, exist_ok=True)
    except OSError as e:
        fail(args.outdir, e.strerror.lower() if e.strerror else str(e))

    tables, bases = [], set()
    truth_frames = []
    for task in task_names:
        task_rows = [r for r in rows if r["task"] == task]
        if not task_rows:
            note(f"{args.csv}: task {task!r} has no usable rows, skipped")
            continue
        if is_truth_task(task_rows):
            truth_frames.append((task, task_rows))   # one chart for all of them, below
            continue
        # Task names become file names; "disk hard" and "disk_hard" must not overwrite.
        base = os.path.join(args.outdir, re.sub(r"[^A-Za-z0-9._-]+", "_", task))
        n = 1
        while base + ("" if n == 1 else f"_{n}") in bases:
            n += 1
        base += "" if n == 1 else f"_{n}"
        bases.add(base)
        try:
            tables.append(draw_task(plt, ticker, task, task_rows, base, args.title_suffix,
                                    args.size_label))
        except OSError as e:
            fail(args.outdir, e.strerror.lower() if e.strerror else str(e))
    if truth_frames:
        try:
            tables += draw_truth(plt, ticker, truth_frames, os.path.join(args.outdir, "deep_truth"),
                                 args.title_suffix)
        except OSError as e:
            fail(args.outdir, e.strerror.lower() if e.strerror else str(e))
    print("\n\n".join(tables))


if __name__ == "__main__":
    main()

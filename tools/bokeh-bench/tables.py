#!/usr/bin/env python3
"""The tables of docs/benchmarks.md, made from bokeh-bench's CSVs.

    tables.py PAGE BENCH_DIR            rewrite PAGE's generated tables from BENCH_DIR/*.csv
    tables.py PAGE BENCH_DIR --check    exit 1 (printing the difference) when they differ

PAGE marks each table it holds as

    <!-- begin table NAME -->
    ...
    <!-- end table NAME -->

and everything between the two lines is replaced; the text around the tables is the
page's own. NAME is one of: blur, defocus, iris, resample-2, resample-4, resample-8,
resample-16. `make bench` runs the rewrite after the bench, so the tables are always the
CSVs' figures.
"""
import csv
import difflib
import os
import re
import sys


def read(bench_dir, name):
    with open(os.path.join(bench_dir, name), newline="") as f:
        return list(csv.DictReader(f))


def num(text):
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


def ms(value):
    """Milliseconds: three significant digits below 100, whole above."""
    return f"{value:.3g}" if value < 100 else f"{value:.0f}"


def blur_table(bench_dir):
    rows = read(bench_dir, "blur.csv")
    sizes = ["15", "31", "63", "127", "255"]
    order, cells = [], {}
    for r in rows:
        if r["peer"] or r["size_px"] not in sizes:
            continue
        key = f"{r['task']}, {r['method']}"
        if key not in cells:
            order.append(key)
            cells[key] = {}
        psnr = num(r["psnr_db_tonemapped"])
        exact = psnr is not None and psnr >= 160
        cells[key][r["size_px"]] = ms(float(r["median_ms"])) + ("" if exact else f" / {psnr:.1f}")
    out = ["| kernel, method | 15 px | 31 | 63 | 127 | 255 |", "|---|---|---|---|---|---|"]
    for key in order:
        out.append(f"| {key} | " + " | ".join(cells[key].get(s, "") for s in sizes) + " |")
    return out


def defocus_table(bench_dir):
    rows = read(bench_dir, "defocus.csv")
    shots, methods, cells = [], [], {}
    for r in rows:
        shot = r["task"].replace("defocus ", "", 1)
        method = r["method"]
        layers = ""
        m = re.match(r"(reference) \((\d+) layers\)", method)
        if m:
            method, layers = m.group(1), m.group(2)
        if shot not in shots:
            shots.append(shot)
        if method not in methods:
            methods.append(method)
        psnr = num(r["psnr_db_tonemapped"])
        t = f"{float(r['median_ms']):.0f}"
        if layers:
            cells[(method, shot)] = f"{t} ({layers} layers)"
        else:
            cells[(method, shot)] = f"{t} / " + ("exact" if psnr >= 160 else f"{psnr:.1f}")
    out = ["| method | " + " | ".join(shots) + " |", "|---|" + "---|" * len(shots)]
    for m in methods:
        bold = "**" if "(default)" in m else ""
        row = [f"{bold}{cells.get((m, s), '')}{bold}" for s in shots]
        out.append(f"| {bold}{m}{bold} | " + " | ".join(row) + " |")
    return out


def iris_table(bench_dir):
    rows = read(bench_dir, "iris.csv")
    ks, methods, cells = [], [], {}
    for r in rows:
        k = r["task"].rsplit(" ", 1)[-1]
        if k not in ks:
            ks.append(k)
        if r["method"] not in methods:
            methods.append(r["method"])
        cells.setdefault((k, r["method"]), {})[r["size_px"]] = f"{float(r['psnr_db_tonemapped']):.1f}"
    sizes = sorted({r["size_px"] for r in rows}, key=float)
    out = ["| \\|k\\| x range | " + " | ".join(f"{m}, {' / '.join(sizes)} px" for m in methods) + " |",
           "|---|" + "---|" * len(methods)]
    for k in ks:
        out.append(f"| {k} | " + " | ".join(" / ".join(cells[(k, m)].get(s, "") for s in sizes)
                                            for m in methods) + " |")
    return out


def deep_table(bench_dir):
    rows = read(bench_dir, "deep.csv")
    out = ["| frame | operation | ours ms | OIIO ms | PSNR dB |", "|---|---|---:|---:|---:|"]
    keys = []
    for r in rows:
        if (r["task"], r["method"]) not in keys:
            keys.append((r["task"], r["method"]))
    for task, method in keys:
        def cell(peer, column):
            match = [r for r in rows if (r["task"], r["method"], r["peer"]) == (task, method, peer)]
            return match[0][column] if match and match[0][column] else ""
        ours, theirs, psnr = cell("", "median_ms"), cell("oiio", "median_ms"), cell("", "psnr_db_tonemapped")
        out.append(f"| {task.removeprefix('deep ')} | {method} | {ms(float(ours)) if ours else ''} | "
                   f"{ms(float(theirs)) if theirs else ''} | {f'{float(psnr):.1f}' if psnr else ''} |")
    return out


def resample_table(bench_dir, factor):
    rows = read(bench_dir, "resample.csv")
    artifacts = read(bench_dir, "resample_artifacts.csv")
    times = {(r["task"], r["method"], r["size_px"]): r for r in rows}
    methods = []
    for r in rows:
        if r["task"] == "enlarge glare" and r["size_px"] == factor and not r["peer"]:
            methods.append(r["method"])
    peers = [a["method"] for a in artifacts if a["peer"] and a["factor"] == factor]
    art = {(a["method"], a["factor"]): a for a in artifacts}

    def cell(task, method, column, fmt):
        r = times.get((task, method, factor))
        value = num(r[column]) if r else None
        return fmt.format(value) if value is not None else ""

    out = ["| method | enlarge ms | glare: pipeline ms | glare: PSNR dB | bokeh: pipeline ms "
           "| bokeh: PSNR dB | Mach | overshoot % | shimmer | detail % |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for m in methods + peers:
        enlarge = cell("enlarge glare", m, "median_ms", "{:.1f}")
        if enlarge and float(enlarge) >= 100:
            enlarge = f"{float(enlarge):.0f}"
        glare_psnr = cell("enlarge glare", m, "psnr_db_tonemapped", "{:.1f}")
        bokeh_psnr = cell("enlarge bokeh", m, "psnr_db_tonemapped", "{:.1f}")
        a = art.get((m, factor))
        extra = ([f"{float(a['mach']):.2f}", f"{float(a['overshoot_pct']):.1f}",
                  f"{float(a['shimmer']):.1f}", f"{float(a['detail_pct']):.1f}"]
                 if a else ["", "", "", ""])
        label = f"{m} (peer)" if m in peers else m
        out.append("| " + " | ".join([label, enlarge,
                                      cell("enlarge glare pipeline", m, "median_ms", "{:.1f}"),
                                      glare_psnr,
                                      cell("enlarge bokeh pipeline", m, "median_ms", "{:.1f}"),
                                      bokeh_psnr] + extra) + " |")
    return out


TABLES = {
    "blur": blur_table,
    "defocus": defocus_table,
    "iris": iris_table,
    "deep": deep_table,
    "resample-2": lambda d: resample_table(d, "2"),
    "resample-4": lambda d: resample_table(d, "4"),
    "resample-8": lambda d: resample_table(d, "8"),
    "resample-16": lambda d: resample_table(d, "16"),
}


def render(page_text, bench_dir):
    out, lines, i = [], page_text.split("\n"), 0
    while i < len(lines):
        line = lines[i]
        out.append(line)
        m = re.fullmatch(r"<!-- begin table (\S+) -->", line)
        i += 1
        if not m:
            continue
        name = m.group(1)
        if name not in TABLES:
            raise SystemExit(f"tables.py: unknown table '{name}' (known: {', '.join(TABLES)})")
        end = f"<!-- end table {name} -->"
        while i < len(lines) and lines[i] != end:
            i += 1
        if i == len(lines):
            raise SystemExit(f"tables.py: '{line}' has no '{end}'")
        out.extend(TABLES[name](bench_dir))
    return "\n".join(out)


def main(argv):
    if len(argv) not in (3, 4) or (len(argv) == 4 and argv[3] != "--check"):
        raise SystemExit("usage: tables.py PAGE BENCH_DIR [--check]")
    page, bench_dir = argv[1], argv[2]
    with open(page) as f:
        old = f.read()
    new = render(old, bench_dir)
    if len(argv) == 4:
        if new != old:
            sys.stdout.writelines(difflib.unified_diff(old.splitlines(True), new.splitlines(True),
                                                       page + " (committed)", page + " (from the CSVs)"))
            print(f"\nFAIL: {page}'s tables differ from {bench_dir}/*.csv. Regenerate them: "
                  f"/usr/bin/python3 tools/bokeh-bench/tables.py {page} {bench_dir}")
            return 1
        return 0
    with open(page, "w") as f:
        f.write(new)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

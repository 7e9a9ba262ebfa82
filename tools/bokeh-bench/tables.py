#!/usr/bin/env python3
"""The tables and the quoted figures of docs/benchmarks.md, made from bokeh-bench's CSVs.

    tables.py PAGE BENCH_DIR            rewrite PAGE's generated tables and figures from BENCH_DIR/*.csv
    tables.py PAGE BENCH_DIR --check    exit 1 (naming each figure, and printing the difference) when they differ

PAGE marks each table it holds as

    <!-- begin table NAME -->
    ...
    <!-- end table NAME -->

and everything between the two lines is replaced. NAME is one of: blur, defocus, iris,
deep, resample-2, resample-4, resample-8, resample-16.

A figure quoted in the text (a time, a ratio, a PSNR, a range of them) is marked inline,
on one line, as

    <!--f:NAME-->44.9 ms at 59.9 dB<!--/f-->

and the text between the two comments is replaced by FIGURES[NAME] (below: each names the
CSV rows it reads), so that the prose quotes the CSVs as the tables do. A statement the
text makes about the figures without quoting one (every budget met, say) is marked
`<!--c:NAME-->` and checked by CLAIMS[NAME]: when it no longer holds, both modes say which
sentence to rewrite and exit 1 (the rewrite still writes the page). The rest of the text
is the page's own. `make bench` runs the rewrite after the bench, so the tables and the
marked figures are always the CSVs'.
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


# --- figures quoted in the text ---------------------------------------------------------

class Bench:
    """BENCH_DIR's CSVs, a row looked up by its key columns (a value, or a test of one);
    `used` notes every value read, so that a figure that differs names its source."""

    def __init__(self, bench_dir):
        self.dir, self.tables, self.used = bench_dir, {}, []

    def rows(self, name):
        if name not in self.tables:
            self.tables[name] = read(self.dir, name)
        return self.tables[name]

    def row(self, name, **key):
        rows = self.rows(name)
        if rows and "peer" in rows[0] and "peer" not in key:
            key["peer"] = ""  # ours, unless a peer is named
        match = [r for r in rows
                 if all(v(r[k]) if callable(v) else r[k] == str(v) for k, v in key.items())]
        if len(match) != 1:
            shown = {k: ("<test>" if callable(v) else v) for k, v in key.items()}
            raise SystemExit(f"tables.py: {name}: {len(match)} rows where {shown}, not one")
        return match[0]

    def value(self, name, column, **key):
        r = self.row(name, **key)
        where = ", ".join(f"{k}={r[k]}" for k in key if r[k])
        self.used.append(f"{name} [{where}] {column}={r[column]}")
        return float(r[column])

    def note(self, text):
        self.used.append(text)


SIZES = ["15", "31", "63", "127", "255"]
FACTORS = ["2", "4", "8", "16"]


def blur(b, task, method, size, column="median_ms", peer=""):
    return b.value("blur.csv", column, task=task, method=method, size_px=size, peer=peer)


def blur_db(b, task, method, size, peer=""):
    return blur(b, task, method, size, "psnr_db_tonemapped", peer)


def bands(b, n, size):
    return blur(b, "disk", f"{n} bands (running sums)", size)


def span(values, fmt):
    """'lo-hi' of `values` in format `fmt` ('lo' alone when they round alike)."""
    lo, hi = format(min(values), fmt), format(max(values), fmt)
    return lo if lo == hi else f"{lo}-{hi}"


def one_digit(x):
    """One significant digit below 10 (0.8, 5), whole above."""
    return f"{x:.1g}" if x < 9.5 else f"{x:.0f}"


def two_digits(x):
    """Two significant digits below 100 (21, 3.8), whole above."""
    return f"{x:.2g}" if x < 99.5 else f"{x:.0f}"


def shown_gain(a, b):
    """a - b as the text shows it beside a and b: the difference of the one-decimal values
    it quotes (so the reader's subtraction agrees), one decimal."""
    return f"{float(f'{a:.1f}') - float(f'{b:.1f}'):.1f}"


def verdict(ok):
    return "met" if ok else "not met"


def registrar(table):
    """A decorator that files a function in `table` under a name: @figure("x"), @claim("y")."""
    def register(name):
        def add(fn):
            table[name] = fn
            return fn
        return add
    return register


FIGURES = {}
figure = registrar(FIGURES)


# Uniform blurs: blur.csv.

@figure("blur_reps")
def figure_blur_reps(b):
    reps = sorted({r["reps"] for r in b.rows("blur.csv") if not r["peer"]}, key=int)
    b.note(f"blur.csv reps of our rows: {', '.join(reps)}")
    return " / ".join(reps)


for _n in (9, 17):
    FIGURES[f"kawase{_n}"] = lambda b, n=_n: (f"{ms(blur(b, 'disk', 'Kawase bilinear taps', n))} ms at "
                                              f"{blur_db(b, 'disk', 'Kawase bilinear taps', n):.1f} dB")

OIIO_DISK = "OIIO IBA::convolve (hard disk)"
GEGL = "GEGL gegl:lens-blur radius 30"
FIGURES.update({
    "oiio31_ours": lambda b: f"{ms(blur(b, 'disk', 'row spans (exact)', 31))} ms",
    "oiio31_peer": lambda b: f"{ms(blur(b, 'disk', OIIO_DISK, 31, peer='oiio'))} ms",
    "oiio31_ratio": lambda b: format(blur(b, "disk", OIIO_DISK, 31, peer="oiio")
                                     / blur(b, "disk", "row spans (exact)", 31), ".0f") + "x",
    "oiio9": lambda b: f"{ms(blur(b, 'disk', OIIO_DISK, 9, peer='oiio'))} ms",
    "gegl_ours_db": lambda b: f"{blur_db(b, 'disk hard', 'row spans (exact)', 61):.0f}",
    "gegl_peer_db": lambda b: f"{blur_db(b, 'disk hard', GEGL, 61, peer='gegl'):.0f}",
    "gegl_ours": lambda b: f"{ms(blur(b, 'disk hard', 'row spans (exact)', 61))} ms",
    "gegl_bands": lambda b: (f"{ms(blur(b, 'disk hard', '8 bands (running sums)', 61))} ms at "
                             f"{blur_db(b, 'disk hard', '8 bands (running sums)', 61):.1f} dB"),
    "gegl_peer": lambda b: f"{ms(blur(b, 'disk hard', GEGL, 61, peer='gegl'))} ms",
    "gegl_ratio": lambda b: format(blur(b, "disk hard", GEGL, 61, peer="gegl")
                                   / blur(b, "disk hard", "row spans (exact)", 61), ".1f") + "x",
    "gegl_verdict": lambda b: verdict(blur(b, "disk hard", GEGL, 61, peer="gegl")
                                      > blur(b, "disk hard", "row spans (exact)", 61)),
    "oiio31_verdict": lambda b: verdict(blur(b, "disk", OIIO_DISK, 31, peer="oiio")
                                        >= 100 * blur(b, "disk", "row spans (exact)", 31)),
    # The targets: box, hexagon, exact disk, a disk approximation.
    "box_range": lambda b: span([blur(b, "box", "running sums", s) for s in SIZES], ".1f") + " ms",
    "box_range0": lambda b: span([blur(b, "box", "running sums", s) for s in SIZES], ".0f"),
    "box_verdict": lambda b: verdict(max(blur(b, "box", "running sums", s) for s in SIZES) < 25),
    "box_flat": lambda b: f"{blur(b, 'box', 'running sums', 255) / blur(b, 'box', 'running sums', 15):.2f}x",
    "box_flat_verdict": lambda b: verdict(blur(b, "box", "running sums", 255)
                                          <= 1.3 * blur(b, "box", "running sums", 15)),
})

HEX_UPRIGHT, HEX_FLAT = "3 parallelograms", "3 parallelograms (flat top)"
FAST = "fast (the tool's choice)"
HEX_TURNED = ["3 parallelograms (7 degrees)", "3 parallelograms (25 degrees)"]
FIGURES.update({
    "hex_flat_range": lambda b: span([blur(b, "hexagon", HEX_FLAT, s) for s in SIZES], ".1f"),
    "hex_upright_range": lambda b: span([blur(b, "hexagon", HEX_UPRIGHT, s) for s in SIZES], ".1f"),
    "hex_upright_255": lambda b: f"{blur(b, 'hexagon', HEX_UPRIGHT, 255):.1f}",
    "hex_turned_range": lambda b: span([blur(b, "hexagon", m, s) for m in HEX_TURNED for s in SIZES], ".0f"),
    "hex_upright_flat": lambda b: f"{blur(b, 'hexagon', HEX_UPRIGHT, 255) / blur(b, 'hexagon', HEX_UPRIGHT, 15):.2f}x",
    "hex_flattop_flat": lambda b: f"{blur(b, 'hexagon', HEX_FLAT, 255) / blur(b, 'hexagon', HEX_FLAT, 15):.2f}x",
})


@figure("hex_verdict")
def figure_hex_verdict(b):
    """The hexagon < 25 ms target, per orientation."""
    flat_ok = all(blur(b, "hexagon", HEX_FLAT, s) < 25 for s in SIZES)
    upright_over = [s for s in SIZES if blur(b, "hexagon", HEX_UPRIGHT, s) >= 25]
    turned_ok = all(blur(b, "hexagon", m, s) < 25 for m in HEX_TURNED for s in SIZES)
    parts = ["met flat-topped" if flat_ok else "not met flat-topped"]
    parts.append("met upright" if not upright_over else f"not upright at {', '.join(upright_over)} px")
    last = "met at other rotations" if turned_ok else "nor at other rotations"
    return "; ".join(parts) + (", " if upright_over and not turned_ok else "; ") + last


@figure("hex_flat_verdict")
def figure_hex_flat_verdict(b):
    ok = {m: blur(b, "hexagon", m, 255) <= 1.3 * blur(b, "hexagon", m, 15) for m in (HEX_UPRIGHT, HEX_FLAT)}
    if all(ok.values()):
        return "met"
    if not any(ok.values()):
        return "not met"
    return "met upright only" if ok[HEX_UPRIGHT] else "met flat-topped only"


FIGURES.update({
    "disk63_spans": lambda b: f"{blur(b, 'disk', 'row spans (exact)', 63):.0f} ms",
    "disk63_fft": lambda b: f"{blur(b, 'disk', 'FFT tiles (exact)', 63):.0f}",
    "disk63_verdict": lambda b: verdict(min(blur(b, "disk", m, 63) for m in ("row spans (exact)", "FFT tiles (exact)"))
                                        < 100),
    "disk63_either": lambda b: span([blur(b, "disk", m, 63) for m in ("row spans (exact)", "FFT tiles (exact)")],
                                    ".0f") + " ms",
    "disk127": lambda b: (f"{blur(b, 'disk', 'FFT tiles (exact)', 127):.0f} against "
                          f"{blur(b, 'disk', 'row spans (exact)', 127):.0f}"),
    "reduced63": lambda b: (f"{blur_db(b, 'disk', 'reduced 1/N (bilinear)', 63):.1f} dB in "
                            f"{ms(blur(b, 'disk', 'reduced 1/N (bilinear)', 63))} ms"),
    "reduced63_verdict": lambda b: verdict(blur_db(b, "disk", "reduced 1/N (bilinear)", 63) >= 40
                                           and blur(b, "disk", "reduced 1/N (bilinear)", 63) < 25),
    "bands4_63_db": lambda b: f"{blur_db(b, 'disk', '4 bands (running sums)', 63):.1f}",
    # "~1.4x": the largest of the band counts' 255 px time over their 127 px time.
    "bands_255_over_127": lambda b: f"{max(bands(b, n, 255) / bands(b, n, 127) for n in (4, 6, 8, 16)):.1f}",
    "fast_disk31": lambda b: (f"{ms(blur(b, 'disk', FAST, 31))} ms at {blur_db(b, 'disk', FAST, 31):.1f} dB"),
    "hex_db_range": lambda b: (f"{blur_db(b, 'hexagon', HEX_UPRIGHT, 15):.1f} -> "
                               f"{blur_db(b, 'hexagon', HEX_UPRIGHT, 255):.1f}"),
    "gauss_boxes": lambda b: (span([blur(b, "gaussian", "3 boxes (fast)", s) for s in SIZES], ".0f") + " ms and "
                              + span([blur_db(b, "gaussian", "3 boxes (fast)", s) for s in SIZES], ".0f") + " dB"),
})


# Reduced buffers: resample.csv, resample_figures.csv, resample_artifacts.csv.

def rs(b, task, method, factor, column="median_ms", peer=""):
    return b.value("resample.csv", column, task=task, method=method, size_px=factor, peer=peer)


def rs_fig(b, figure_name, method, column="ms"):
    return b.value("resample_figures.csv", column, figure=figure_name, method=method)


def rs_met(b, figure_name, method):
    r = b.row("resample_figures.csv", figure=figure_name, method=method)
    b.note(f"resample_figures.csv [{figure_name}, {method}] met={r['met']}")
    return r["met"] == "yes"


ENLARGE = "enlarge 480x270 -> 1920x1080 enlarge()"
VS_OIIO = "vs OIIO IBA::resize 480x270 -> 1920x1080"
CLAIM = "pipeline {} at 1/8 vs bilinear"
REFERENCE = "full-resolution blur (reference)"
FIGURES.update({
    "rs_glare_ref_ms": lambda b: f"{rs(b, 'enlarge glare pipeline', REFERENCE, 1):.0f}",
    "rs_bokeh_ref_ms": lambda b: f"{rs(b, 'enlarge bokeh pipeline', REFERENCE, 1):.0f}",
    "rs_low_glare": lambda b: " / ".join(two_digits(rs_fig(b, f"reduce + blur glare at 1/{s}", lambda m: True))
                                         for s in FACTORS),
    "rs_low_bokeh": lambda b: " / ".join(two_digits(rs_fig(b, f"reduce + blur bokeh at 1/{s}", lambda m: True))
                                         for s in FACTORS),
    "rs_t_bilinear": lambda b: f"{rs_fig(b, ENLARGE, 'bilinear'):.1f} ms",
    "rs_t_bilinear_met": lambda b: verdict(rs_met(b, ENLARGE, "bilinear")),
    "rs_t_gaussian": lambda b: f"{rs_fig(b, ENLARGE, 'gaussian'):.1f} ms",
    "rs_t_gaussian_met": lambda b: verdict(rs_met(b, ENLARGE, "gaussian")),
    "rs_t_upscale": lambda b: (f"{rs_fig(b, ENLARGE, 'upscale-blur'):.1f} ms (fused "
                               f"{rs_fig(b, ENLARGE, 'upscale-blur-fused'):.1f}, two-stage "
                               f"{rs_fig(b, ENLARGE, 'upscale-blur-2stage'):.1f})"),
    "rs_t_upscale_met": lambda b: verdict(rs_met(b, ENLARGE, "upscale-blur")),
    "rs_claim_glare": lambda b: f"{rs_fig(b, CLAIM.format('glare'), 'upscale-blur', 'ratio'):.3f}x",
    "rs_claim_bokeh": lambda b: f"{rs_fig(b, CLAIM.format('bokeh'), 'upscale-blur', 'ratio'):.3f}x",
    "rs_claim_glare_met": lambda b: verdict(rs_met(b, CLAIM.format("glare"), "upscale-blur")),
    "rs_claim_bokeh_met": lambda b: verdict(rs_met(b, CLAIM.format("bokeh"), "upscale-blur")),
    "rs_glare_pipe8": lambda b: f"{rs_fig(b, CLAIM.format('glare'), 'upscale-blur', 'versus_ms'):.0f}",
    # upscale-blur's extra pass: its 1/8 pipeline less bilinear's, glare and bokeh.
    "rs_extra": lambda b: span([rs_fig(b, CLAIM.format(e), "upscale-blur")
                                - rs_fig(b, CLAIM.format(e), "upscale-blur", "versus_ms") for e in ("glare", "bokeh")],
                               ".1f"),
    # "the glare falls from 87 to 49 dB": bilinear's, at 1/2 and 1/16.
    "rs_glare_fall": lambda b: (f"{rs(b, 'enlarge glare', 'bilinear', 2, 'psnr_db_tonemapped'):.0f} to "
                                f"{rs(b, 'enlarge glare', 'bilinear', 16, 'psnr_db_tonemapped'):.0f}"),
    "rs_mach_oiio_gaussian": lambda b: " / ".join(
        f"{b.value('resample_artifacts.csv', 'mach', method='OIIO IBA::resize gaussian', peer='oiio', factor=s):.0f}"
        for s in FACTORS),
    "rs_mach_gaussian": lambda b: " / ".join(
        f"{b.value('resample_artifacts.csv', 'mach', method='gaussian', factor=s):.1f}" for s in FACTORS),
})
for _ours, _peer in (("bilinear", "triangle"), ("gaussian", "gaussian"), ("lanczos3", "lanczos3"),
                     ("catmull-rom", "catmull-rom")):
    FIGURES[f"rs_vs_{_peer}"] = lambda b, o=_ours: (f"{rs_fig(b, VS_OIIO, o):.1f} vs "
                                                    f"{rs_fig(b, VS_OIIO, o, 'versus_ms'):.0f} ms: "
                                                    f"{rs_fig(b, VS_OIIO, o, 'ratio'):.0f}x")
    FIGURES[f"rs_vs_{_peer}_met"] = lambda b, o=_ours: verdict(rs_met(b, VS_OIIO, o))


# Depth defocus: defocus.csv.

SHOTS = ["lights", "edges", "giant", "beachball", "lowresleftview"]
SYNTHETIC = ["lights", "edges", "giant"]
DEFAULT = "layers budget 40 dB (default)"


def dof(b, shot, method, column="median_ms"):
    return b.value("defocus.csv", column, task=f"defocus {shot}", method=method)


def dof_db(b, shot, method):
    return dof(b, shot, method, "psnr_db_tonemapped")


def is_reference(method):
    return method.startswith("reference (")


def ref_layers(b, shot):
    r = b.row("defocus.csv", task=f"defocus {shot}", method=is_reference)
    b.note(f"defocus.csv [defocus {shot}] method={r['method']}")
    return re.match(r"reference \((\d+) layers\)", r["method"]).group(1)


def dof_reps(b, reference):
    reps = sorted({r["reps"] for r in b.rows("defocus.csv") if is_reference(r["method"]) == reference}, key=int)
    b.note(f"defocus.csv reps of the {'reference' if reference else 'other'} rows: {', '.join(reps)}")
    return reps


@figure("dof_reps")
def figure_dof_reps(b):
    return " / ".join(dof_reps(b, False))


@figure("dof_ref_reps")
def figure_dof_ref_reps(b):
    reps = dof_reps(b, True)
    return "a single run" if reps == ["1"] else f"the median of {' / '.join(reps)}"


def db_text(db):
    """A PSNR as the page writes it: "exact" where the CSV's 999 says identical."""
    return "exact" if db >= 999 else f"{db:.1f} dB"


# The shots' largest |CoC| (the CSV's size_px), with the sign of the end it is at.
for _shot, _sign in (("lights", "-"), ("edges", "-"), ("giant", "-"), ("beachball", ""), ("lowresleftview", "-")):
    FIGURES[f"coc_{_shot}"] = lambda b, s=_shot, sign=_sign: (
        f"{sign}{dof(b, s, is_reference, 'size_px'):.0f}")
for _shot in SHOTS:
    FIGURES[f"dof_layers_{_shot}"] = lambda b, s=_shot: ref_layers(b, s)
    FIGURES[f"dof_default_{_shot}"] = lambda b, s=_shot: f"{dof(b, s, DEFAULT):.0f} ms / {db_text(dof_db(b, s, DEFAULT))}"
    FIGURES[f"dof_default_{_shot}_db"] = lambda b, s=_shot: db_text(dof_db(b, s, DEFAULT))
FIGURES.update({
    # "giant, whose CoC is 5x that" (the target's 64 px).
    "dof_giant_coc_x": lambda b: f"{dof(b, 'giant', is_reference, 'size_px') / 64:.0f}",
    "dof_giant_ms": lambda b: f"{dof(b, 'giant', DEFAULT):.0f} ms",
    "dof_giant_speedup": lambda b: f"{dof(b, 'giant', is_reference) / dof(b, 'giant', DEFAULT):.1f}x",
    "dof_gather_db": lambda b: span([dof_db(b, s, "gather (hikita)") for s in SYNTHETIC], ".0f"),
    "dof_gather_x": lambda b: "-".join(
        one_digit(f([dof(b, s, "gather (hikita)") / dof(b, s, DEFAULT) for s in SYNTHETIC])) for f in (min, max)),
})


@figure("dof_budget_worst")
def figure_dof_budget_worst(b):
    """Each budget's worst PSNR over the shots."""
    worst = [f"{min(dof_db(b, s, f'layers budget {db} dB' + (' (default)' if db == 40 else '')) for s in SHOTS):.1f}"
             for db in (30, 40, 50, 60)]
    return f"30: {worst[0]} dB worst; 40: {worst[1]}; 50: {worst[2]}; 60: {worst[3]}"


# Deep images: deep.csv. `auto` = "deep auto", the flat one = "flat auto of the flatten",
# the floor = "another seed's truth vs truth"; over the frame, the mask, the held pixels.

DEEP_FRAMES = {"lrv": "LowResLeftView merged", "rdi": "representativeDeepImage"}
OVER = ["", " (mask)", " (held)"]
FLOOR = "another seed's truth"


def deep_db(b, frame, method, over):
    return b.value("deep.csv", "psnr_db_tonemapped", task=f"deep {DEEP_FRAMES[frame]}",
                   method=f"{method} vs truth{over}")


for _f in DEEP_FRAMES:
    FIGURES[f"deep_{_f}_auto"] = lambda b, f=_f: " / ".join(f"{deep_db(b, f, 'deep auto', o):.1f}" for o in OVER)
    FIGURES[f"deep_{_f}_flat"] = lambda b, f=_f: " / ".join(
        f"{deep_db(b, f, 'flat auto of the flatten', o):.1f}" for o in OVER)
    for _o, _name in zip(OVER, ("frame", "mask", "held")):
        FIGURES[f"deep_{_f}_gain_{_name}"] = lambda b, f=_f, o=_o: shown_gain(
            deep_db(b, f, "deep auto", o), deep_db(b, f, "flat auto of the flatten", o))
    FIGURES[f"deep_{_f}_floor_held"] = lambda b, f=_f: f"{deep_db(b, f, FLOOR, ' (held)'):.1f}"
    FIGURES[f"deep_{_f}_short_held"] = lambda b, f=_f: shown_gain(
        deep_db(b, f, FLOOR, " (held)"), deep_db(b, f, "deep auto", " (held)"))


# --- statements about the figures -------------------------------------------------------

CLAIMS = {}
claim = registrar(CLAIMS)


@claim("bands6_cheapest_40db")
def claim_bands6_cheapest_40db(b):
    """6 bands keep 40 dB at every size; 4 bands do not."""
    keeps = {n: all(blur_db(b, "disk", f"{n} bands (running sums)", s) >= 40 for s in SIZES) for n in (4, 6)}
    return keeps[6] and not keeps[4]


@claim("reduced_exact_below")
def claim_reduced_exact_below(b):
    """The reduced blur is exact (999 dB) at the sizes below 37.5 px."""
    return all(blur_db(b, shape, "reduced 1/N (bilinear)", s) == 999
               for shape in ("disk", "hexagon") for s in ("15", "31"))


@claim("iris_under_40")
def claim_iris_under_40(b):
    """At the largest |k| x range measured, every approximation is under 40 dB."""
    rows = b.rows("iris.csv")
    last = max({r["task"] for r in rows}, key=lambda t: float(t.rsplit(" ", 1)[-1]))
    b.note(f"iris.csv [{last}] psnr_db_tonemapped")
    return all(float(r["psnr_db_tonemapped"]) < 40 for r in rows if r["task"] == last)


@claim("nearest_is_box")
def claim_nearest_is_box(b):
    """Nearest and box give the same result at every factor."""
    return all(rs(b, f"enlarge {e}", "nearest", s, "psnr_db_tonemapped")
               == rs(b, f"enlarge {e}", "box", s, "psnr_db_tonemapped") for e in ("glare", "bokeh") for s in FACTORS)


@claim("budgets_met")
def claim_budgets_met(b):
    """Every budget's worst PSNR over the shots is at least the budget."""
    return all(min(dof_db(b, s, f"layers budget {db} dB" + (" (default)" if db == 40 else "")) for s in SHOTS) >= db
               for db in (30, 40, 50, 60))


# --- the page ---------------------------------------------------------------------------

MARK = re.compile(r"<!--f:([\w.-]+)-->(.*?)<!--/f-->|<!--c:([\w.-]+)-->")
STRIP = re.compile(r"<!--(?:f:[\w.-]+|/f|c:[\w.-]+)-->")


def sentence(lines, i, column):
    """The sentence of lines[i] that holds `column` (markers dropped, spaces collapsed): a
    table row whole, else cut out of its paragraph or list item."""
    if lines[i].lstrip().startswith("|"):
        return " ".join(STRIP.sub("", lines[i]).split())

    def breaks(line):
        return not line.strip() or line.lstrip().startswith(("#", "|", "<!-- "))

    def item(line):
        return line.lstrip().startswith("* ")

    first, last = i, i
    while first > 0 and not item(lines[first]) and not breaks(lines[first - 1]):
        first -= 1
    while last + 1 < len(lines) and not breaks(lines[last + 1]) and not item(lines[last + 1]):
        last += 1
    text = " ".join(lines[first:i] + [lines[i][:column] + "\0" + lines[i][column:]] + lines[i + 1:last + 1])
    before, after = " ".join(STRIP.sub("", text).split()).split("\0")
    before = before.removeprefix("* ")
    start, end = before.rfind(". "), after.find(". ")
    return (before[start + 2:] if start >= 0 else before) + (after[:end + 1] if end >= 0 else after)


def render(page_text, bench_dir, problems=None):
    """The page with its tables and figures from the CSVs; `problems` (a list) gets a
    message for each figure that changes and each claim that no longer holds."""
    bench = Bench(bench_dir)
    out, lines, i = [], page_text.split("\n"), 0
    while i < len(lines):
        line = lines[i]
        m = re.fullmatch(r"<!-- begin table (\S+) -->", line)
        if not m:
            out.append(render_line(lines, i, bench, problems))
            i += 1
            continue
        out.append(line)
        i += 1
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


def render_line(lines, i, bench, problems):
    line = lines[i]
    if "<!--f:" in line and line.count("<!--f:") != line.count("<!--/f-->"):
        raise SystemExit(f"tables.py: line {i + 1}: a figure's '<!--f:NAME-->' needs its '<!--/f-->' on the same line")

    def one(m):
        name = m.group(1) or m.group(3)
        table = FIGURES if m.group(1) else CLAIMS
        if name not in table:
            raise SystemExit(f"tables.py: line {i + 1}: unknown {'figure' if m.group(1) else 'claim'} '{name}'")
        bench.used = []
        result = table[name](bench)
        if m.group(1):
            if problems is not None and result != m.group(2):
                problems.append(f"{i + 1}: figure '{name}': the page says '{m.group(2)}', the CSVs give "
                                f"'{result}'\n    in: {sentence(lines, i, m.start())}\n    from: "
                                + "\n          ".join(bench.used))
            return f"<!--f:{name}-->{result}<!--/f-->"
        if not result and problems is not None:
            problems.append(f"{i + 1}: claim '{name}' ({table[name].__doc__.strip()}) no longer holds: "
                            f"rewrite\n    {sentence(lines, i, m.start())}\n    from: "
                            + "\n          ".join(bench.used))
        return m.group(0)

    return MARK.sub(one, line)


def main(argv):
    if len(argv) not in (3, 4) or (len(argv) == 4 and argv[3] != "--check"):
        raise SystemExit("usage: tables.py PAGE BENCH_DIR [--check]")
    page, bench_dir = argv[1], argv[2]
    with open(page) as f:
        old = f.read()
    problems = []
    new = render(old, bench_dir, problems)
    claims_fail = [p for p in problems if ": claim '" in p.split("\n")[0]]
    if len(argv) == 4:
        if new != old or claims_fail:
            for p in problems:
                print(f"{page}:{p}")
            sys.stdout.writelines(difflib.unified_diff(old.splitlines(True), new.splitlines(True),
                                                       page + " (committed)", page + " (from the CSVs)"))
            print(f"\nFAIL: {page}'s tables or quoted figures differ from {bench_dir}/*.csv"
                  + (", or a claim no longer holds" if claims_fail else "")
                  + f". Regenerate them: /usr/bin/python3 tools/bokeh-bench/tables.py {page} {bench_dir}"
                  + (" and rewrite the sentences named" if claims_fail else ""))
            return 1
        return 0
    with open(page, "w") as f:
        f.write(new)
    for p in claims_fail:
        print(f"{page}:{p}")
    return 1 if claims_fail else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

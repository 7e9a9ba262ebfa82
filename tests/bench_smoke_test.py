#!/usr/bin/env python3
"""bokeh-bench and its chart, end to end, small: the blur task on a small built-in scene
and on a file, then chart.py on its CSV. Checks what the benchmark must give
(columns, an error per case against the exact reference, the peers in the same run, one
chart per task in PNG and SVG) and that bad arguments fail with one line and status 1.
Timings are not checked (they are measured, never asserted).

    bench_smoke_test.py BOKEH_BENCH BOKEHTOOL CHART_PY SCRATCH_DIR
"""

import csv
import math
import os
import re
import shutil
import subprocess
import sys

bench, bokehtool, chart, scratch = sys.argv[1:5]
shutil.rmtree(scratch, ignore_errors=True)
os.makedirs(scratch)
failures = []


def check(ok, what):
    if not ok:
        failures.append(what)
        print("FAILED:", what)


def run(args):
    return subprocess.run(args, capture_output=True, text=True, timeout=600)


# A file frame: a built-in scene written by bokehtool, 200x120 (RGBA+Z: the bench takes RGBA).
plate = os.path.join(scratch, "plate.exr")
r = run([bokehtool, "--scene", "edges:width=200:height=120", "-o", plate])
check(r.returncode == 0, "bokehtool wrote the plate: " + r.stderr)

out_csv = os.path.join(scratch, "blur.csv")
r = run([bench, "--quick", "--size", "240x160", "--reps", "1", "--threads", "2",
         "--scenes", "lights", "--image", plate, "--csv", out_csv])
check(r.returncode == 0, "bokeh-bench ran: " + r.stderr[-2000:])
print(r.stdout[-3000:])

with open(out_csv, newline="") as f:
    reader = csv.reader(f)
    header = next(reader)
    rows = [dict(zip(header, row)) for row in reader]
    f.seek(0)
    widths = {len(row) for row in csv.reader(f)}
check(header == ["task", "method", "peer", "size_px", "threads", "median_ms", "reps",
                 "rmse_linear", "psnr_db_tonemapped", "max_abs_linear"], f"header: {header}")
check(widths == {len(header)}, f"every row has {len(header)} fields: {widths}")

tasks = {row["task"] for row in rows}
for shape in ("box", "disk", "hexagon", "gaussian"):
    check(f"{shape} (lights 240x160)" in tasks, f"rows for {shape} on the lights scene")
    check(f"{shape} (plate.exr)" in tasks, f"rows for {shape} on the file")
for row in rows:
    name = f"{row['task']} / {row['method']} / {row['size_px']}"
    ms = float(row["median_ms"])
    check(ms > 0 and math.isfinite(ms), f"{name}: a time ({row['median_ms']})")
    rmse, psnr, mx = (float(row[c]) for c in ("rmse_linear", "psnr_db_tonemapped", "max_abs_linear"))
    if row["peer"] == "gegl":
        continue  # the peer's own output, reported as it is
    check(all(math.isfinite(v) for v in (rmse, psnr, mx)), f"{name}: finite errors")
    check(0 <= rmse <= mx, f"{name}: RMSE {rmse} <= max error {mx}")
    if "exact" in row["method"]:
        # Exact methods against the brute force: float rounding of the peak at most.
        check(psnr >= 120, f"{name}: exact, PSNR {psnr}")
    if row["method"].startswith("3 parallelograms") or row["method"].startswith("3 boxes"):
        check(mx > 0, f"{name}: an approximation differs from the exact kernel")
peers = {row["peer"] for row in rows}
check("oiio" in peers, "OIIO's convolution runs in the same run")

charts = os.path.join(scratch, "charts")
if subprocess.run(["/usr/bin/python3", "-c", "import matplotlib"], capture_output=True).returncode != 0:
    print("matplotlib is missing (make deps installs python3-matplotlib): the chart is not checked")
    sys.exit(77 if not failures else 1)
r = run(["/usr/bin/python3", chart, out_csv, charts])
check(r.returncode == 0, "chart.py ran: " + r.stderr[-2000:])
for task in tasks:
    check(f"### {task}\n" in r.stdout, f"chart.py printed the front table of {task}")
for task in tasks:
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", task)  # as chart.py names its files
    for ext in ("png", "svg"):
        path = os.path.join(charts, f"{stem}.{ext}")
        check(os.path.isfile(path) and os.path.getsize(path) > 1000, f"chart {path}")

# The deep task's rows against the truth (as bokeh-bench --task deep writes them, which
# needs the test images in ../shared/data, so written here): one chart for every frame, a
# table per frame.
truth_csv = os.path.join(scratch, "deep.csv")
with open(truth_csv, "w") as f:
    f.write("task,method,peer,size_px,threads,median_ms,reps,rmse_linear,psnr_db_tonemapped,max_abs_linear\n")
    for frame, scale in (("deep A", 1.0), ("deep B", 0.1)):
        f.write(f"{frame},truth 64 spp,,0,2,{9000 * scale},1,,55.0,\n")
        for method, ms, db in (("deep auto", 500, 42.0), ("flat auto of the flatten", 130, 38.0)):
            f.write(f"{frame},{method} vs truth,,0,2,{ms * scale},3,0.02,{db},0.5\n")
            f.write(f"{frame},{method} vs truth (mask),,0,2,{ms * scale},3,,{db - 6},\n")
        f.write(f"{frame},flatten,,0,2,{30 * scale},3,,,\n")
r = run(["/usr/bin/python3", chart, truth_csv, charts])
check(r.returncode == 0, "chart.py ran on the truth rows: " + r.stderr[-2000:])
for frame in ("deep A", "deep B"):
    check(f"### {frame}\n" in r.stdout, f"chart.py printed the truth table of {frame}")
check("| deep auto | 500 | 42.0 | 36.0 |" in r.stdout, "the table pairs frame and mask: " + r.stdout)
for ext in ("png", "svg"):
    path = os.path.join(charts, f"deep_truth.{ext}")
    check(os.path.isfile(path) and os.path.getsize(path) > 1000, f"chart {path}")
check(not os.path.exists(os.path.join(charts, "deep_A.png")), "no per-task chart for truth rows")

# Bad arguments: one line naming the argument, status 1, no CSV written.
for args, says in ((["--scenes", "nosuch"], "nosuch"),
                   (["--image", os.path.join(scratch, "missing.exr")], "missing.exr"),
                   (["--frobnicate"], "--frobnicate"),
                   (["--task", "iris", "--image", plate], "--image is for the blur task")):
    bad_csv = os.path.join(scratch, "bad.csv")
    r = run([bench, "--quick", "--size", "64x48", "--reps", "1"] + args + ["--csv", bad_csv])
    check(r.returncode == 1, f"{args}: status {r.returncode}")
    check(says in r.stderr, f"{args}: names it: {r.stderr.strip()}")
    check(not os.path.exists(bad_csv), f"{args}: nothing written")

# The plans task (the flat planner's plans, predicted against measured) and its chart.
plans_csv = os.path.join(scratch, "plans.csv")
r = run([bench, "--task", "plans", "--size", "240x135", "--reps", "1", "--scenes", "lights,edges",
         "--csv", plans_csv])
check(r.returncode == 0, "bokeh-bench --task plans ran: " + r.stderr[-2000:])
with open(plans_csv, newline="") as f:
    plan_rows = list(csv.DictReader(f))
for scene in ("lights", "edges"):
    floor = [p for p in plan_rows if p["scene"] == scene and p["chosen"] == "floor"]
    mine = [p for p in plan_rows if p["scene"] == scene and p["chosen"] != "floor"]
    check(len(floor) == 1 and float(floor[0]["truth_psnr_db"]) > 0, f"{scene}: the two truths' row")
    check(sum(p["chosen"] == "steps" for p in mine) == 1, f"{scene}: the default's row")
    check(sum(p["chosen"] == "predicted" for p in mine) == 1, f"{scene}: planner=predicted's row")
    check(len(mine) > 6, f"{scene}: a grid of plans ({len(mine)} rows)")
    check(all(float(p["psnr_db"]) > 0 and float(p["median_ms"]) > 0 and float(p["truth_psnr_db"]) > 0
              for p in mine), f"{scene}: measured, against the reference and the truth")
plans_chart = os.path.join(os.path.dirname(chart), "plans_chart.py")
r = run([sys.executable, plans_chart, plans_csv, charts])
check(r.returncode == 0, "plans_chart.py ran: " + r.stderr[-2000:])
check(os.path.exists(os.path.join(charts, "plans.png")), "plans.png written")
check("lights: default (steps" in r.stdout, "plans_chart.py printed the default's figures: " + r.stdout)
check("lights: against the truth: default" in r.stdout, "and against the truth: " + r.stdout)

if failures:
    print(f"{len(failures)} check(s) failed")
    sys.exit(1)
print("bench smoke test passed")

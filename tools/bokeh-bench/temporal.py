#!/usr/bin/python3
"""How steadily each defocus method changes over a shot: a focus pull and a dolly, each
method's figure beside the thin-lens truth's.

The figure of a sequence of frames f_i (R, G, B after the tone map x / (1 + |x|)) is

    sqrt( mean_i <d2_i, d2_i> / mean_i <d1_i, d1_i> ),  d1_i = f_(i+1) - f_i,
                                                       d2_i = f_(i+2) - 2 f_(i+1) + f_i,

<,> the mean over pixels and channels: 0 for frames changing at a steady rate, about 1
and more when they step. The truth is rendered twice with independent ray seeds A and B
and its products are taken across them (<d_A, d_B>): the rays' noise, independent between
A and B, averages out, so its figure is the noiseless truth's (a noisy truth alone scores
sqrt(3) for its noise). Per frame, the worst and the median of the same ratio (d2_i
against the mean of d1_i and d1_(i+1)) are written too.

Methods: the default, 18 layers, the reference and gather, and lens character on the
default: highlights drawn as sprites with the lens off (the aperture's disk) and with an
achromat (lens=achromat: its aberrations at focus and on the highlights). The truths are of
the plain aperture.

Shots:
  plane-pull   a 320 x 180 slanted textured plane (1/Z linear from 1 m to 10 m), 85 mm
               f/1.4, focus 1.5 m -> 6 m evenly in 1/distance; truth: rays through the
               plane's deep image (256 a pixel, two seeds)
  plane-dolly  the same plane moved 0 -> 0.5 m towards the camera (every depth changes),
               focus held at 3 m; truth as above
  facing-cross the plane's texture facing the camera at 3 m, focus moved so its CoC runs
               -3 -> +3 px evenly (not in the default shots): how the picture starts to
               blur; truth as above, and again with the rays over each pixel's area
  lights-pull  the built-in lights scene (240 x 135: HDR lights over a textured floor) at
               its f/1.27, focus 5 m -> 7 m; truth: the scene's geometric truth (--spp a
               pixel, two seeds; its figure is noisy at that count: see --spp)
  lights-dolly the lights scene's depths all moved 0 -> 1 m nearer, focus held at 6 m
               (the picture held: a defocus-only dolly); no truth (the scene's camera
               cannot move)

    temporal.py [--module-dir build/python] [--frames 24] [--spp 1024] [--csv FILE]
                [--chart FILE] [--shots plane-pull,...] [--plane-width 320] [--columns 0]

--columns K also prints each plane shot's figure over bands of K columns of the frame (the
plane's near side on the left, its far side on the right): where in depth a method is less
steady than the truth.
"""
import argparse
import csv
import sys
import time

import numpy as np

ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("--module-dir", default="build/python")
ap.add_argument("--frames", type=int, default=24)
ap.add_argument("--spp", type=int, default=1024, help="rays a pixel of the lights scene's truth")
ap.add_argument("--csv")
ap.add_argument("--chart")
ap.add_argument("--shots", default="plane-pull,plane-dolly,lights-pull,lights-dolly")
ap.add_argument("--plane-width", type=int, default=320, help="the plane shots' width (height 9/16 of it)")
ap.add_argument("--columns", type=int, default=0, help="also print the plane shots' figure over bands of this many columns")
args = ap.parse_args()
sys.path.insert(0, args.module_dir)
import openbokeh as ob  # noqa: E402

METHODS = [("default", {}), ("layers 18", {"method": "layers", "layers": "18"}),
           ("reference", {"method": "reference"}), ("gather", {"method": "gather"}),
           ("sprites, lens off", {"highlights": "1"}), ("achromat", {"lens": "achromat"})]
n = args.frames


def tone_mapped(img):
    a = ob.to_array(img[0] if isinstance(img, tuple) else img).astype(np.float64)[..., :3]
    return a / (1.0 + np.abs(a))


def figure(a, b, cols=slice(None)):
    """(overall, worst frame, median frame) of the sequences a and b (the same for a method),
    over the columns `cols` of the frames."""
    e1 = np.array([np.mean(((a[i + 1] - a[i]) * (b[i + 1] - b[i]))[:, cols]) for i in range(n - 1)])
    e2 = np.array([np.mean(((a[i + 2] - 2 * a[i + 1] + a[i]) * (b[i + 2] - 2 * b[i + 1] + b[i]))[:, cols])
                   for i in range(n - 2)])
    # Frames that do not change (a facing plane in focus) have no figure of their own.
    per = [np.sqrt(max(e2[i], 0.0) / (0.5 * (e1[i] + e1[i + 1]))) for i in range(n - 2) if e1[i] + e1[i + 1] > 0]
    return np.sqrt(max(e2.mean(), 0.0) / e1.mean()), max(per), float(np.median(per))


def slanted_plane(w, h):
    x = np.arange(w)[None, :].repeat(h, 0)
    y = np.arange(h)[:, None].repeat(w, 1)
    tex = np.random.default_rng(3).random((h // 3 + 1, w // 3 + 1))
    img = np.zeros((h, w, 5), np.float32)
    img[..., 0] = np.where(((x // 6) + (y // 6)) % 2 == 0, 0.9, 0.1)
    img[..., 1] = 0.5 + 0.4 * np.sin(0.5 * y)
    img[..., 2] = 0.3 + 0.6 * tex[y // 3, x // 3]
    img[..., 3] = 1.0
    img[..., 4] = 1.0 / (1.0 + (0.1 - 1.0) * x / (w - 1))
    return img


def pull(near, far):
    return [1.0 / (1.0 / near + (1.0 / far - 1.0 / near) * i / (n - 1)) for i in range(n)]


def shot_frames(shot):
    """[(focus_m, image array or ImageBuf, truth callable(seed) or None)] for each frame, and lens kwargs."""
    if shot.startswith("plane") or shot == "facing-cross":
        base = slanted_plane(args.plane_width, args.plane_width * 9 // 16)
        lens = dict(focal="85", fstop="1.4", sensor="36", unit="m")
        # CoC px of depth 3 m at focus f (m): (3 - f) / 3 * k / (1000 f - 85), k = 85^2 / (1.4 eps),
        # eps the sensor's mm a pixel; solved for f.
        k = 85.0 ** 2 / (1.4 * 36.0 / args.plane_width)
        frames = []
        for i in range(n):
            img = base.copy()
            if shot == "plane-pull":
                focus = pull(1.5, 6.0)[i]
            elif shot == "facing-cross":
                c = -3.0 + 6.0 * i / (n - 1)
                focus = (3.0 * k + 255.0 * c) / (3000.0 * c + k)
                img[..., 4] = 3.0
            else:
                focus = 3.0
                img[..., 4] -= 0.5 * i / (n - 1)
            deep = ob.deepen(img)
            frames.append((focus, img, lambda seed, d=deep, f=focus, pixel="centre": ob.defocus(
                d, method="truth", spp="256", seed=str(seed), focus=str(f), pixel=pixel, **lens)))
        return frames, lens
    sharp = ob.scene("lights", width=240, height=135)
    lens = dict(fstop="1.27", focal="50", sensor="36")
    frames = []
    for i in range(n):
        if shot == "lights-pull":
            focus = pull(5.0, 7.0)[i]
            frames.append((focus, sharp, lambda seed, f=focus: ob.scene(
                "lights", width=240, height=135, output="truth", focus=str(f), fstop=1.27,
                spp=args.spp, rayseed=seed)))
        else:
            img = ob.to_array(sharp).copy()
            img[..., 4] -= 1.0 * i / (n - 1)
            frames.append((6.0, img, None))
    return frames, lens


rows = []
for shot in args.shots.split(","):
    frames, lens = shot_frames(shot)
    # Timed frame by frame, every method in turn (interleaved rounds: a slow phase of the
    # machine falls on all alike), after one untimed call of each (the warm-up); `seconds` is
    # the sum of the sequence's defocus calls, `median_frame_s` their median.
    for _, opts in METHODS:
        ob.defocus(frames[0][1], focus=str(frames[0][0]), **lens, **opts)
    seqs = {name: [] for name, _ in METHODS}
    secs = {name: [] for name, _ in METHODS}
    for f, img, _ in frames:
        for name, opts in METHODS:
            t = time.perf_counter()
            out = ob.defocus(img, focus=str(f), **lens, **opts)
            secs[name].append(time.perf_counter() - t)
            seqs[name].append(tone_mapped(out))
    for name, _ in METHODS:
        overall, worst, median = figure(seqs[name], seqs[name])
        rows.append(dict(shot=shot, method=name, figure=overall, worst=worst, median=median,
                         seconds=sum(secs[name]), median_frame_s=float(np.median(secs[name]))))
        print(f"{shot:13s} {name:17s} {overall:6.3f}  worst {worst:6.3f}  median {median:6.3f}  "
              f"({sum(secs[name]):.1f} s)", flush=True)
    if frames[0][2] is not None:
        t = time.time()
        a = [tone_mapped(tr(1)) for _, _, tr in frames]
        b = [tone_mapped(tr(2)) for _, _, tr in frames]
        overall, worst, median = figure(a, b)
        rows.append(dict(shot=shot, method="truth", figure=overall, worst=worst, median=median, seconds=time.time() - t))
        print(f"{shot:13s} {'truth':17s} {overall:6.3f}  worst {worst:6.3f}  median {median:6.3f}  ({time.time() - t:.1f} s)",
              flush=True)
    if shot == "facing-cross":
        pa = [tone_mapped(tr(1, pixel="area")) for _, _, tr in frames]
        pb = [tone_mapped(tr(2, pixel="area")) for _, _, tr in frames]
        overall, worst, median = figure(pa, pb)
        rows.append(dict(shot=shot, method="truth (pixel area)", figure=overall, worst=worst, median=median))
        print(f"{shot:13s} {'truth (area)':17s} {overall:6.3f}  worst {worst:6.3f}  median {median:6.3f}", flush=True)
    if args.columns > 0 and shot.startswith("plane"):
        width = seqs[METHODS[0][0]][0].shape[1]
        for c0 in range(0, width, args.columns):
            cols = slice(c0, min(width, c0 + args.columns))
            line = " ".join(f"{name} {figure(seqs[name], seqs[name], cols)[0]:.3f}" for name, _ in METHODS)
            if frames[0][2] is not None:
                line += f" truth {figure(a, b, cols)[0]:.3f}"
            print(f"{shot:13s} columns {c0:4d}-{cols.stop - 1:4d}: {line}", flush=True)

if args.csv:
    with open(args.csv, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["shot", "method", "figure", "worst", "median", "seconds", "median_frame_s"])
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.4f}" if isinstance(v, float) else v) for k, v in r.items()})

if args.chart:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    shots = list(dict.fromkeys(r["shot"] for r in rows))
    names = [m for m, _ in METHODS] + ["truth"]
    colours = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "black"]
    fig, ax = plt.subplots(figsize=(10, 4.5))
    width = 0.8 / len(names)
    for k, (m, c) in enumerate(zip(names, colours)):
        xs, ys, lo, hi = [], [], [], []
        for s, shot in enumerate(shots):
            r = [r for r in rows if r["shot"] == shot and r["method"] == m]
            if r:
                xs.append(s + (k - len(names) / 2 + 0.5) * width)
                ys.append(r[0]["figure"])
                lo.append(r[0]["figure"] - min(r[0]["figure"], r[0]["median"]))
                hi.append(max(0.0, r[0]["worst"] - r[0]["figure"]))
        ax.bar(xs, ys, width, color=c, label=m, yerr=[lo, hi], capsize=2, error_kw=dict(lw=0.8))
    ax.set_xticks(range(len(shots)))
    ax.set_xticklabels(shots)
    ax.set_ylabel("rms second / first difference\n(bar: whole shot; whisker: median .. worst frame)")
    ax.set_title(f"How steadily each method changes over {n} frames (lower is steadier; the truth's is the aim)")
    ax.legend(fontsize=8, ncol=4)
    fig.tight_layout()
    fig.savefig(args.chart, dpi=110)

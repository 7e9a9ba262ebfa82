#!/usr/bin/env python3
"""Merge two deep images and flatten them, as `bokehtool A B --deepmerge --flatten`.

    PYTHONPATH=build/python /usr/bin/python3 examples/python/deep_merge_flatten.py [OUTDIR] [A.exr B.exr]

Without files it makes its two deep inputs: a built-in scene made deep (one sample a
pixel), and a half-transparent card in front of it. Writes OUTDIR/merged.exr (deep) and
OUTDIR/flat.exr. Deep images are OpenImageIO.ImageBuf objects: deep data is not an array.
"""
import os
import sys

import numpy as np

import openbokeh

out_dir = sys.argv[1] if len(sys.argv) > 1 else "out"
os.makedirs(out_dir, exist_ok=True)

if len(sys.argv) > 3:
    deep_a, deep_b = openbokeh.read_image(sys.argv[2]), openbokeh.read_image(sys.argv[3])
else:
    deep_a = openbokeh.deepen(openbokeh.scene("edges", width=320, height=180))
    # A red card at 2 m, half transparent (premultiplied), over the left half of the frame.
    card = np.zeros((180, 320, 5), np.float32)
    card[:, :160] = (0.5, 0.0, 0.0, 0.5, 2.0)
    deep_b = openbokeh.deepen(card)  # channels R, G, B, A, Z by count

merged = openbokeh.deep_merge([deep_a, deep_b])  # hidden samples kept (cull=True drops them)
openbokeh.write_image(merged, os.path.join(out_dir, "merged.exr"))
flat = openbokeh.flatten(merged)
openbokeh.write_image(flat, os.path.join(out_dir, "flat.exr"))

samples = merged.deepdata()
total = sum(samples.samples(p) for p in range(samples.pixels))
print(f"merged: {total} samples over {samples.pixels} pixels; flat: {flat.spec().channelnames}")

#!/usr/bin/env python3
"""Defocus a built-in scene from Python, as `bokehtool --scene lights --defocus:focus=6:fstop=2`.

    PYTHONPATH=build/python /usr/bin/python3 examples/python/defocus_scene.py [OUTDIR]

Writes OUTDIR/sharp.exr (the scene, RGBA + Z) and OUTDIR/defocused.exr, and prints what the
defocus decided. The same call takes a numpy array (H, W, C) float32.
"""
import os
import sys

import numpy as np

import openbokeh

out_dir = sys.argv[1] if len(sys.argv) > 1 else "out"
os.makedirs(out_dir, exist_ok=True)

# An OpenImageIO.ImageBuf: R, G, B, A, Z (metres), the camera in its metadata.
sharp = openbokeh.scene("lights", width=640, height=360)
openbokeh.write_image(sharp, os.path.join(out_dir, "sharp.exr"))

# Options are bokehtool's, as keyword arguments; the focal length and film back come from
# the scene's metadata. The GIL is released while it works.
defocused, report = openbokeh.defocus(sharp, focus=6, fstop=2, kernel="hex", rotation=15)
openbokeh.write_image(defocused, os.path.join(out_dir, "defocused.exr"))
print(f"defocus: {report.summary}")
print(f"  {len(report.layer_coc_px)} layers, CoC {report.min_coc_px:.1f} .. {report.max_coc_px:.1f} px")

# As arrays: the data window, float32 (H, W, C).
pixels = openbokeh.to_array(defocused)
print(f"  result {pixels.shape}, mean R {np.mean(pixels[..., 0]):.4f}")

#!/usr/bin/env python3
"""Look at a lens's bokeh from Python, as `bokehtool --bokeh:lens=achromat:... COC`.

    PYTHONPATH=build/python /usr/bin/python3 examples/python/lens_bokeh.py [OUTDIR]

Writes OUTDIR/front.exr and OUTDIR/back.exr (one achromat's point-spread function in front
of and behind focus, with exact diffraction fringes; the lens's spherical aberration makes
the two rims differ, and the print says how much light each holds near its edge) and
OUTDIR/sheet.exr (its bokeh across defocus
and field position), and prints where each PSF's light sits. A PSF is an ImageBuf whose
data window is centred on 0, 0, ready for `bokehtool IMAGE PSF.exr --convolve`.
"""
import os
import sys

import numpy as np

import openbokeh

out_dir = sys.argv[1] if len(sys.argv) > 1 else "out"
os.makedirs(out_dir, exist_ok=True)

lens = dict(lens="achromat", diffraction="exact", kernel="polygon", blades=7, curvature=0.5)
for name, coc in (("front", -48), ("back", 48)):
    psf = openbokeh.bokeh(coc, **lens)
    openbokeh.write_image(psf, os.path.join(out_dir, name + ".exr"))
    rgb = openbokeh.to_array(psf)[..., :3]
    h, w = rgb.shape[:2]
    y, x = np.mgrid[0:h, 0:w]
    r = np.hypot(x - (w - 1) / 2, y - (h - 1) / 2)
    luminance = rgb @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    rim = luminance[r > 0.8 * abs(coc) / 2].sum() / luminance.sum()
    print(f"{name}: CoC {coc} px, {w} x {h} px, energy {rgb.sum(axis=(0, 1)).round(4)}, "
          f"{100 * rim:.0f} % of the light in the outer fifth of the radius")

sheet = openbokeh.bokeh(40, sheet=True, **lens)
openbokeh.write_image(sheet, os.path.join(out_dir, "sheet.exr"))

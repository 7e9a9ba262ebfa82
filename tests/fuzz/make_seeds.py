#!/usr/bin/python3
"""Seed inputs for the read fuzzer, made here (no data files needed): small EXRs as
scanlines (zip, piz, none), tiles, two parts and deep (scanline and tiled), and a PNG.
Usage: make_seeds.py DIR"""
import os
import sys

import OpenImageIO as oiio


def flat(w, h, nch):
    spec = oiio.ImageSpec(w, h, nch, oiio.HALF)
    buf = oiio.ImageBuf(spec)
    for y in range(h):
        for x in range(w):
            buf.setpixel(x, y, [((x * 7 + y * 3 + c) % 11) / 10.0 for c in range(nch)])
    return buf


def write(buf, path, **attrs):
    for k, v in attrs.items():
        buf.specmod().attribute(k, v)
    if not buf.write(path):
        sys.exit(f"make_seeds: {path}: {buf.geterror()}")


def deep(w, h, tiles):
    spec = oiio.ImageSpec(w, h, 5, oiio.FLOAT)
    spec.channelnames = ("R", "G", "B", "A", "Z")
    spec.deep = True
    spec.attribute("compression", "zips")
    if tiles:
        spec.tile_width, spec.tile_height = 8, 8
    buf = oiio.ImageBuf(spec)
    if tiles:
        buf.set_write_tiles(8, 8)
    for y in range(h):
        for x in range(w):
            n = (x + y) % 3
            buf.set_deep_samples(x, y, 0, n)
            for s in range(n):
                for c, v in enumerate((0.2 * s, 0.1, 0.3, 0.5, 1.0 + s + 0.1 * x)):
                    buf.set_deep_value(x, y, 0, c, s, v)
    return buf


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    write(flat(16, 12, 4), f"{out}/scanline_zip.exr", compression="zip")
    write(flat(16, 12, 4), f"{out}/scanline_piz.exr", compression="piz")
    write(flat(16, 12, 3), f"{out}/scanline_none.exr", compression="none")
    tiled = flat(16, 12, 4)
    tiled.set_write_tiles(8, 8)
    write(tiled, f"{out}/tiled.exr", compression="zip")
    png = flat(16, 12, 4)
    write(png, f"{out}/rgba.png")
    write(deep(12, 8, False), f"{out}/deep_scanline.exr")
    write(deep(12, 8, True), f"{out}/deep_tiled.exr")
    # Two parts.
    a, b = flat(16, 12, 4), flat(8, 8, 3)
    b.specmod().full_width, b.specmod().full_height = 16, 12  # parts share a display window
    specs = [a.spec(), b.spec()]
    o = oiio.ImageOutput.create(f"{out}/two_parts.exr")
    if not o.open(f"{out}/two_parts.exr", specs):
        sys.exit("make_seeds: two_parts.exr: " + o.geterror())
    a.write(o)
    o.open(f"{out}/two_parts.exr", specs[1], "AppendSubimage")
    b.write(o)
    o.close()


main()

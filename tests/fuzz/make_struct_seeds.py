#!/usr/bin/python3
"""Seed inputs for the two structured fuzz targets, made here:
* deep: byte strings as fuzz_deep.cpp reads them (size, channel kind, sample counts,
  then value selectors): every channel kind, points and volumes, coincident depths;
* kernel_image: raw kernels (mode byte even: sizes, channels, value selectors) and the
  read fuzzer's committed corpus files as kernel files (mode byte odd), resized or not.
Usage: make_struct_seeds.py FUZZ_DIR   (writes FUZZ_DIR/corpus/deep, .../kernel_image)"""
import hashlib
import os
import sys


def put(directory, data):
    os.makedirs(directory, exist_ok=True)
    with open(os.path.join(directory, hashlib.sha1(data).hexdigest()), "wb") as f:
        f.write(data)


def main():
    root = sys.argv[1]
    deep = os.path.join(root, "corpus", "deep")
    # size byte: w = 1 + s % 4, h = 1 + (s >> 2) % 3, 0x40 = offset window; kind byte:
    # bit 0 half colour, (kind >> 1) % 3 channel set, 8 ZBack, 16 id channel.
    for size in (0x00, 0x05, 0x0b, 0x45):
        for kind in (0x00, 0x01, 0x02, 0x04, 0x08, 0x0a, 0x18, 0x19):
            body = bytearray([size, kind])
            if size & 0x40:
                body += bytes([2, 5])
            npx = (1 + size % 4) * (1 + (size >> 2) % 3)
            for image in range(2):
                counts = [(p + image + kind) % 4 for p in range(npx)]
                body += bytes(counts)
                for n in counts:
                    for s in range(n):
                        nch = {0: 4, 1: 6, 2: 1}[(kind >> 1) % 3]
                        body += bytes([(s + image) % 5])            # Z: 1, 2, 1, 3, 2
                        body += bytes([(s * 3 + kind) % 10] * nch)  # alphas, colours
                        if kind & 8:
                            body += bytes([s % 3])                  # ZBack = Z + 0..2
                        if kind & 16:
                            body += bytes([s])
            body += bytes([0x10 + (kind % 4)])  # slice range
            put(deep, bytes(body))

    kern = os.path.join(root, "corpus", "kernel_image")
    for how in (0, 1, 2, 5, 6, 9, 18):
        for w, h, nch in ((1, 1, 1), (3, 3, 1), (5, 3, 3), (4, 4, 4), (9, 9, 2)):
            vals = bytes([(i * 7) % 7 for i in range(w * h * nch)])  # weights 1, 0, 0.5, 2, 1, 0.25, -1
            put(kern, bytes([0, how, 0]) + bytes([w - 1, h - 1, nch - 1]) + vals)
            put(kern, bytes([0, how, 0x80 | 0x1b]) + bytes([w - 1, h - 1, nch - 1]) + vals)
    files = os.path.join(root, "corpus", "read_image")
    for i, name in enumerate(sorted(os.listdir(files))[:20]):
        with open(os.path.join(files, name), "rb") as f:
            data = f.read()
        if len(data) < 60000:
            put(kern, bytes([1, i % 32, 0x80 | 0x12 if i % 2 else 0]) + data)
    print(f"seeds in {deep} and {kern}")


main()

#!/bin/bash
# The pictures of the user guide, from the built-in scenes. Run from the project's root
# after a build: docs/images/make_images.sh [build/bin/bokehtool]
# bokehtool makes every image; oiiotool only cuts and tiles them into one picture.
set -euo pipefail
tool=${1:-build/bin/bokehtool}
out=docs/images
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# The demo's scene and its depth of field (make demo), both frames side by side, 480 px each.
"$tool" -q --scene lights -o "$tmp/sharp.exr" --defocus:focus=6:fstop=2 -o "$tmp/dof.exr"
"$tool" -q "$tmp/sharp.exr" --ch R,G,B --resize 480x270 -o "$tmp/sharp.png"
"$tool" -q "$tmp/dof.exr" --ch R,G,B --resize 480x270 -o "$tmp/dof.png"
oiiotool "$tmp/sharp.png" "$tmp/dof.png" --mosaic:pad=4 2x1 -o "$out/defocus.png"
"$tool" -q "$tmp/sharp.exr" --defocus:focus=6:fstop=2:output=focalplane --resize 480x270 \
    -o "$out/focalplane.png"

# Four kernels of 31 px on the same 320x180 crop of the full-resolution frame.
crop=320x180+1040+320
for k in disk hex polygon:blades=7:curvature=0.3:rotation=10 gaussian; do
    name=${k%%:*}
    "$tool" -q "$tmp/sharp.exr" --ch R,G,B --blur:kernel=$k 31 -o "$tmp/k_$name.png"
    oiiotool "$tmp/k_$name.png" --cut $crop -o "$tmp/c_$name.png"
done
oiiotool "$tmp/c_disk.png" "$tmp/c_hex.png" "$tmp/c_polygon.png" "$tmp/c_gaussian.png" \
    --mosaic:pad=4 2x2 -o "$out/kernels.png"
ls -l "$out"/*.png

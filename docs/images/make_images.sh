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

# Lens character (docs/optics.md): contact sheets of three lens designs with fringes and
# onion rings, 9 defocus columns (front .. focus .. back) x 4 field rows (centre .. corner),
# and the achromat's beam map. Each PSF is scaled to its own peak.
for lens in uncorrected achromat apochromat:chromatic=10; do
    name=${lens%%:*}
    "$tool" -q --bokeh:lens=$lens:fstop=1.4:diffraction=exact:onion=0.15:catseye=0.5:kernel=polygon:blades=9:curvature=0.5:sheet=1 \
        60 -o "$out/bokeh_$name.png"
done
"$tool" -q --bokeh:lens=achromat:fstop=1.4:map=1 40 -o "$out/beam_map_achromat.png"
# Lateral colour across the field (docs/methods/distortion.md).
"$tool" -q --bokeh:sheet=1:lens=achromat:lateralr=0.004:lateralb=-0.004:columns=5:rows=3:size=96 40 \
    -o "$out/bokeh_lateral.png"

# Flat silhouettes (docs/methods/disocclusion.md): a 150 px crop of a defocused foreground's
# edge, 2x, in edges (the near orange panel over the in-focus checker) and lights (the post
# over the floor), at 960x540: sharp, the thin-lens truth (256 rays), the flat defocus with
# fill=foreground, fill=smooth (the default) and fill=mirror, and the deep defocus.
for s in edges:3:1.06:645:180 lights:6:1.27:105:300; do
    IFS=: read -r name focus fstop cx cy <<< "$s"
    scene=$name:width=960:height=540
    lens=focus=$focus:fstop=$fstop
    "$tool" -q --scene $scene -o "$tmp/s_sharp.exr"
    "$tool" -q --scene $scene:output=truth:spp=256 -o "$tmp/s_truth.exr"
    "$tool" -q --scene $scene:output=deep --defocus:$lens -o "$tmp/s_deep.exr"
    for fill in foreground smooth mirror; do
        "$tool" -q "$tmp/s_sharp.exr" --defocus:$lens:fill=$fill -o "$tmp/s_$fill.exr"
    done
    for v in sharp truth foreground smooth mirror deep; do
        "$tool" -q "$tmp/s_$v.exr" --ch R,G,B -o "$tmp/s_$v.png"
        oiiotool "$tmp/s_$v.png" --cut 150x150+$cx+$cy --resize 300x300 -o "$tmp/${name}_$v.png"
    done
done
oiiotool "$tmp"/edges_{sharp,truth,foreground,smooth,mirror,deep}.png \
    "$tmp"/lights_{sharp,truth,foreground,smooth,mirror,deep}.png --mosaic:pad=4 6x2 -o "$out/silhouettes.png"

# Lens distortion (docs/methods/distortion.md): the scene, distorted (barrel k1 = -0.15 with
# lateral colour), undistorted back, and the distortion's STMap (s in red, t in green).
"$tool" -q --scene lights:width=480:height=270 -o "$tmp/d_sharp.exr"
"$tool" -q "$tmp/d_sharp.exr" --lensdistort:k1=-0.15:k2=0.02:lateralr=0.004:lateralb=-0.004 -o "$tmp/d_dist.exr"
"$tool" -q "$tmp/d_dist.exr" --lensdistort:k1=-0.15:k2=0.02:lateralr=0.004:lateralb=-0.004:direction=undistort \
    -o "$tmp/d_back.exr"
"$tool" -q "$tmp/d_sharp.exr" --lensdistort:k1=-0.15:k2=0.02:output=stmap --ch R,G,B=0 -o "$tmp/d_stmap.exr"
for v in sharp dist back stmap; do
    "$tool" -q "$tmp/d_$v.exr" --ch R,G,B -o "$tmp/d_$v.png"
done
oiiotool "$tmp/d_sharp.png" "$tmp/d_dist.png" "$tmp/d_back.png" "$tmp/d_stmap.png" --mosaic:pad=4 2x2 \
    -o "$out/distortion.png"

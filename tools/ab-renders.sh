#!/usr/bin/env bash
# ab-renders.sh — the A/B render set for refactoring: renders a fixed set of images (the
# demo's commands, every defocus method and option family, deep nodes and deep defocus,
# every blur method and kernel family, every enlargement filter, --bokeh's lens effects,
# the scene truth) with two bokehtool builds and compares them: byte for byte, else pixel
# for pixel (idiff -fail 0; a recorded command line may differ). A change that should not
# move a pixel is checked by it.
#   tools/ab-renders.sh OLD_BOKEHTOOL NEW_BOKEHTOOL [WORKDIR]
# Images from ../shared/data (test images kept beside the repository) join the set when
# the folder is there. Exit status 1 when any image differs.
# Each bokehtool must come from its own build tree (or install): a build-tree bokehtool and
# its plugins load the library of the tree they were built in (absolute RPATH), so a copy
# of an old build's bin/ beside a newer build renders with the newer library.
set -uo pipefail
old=$(realpath "$1"); new=$(realpath "$2"); work=${3:-$(mktemp -d)}
data=$(cd "$(dirname "$0")/../.." && pwd)/shared/data
export SOURCE_DATE_EPOCH=0
unset BOKEH_PLUGIN_PATH

render() {  # render BOKEHTOOL DIR
    local T=$1 O=$2 D=$data PSEUDO
    mkdir -p "$O" && cd "$O" || return 1
    # diffraction=pseudo is the pseudo-diffraction map's name; older builds called it seed.
    PSEUDO=pseudo; "$T" --help --bokeh 2>/dev/null | grep -q "off|exact|seed" && PSEUDO=seed
    local LRV RDI
    LRV=$(find "$D" -name "LowResLeftView*.exr" 2>/dev/null | head -1)
    RDI=$D/gaffer/representativeDeepImage.exr
    run() { local n=$1; shift; "$T" --threads 2 "$@" >/dev/null 2>"$n.err" || echo "render $n failed: $(head -c 300 "$n.err")"; }
    run sharp --scene lights:width=480:height=270 -o sharp.exr
    run edges --scene edges:width=480:height=270 -o edges.exr
    run demo  sharp.exr --defocus:focus=6:fstop=2 -o demo.exr
    run focal sharp.exr --defocus:focus=6:fstop=2:output=focalplane -o focal.exr
    run coc   sharp.exr --defocus:focus=6:fstop=2:output=coc -o coc.exr
    run lens  sharp.exr --defocus:focus=6:fstop=2:lens=achromat:diffraction=exact:onion=0.15 -o lens.exr
    run sheet --bokeh:lens=achromat:fstop=1.4:diffraction=exact:onion=0.15:catseye=0.5:sheet=1 40 -o sheet.exr
    run bokeh1 --bokeh:fstop=2:lens=uncorrected:kernel=polygon:blades=7:curvature=0.3 25 -o bokeh1.exr
    run layers sharp.exr --defocus:focus=6:fstop=1.4:method=layers -o layers.exr
    run layers18 sharp.exr --defocus:focus=6:fstop=1.4:layers=18 -o layers18.exr
    run gather sharp.exr --defocus:focus=6:fstop=1.4:method=gather -o gather.exr
    run ref   sharp.exr --defocus:focus=6:fstop=2:method=reference -o ref.exr
    run views sharp.exr --defocus:focus=6:fstop=2:views=2 -o views.exr
    run poly  edges.exr --defocus:focus=3:fstop=1.4:kernel=polygon:blades=6:rotation=15 -o poly.exr
    run sprites sharp.exr --defocus:focus=6:fstop=1.4:lens=apochromat:catseye=0.4:supersample=2 -o sprites.exr
    run disk  sharp.exr --blur:kernel=disk 21x21 -o disk.exr
    run diskf sharp.exr --blur:kernel=disk:method=fast 61x61 -o diskf.exr
    run hex   sharp.exr --blur:kernel=hex 31x31 -o hex.exr
    run polyb sharp.exr --blur:kernel=polygon:blades=5:curvature=0.2 25x25 -o polyb.exr
    run gauss sharp.exr --blur 15x9 -o gauss.exr
    run fft   sharp.exr --blur:kernel=disk:method=fft 41x41 -o fft.exr
    run resize sharp.exr --resize 311x177 -o resize.exr
    run enlarge sharp.exr --reduce 3 --enlarge 3 -o enlarge.exr
    run truth --scene lights:width=160:height=90:output=truth:spp=64:focus=6:fstop=2 -o truth.exr 
    if [ -n "$LRV" ]; then
    run deepdef $LRV --defocus:focus=5:fstop=2 -o deepdef.exr
    run deepdefv $LRV --defocus:focus=5:fstop=2:views=2 -o deepdefv.exr
    run deeptruth $LRV --defocus:focus=5:fstop=2:method=truth:spp=16 -o deeptruth.exr
    run flat $LRV --flatten -o flat.exr
    run deepref $LRV --defocus:focus=5:fstop=2:method=reference -o deepref.exr
    run deeplens $LRV --defocus:focus=5:fstop=1.4:lens=achromat:catseye=0.3 -o deeplens.exr
    run deepout $LRV --defocus:focus=5:fstop=2:output=deep -o deepout.exr
    run deepss $LRV --defocus:focus=5:fstop=2:supersample=2:lens=apochromat -o deepss.exr
    fi
    [ -f "$RDI" ] && run rdi $RDI --defocus:focus=20:fstop=2 -o rdi.exr
    [ -f "$RDI" ] && run rdiflat $RDI --deeptidy --flatten -o rdiflat.exr
    [ -f "$RDI" ] && run merge $RDI $RDI --deepmerge -o merge.exr
    run scatref sharp.exr --defocus:focus=6:fstop=2:method=reference:lens=achromat -o scatref.exr
    run iris sharp.exr --defocus:focus=6:fstop=2:iris=0.05 -o iris.exr
    run bloom sharp.exr --defocus:focus=6:fstop=2:bloomgain=2:zdilate=2 -o bloom.exr
    [ -f "$RDI" ] && run holdout $RDI $RDI --deepslice 10 1e9 --deepholdout --flatten -o holdout.exr
    [ -f "$RDI" ] && run slice $RDI --deepslice 5 30 -o slice.exr
    run en_catmull-rom sharp.exr --reduce 4 --enlarge:filter=catmull-rom:border=mirror 3.7 -o en_catmull-rom.exr
    run en_lanczos3 sharp.exr --reduce 4 --enlarge:filter=lanczos3:border=mirror 3.7 -o en_lanczos3.exr
    run en_gaussian sharp.exr --reduce 4 --enlarge:filter=gaussian:border=mirror 3.7 -o en_gaussian.exr
    run en_box sharp.exr --reduce 4 --enlarge:filter=box:border=mirror 3.7 -o en_box.exr
    run en_reduced-blur sharp.exr --reduce 4 --enlarge:filter=reduced-blur:border=mirror 3.7 -o en_reduced-blur.exr
    run en_upscale-blur sharp.exr --reduce 4 --enlarge:filter=upscale-blur:border=mirror 3.7 -o en_upscale-blur.exr
    run en_upscale-blur-fused sharp.exr --reduce 4 --enlarge:filter=upscale-blur-fused:border=mirror 3.7 -o en_upscale-blur-fused.exr
    run en_upscale-blur-2stage sharp.exr --reduce 4 --enlarge:filter=upscale-blur-2stage:border=mirror 3.7 -o en_upscale-blur-2stage.exr
    run en_bspline sharp.exr --reduce 4 --enlarge:filter=bspline:border=mirror 3.7 -o en_bspline.exr
    run en_nearest sharp.exr --reduce 4 --enlarge:filter=nearest:border=mirror 3.7 -o en_nearest.exr
    run rs_black sharp.exr --resize:filter=lanczos3 700x300 -o rs_black.exr
    run bk_onion --bokeh:lens=achromat:onionwaves=0.2:noise=0.3:onionsharpness=4:fstop=2.8 30 -o bk_onion.exr
    run bk_field --bokeh:fstop=2:lens=uncorrected:catseye=0.6:astigmatism=8:fieldcurvature=4:sheet=1:diffraction=$PSEUDO 24 -o bk_field.exr
    run bk_front --bokeh:fstop=2:lens=apochromat:kernel=polygon:blades=5:hole=0.3:diffraction=exact -20 -o bk_front.exr
    run bk_tiny --bokeh:fstop=2:lens=achromat 0.4 -o bk_tiny.exr
    run bk_aspect --bokeh:fstop=2:aspect=1.8:anamorphicfocus=5:onion=0.3:onionoffset=0.5 40 -o bk_aspect.exr
    run b_box sharp.exr --blur:kernel=box 13.5x7 -o b_box.exr
    run b_ref sharp.exr --blur:kernel=disk:method=reference 9x9 -o b_ref.exr
    run b_bands sharp.exr --blur:kernel=disk:method=bands:bands=5 31x31 -o b_bands.exr
    run b_taps sharp.exr --blur:kernel=disk:method=taps 17x17 -o b_taps.exr
    run b_lanczos sharp.exr --blur:kernel=lanczos3 9x9 -o b_lanczos.exr
    run b_mitchell sharp.exr --blur:kernel=mitchell 11x7 -o b_mitchell.exr
    run b_boxes3 sharp.exr --blur:method=boxes3 21x21 -o b_boxes3.exr
    run b_para sharp.exr --blur:kernel=hex:method=parallelograms:rotation=30 27x27 -o b_para.exr
    run b_sweep sharp.exr --blur:kernel=hex:rotation=7:method=fast 40x40 -o b_sweep.exr
    run b_iris sharp.exr --blur:kernel=disk:iris=0.05 15x15 -o b_iris.exr
    run b_irisg sharp.exr --blur:iris=0.05:border=mirror 12x12 -o b_irisg.exr
    run b_sep sharp.exr --blur:method=separable:grow=1 31x9 -o b_sep.exr
    run b_hard sharp.exr --blur:kernel=disk:edge=hard:border=black 14x14 -o b_hard.exr
    run b_fast_small sharp.exr --blur:kernel=polygon:blades=5:method=fast 21x21 -o b_fast_small.exr
    run b_reduced sharp.exr --blur:kernel=disk:method=reduced:reduction=3 50x50 -o b_reduced.exr
    run deepen sharp.exr --deepen --flatten -o deepen.exr
    cd - >/dev/null || return 1
}

render "$old" "$work/old"
render "$new" "$work/new"
n=0; same=0; pixels=0; differ=0
for f in "$work"/old/*.exr; do
    n=$((n + 1)); g=$work/new/$(basename "$f")
    if cmp -s "$f" "$g"; then
        same=$((same + 1))
    elif idiff -a -fail 0 -failpercent 0 -warn 0 -warnpercent 0 "$f" "$g" >/dev/null 2>&1; then
        pixels=$((pixels + 1))
    else
        differ=$((differ + 1)); echo "differs: $(basename "$f")"
    fi
done
echo "ab-renders: $n images, $same byte-identical, $pixels pixel-identical (metadata differ), $differ differ ($work)"
[ "$differ" -eq 0 ]

#!/usr/bin/env bash
# Whole-process time of --defocus over a frame sequence against oiiotool copying the same
# sequence (read + write), 2 threads, wall and CPU seconds, runs interleaved so the machine's drift falls on all
# of them alike; prints each run and the medians (docs/io.md, "Sequences at I/O speed").
#
#   tools/bokeh-bench/sequence_vs_oiiotool.sh [BOKEHTOOL] [DIR] [REPS] [FRAMES]
#
# DIR gets FRAMES (default 24) frames of the built-in lights scene, 1920x1080 float
# RGBA + Z, zip (about 25 MB each), made once; REPS (default 3) runs of each of:
#   oiiotool --threads 2 --frames 1-N in.#.exr -o copy/out.#.exr
#   bokehtool --threads 2 --frames 1-N in.#.exr --defocus -o seq/out.#.exr
#   bokehtool --threads 2 --parallel-frames --frames 1-N in.#.exr --defocus -o par/out.#.exr
# and checks the last two give byte-identical files.
set -euo pipefail
bokehtool=${1:-build/bin/bokehtool}
dir=${2:-/tmp/openbokeh-sequence}
reps=${3:-3}
frames=${4:-24}
bokehtool=$(cd "$(dirname "$bokehtool")" && pwd)/$(basename "$bokehtool")
mkdir -p "$dir"/{copy,seq,par}
cd "$dir"
if [[ ! -e in.$(printf %04d "$frames").exr ]]; then
  echo "making $frames frames in $dir"
  "$bokehtool" --frames "1-$frames" --scene "lights:seed=#" -o:compression=zip in.#.exr
fi
declare -A times cpus
run() {  # name command...: wall and CPU (user + sys) seconds of the whole process
  local name=$1; shift
  local out; out=$(mktemp)
  /usr/bin/time -f '%e %U %S' -o "$out" "$@"
  local t c
  read -r t c < <(awk '{print $1, $2 + $3}' "$out"); rm -f "$out"
  times[$name]+="$t "
  cpus[$name]+="$c "
  printf '%-10s %6.2f s wall %6.2f s CPU   (load %s)\n' "$name" "$t" "$c" "$(cut -d' ' -f1 /proc/loadavg)"
}
# One untimed round first (the warm-up: page cache, the tools' first start), then REPS timed
# rounds, each running the three in turn.
oiiotool --threads 2 --frames "1-$frames" in.#.exr -o copy/out.#.exr
"$bokehtool" --threads 2 --frames "1-$frames" in.#.exr --defocus -o seq/out.#.exr
"$bokehtool" --threads 2 --parallel-frames --frames "1-$frames" in.#.exr --defocus -o par/out.#.exr
for rep in $(seq "$reps"); do
  run oiiotool  oiiotool --threads 2 --frames "1-$frames" in.#.exr -o copy/out.#.exr
  run defocus   "$bokehtool" --threads 2 --frames "1-$frames" in.#.exr --defocus -o seq/out.#.exr
  run parallel  "$bokehtool" --threads 2 --parallel-frames --frames "1-$frames" in.#.exr --defocus -o par/out.#.exr
done
for f in $(seq -f %04g 1 "$frames"); do
  cmp -s "seq/out.$f.exr" "par/out.$f.exr" || { echo "frame $f differs with --parallel-frames"; exit 1; }
done
median() { tr ' ' '\n' | grep . | sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }
o=$(printf %.2f "$(echo "${times[oiiotool]}" | median)")
d=$(printf %.2f "$(echo "${times[defocus]}" | median)")
p=$(printf %.2f "$(echo "${times[parallel]}" | median)")
echo "medians of $reps: oiiotool copy $o s; --defocus $d s ($(echo "scale=2; $d / $o" | bc)x); --defocus --parallel-frames $p s ($(echo "scale=2; $p / $o" | bc)x)"
oc=$(printf %.2f "$(echo "${cpus[oiiotool]}" | median)")
dc=$(printf %.2f "$(echo "${cpus[defocus]}" | median)")
pc=$(printf %.2f "$(echo "${cpus[parallel]}" | median)")
echo "CPU medians: oiiotool copy $oc s; --defocus $dc s ($(echo "scale=2; $dc / $oc" | bc)x); --defocus --parallel-frames $pc s ($(echo "scale=2; $pc / $oc" | bc)x)"

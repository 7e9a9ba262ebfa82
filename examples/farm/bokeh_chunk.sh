#!/usr/bin/env bash
# bokeh_chunk.sh — render one chunk of a shot: the frames FIRST + INDEX*CHUNK .. (that + CHUNK
# - 1, at most LAST) of a bokehtool command line holding a frame pattern (shot.#.exr).
#
#   bokeh_chunk.sh FIRST LAST CHUNK INDEX [bokehtool arguments...]
#
# INDEX counts chunks from 0; the word "slurm" takes it from $SLURM_ARRAY_TASK_ID (what
# submit_slurm.sh passes). Any farm manager runs this once per task: Slurm job arrays,
# Deadline, Tractor and OpenCue (docs/farm.md).
# The chunk runs `bokehtool -u --skip-bad-frames --frames A-B ...`:
#   * -u: a frame whose outputs exist and are newer than its inputs is skipped, so a
#     resubmitted shot redoes only the frames missing or stale;
#   * --skip-bad-frames: a bad frame is reported by number on stderr and the chunk's other
#     frames are still rendered; the exit status is then 1, which fails the farm task.
# Exit status: bokehtool's (0 every frame of the chunk written or up to date; 1 a frame
# failed, its number in the log; 124 --timeout stopped it); 2 bad arguments to this
# script. BOKEHTOOL overrides the program, BOKEH_THREADS the thread count.
set -u
if [[ $# -lt 5 ]]; then
  echo "usage: $0 FIRST LAST CHUNK INDEX bokehtool-arguments..." >&2
  exit 2
fi
first=$1 last=$2 chunk=$3 index=$4
shift 4
[[ "$index" == slurm ]] && index=${SLURM_ARRAY_TASK_ID:-missing}
for n in "$first" "$last" "$chunk" "$index"; do
  [[ "$n" =~ ^-?[0-9]+$ ]] || { echo "bokeh_chunk.sh: '$n' is not a whole number" >&2; exit 2; }
done
(( chunk > 0 )) || { echo "bokeh_chunk.sh: CHUNK must be > 0" >&2; exit 2; }
a=$(( first + index * chunk ))
b=$(( a + chunk - 1 ))
(( b > last )) && b=$last
if (( index < 0 || a > last )); then
  echo "bokeh_chunk.sh: chunk $index starts past the last frame $last" >&2
  exit 2
fi
bokehtool=${BOKEHTOOL:-bokehtool}
# As many threads as the task was given CPUs (Slurm says so in SLURM_CPUS_PER_TASK; other
# managers can set BOKEH_THREADS); 0, every core, when nothing says.
threads=${BOKEH_THREADS:-${SLURM_CPUS_PER_TASK:-0}}
echo "chunk $index: frames $a-$b on $(hostname) at $(date -u +%FT%TZ), $threads thread(s) (0: all cores)"
"$bokehtool" -u --skip-bad-frames --progress --runstats --threads "$threads" --frames "$a-$b" "$@"
status=$?
echo "chunk $index: frames $a-$b exit status $status"
exit $status

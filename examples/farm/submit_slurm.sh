#!/usr/bin/env bash
# submit_slurm.sh — submit a shot to Slurm as a job array, a task per chunk of frames.
#
#   submit_slurm.sh [-c CHUNK] [-n CPUS] [-l LOGDIR] [-w] FIRST LAST -- bokehtool-arguments...
#
#   -c CHUNK   frames a task (default 5)
#   -n CPUS    CPUs a task asks for (default: $SBATCH_CPUS_PER_TASK, else 1); bokehtool runs
#              as many threads (bokeh_chunk.sh passes --threads $SLURM_CPUS_PER_TASK)
#   -l LOGDIR  a log file per chunk: LOGDIR/<job>_<chunk>.log (default ./logs)
#   -w         wait for the whole array (sbatch --wait): exit 0 only if every task succeeded
#   -h         this help
#   Other sbatch options can go in SBATCH_* environment variables (SBATCH_PARTITION, ...).
#   BOKEHTOOL names the program the tasks run (default: bokehtool on this PATH; it must
#   exist: the tasks are given its full path).
#
# Example: a 240-frame shot in chunks of 10, 4 CPUs a task, defocused:
#   submit_slurm.sh -c 10 -n 4 1001 1240 -- shot/beauty.#.exr --defocus:focus=4:fstop=2 -o out/dof.#.exr
# Each task runs bokeh_chunk.sh (bokehtool -u --skip-bad-frames --frames A-B ...). A failing
# frame fails its task (State FAILED, ExitCode 1:0) and is named in the chunk's log; run the
# same command again after fixing it: the frames already written are skipped (-u), and
# frames written with other options are made again.
# Exit status: sbatch's (0: submitted; with -w, 0 only if every task succeeded); 2: bad
# arguments, no sbatch, no bokehtool, or an output folder that does not exist.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
usage="usage: $0 [-c CHUNK] [-n CPUS] [-l LOGDIR] [-w] FIRST LAST -- bokehtool-arguments..."
help() { sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0"; }
if [[ "${1:-}" == "--help" ]]; then help; exit 0; fi
chunk=5 cpus=${SBATCH_CPUS_PER_TASK:-1} logdir=logs wait=()
while getopts "c:n:l:wh" opt; do
  case $opt in
    c) chunk=$OPTARG ;;
    n) cpus=$OPTARG ;;
    l) logdir=$OPTARG ;;
    w) wait=(--wait) ;;
    h) help; exit 0 ;;
    *) echo "$usage" >&2; exit 2 ;;
  esac
done
shift $((OPTIND - 1))
if [[ $# -lt 4 || "$3" != "--" ]]; then
  echo "$usage" >&2
  exit 2
fi
first=$1 last=$2
shift 3
if ! [[ "$first" =~ ^-?[0-9]+$ && "$last" =~ ^-?[0-9]+$ && "$chunk" =~ ^[0-9]+$ ]] \
   || (( last < first || chunk < 1 )); then
  echo "submit_slurm.sh: frames $first-$last in chunks of $chunk: not a frame range" >&2
  exit 2
fi
if ! [[ "$cpus" =~ ^[0-9]+$ ]] || (( cpus < 1 )); then
  echo "submit_slurm.sh: -n $cpus: not a CPU count (1 or more)" >&2
  exit 2
fi
# The bokehtool on this machine's PATH unless BOKEHTOOL names one; the tasks get its full
# path (a bare name would be looked up again on each node, perhaps finding nothing).
tool=${BOKEHTOOL:-bokehtool}
resolved=$(command -v "$tool" || true)
if [[ -z "$resolved" || ! -x "$resolved" ]]; then
  echo "submit_slurm.sh: bokehtool '$tool' not found; put it on PATH or set BOKEHTOOL=/path/to/bokehtool" >&2
  exit 2
fi
export BOKEHTOOL=$resolved
# The outputs' folders exist before anything is queued: bokehtool refuses a frame whose
# output folder is missing, and a farm would learn it task by task.
prev=""
for a in "$@"; do
  if [[ "$prev" == -o || "$prev" == -o:* ]]; then
    dir=$(dirname -- "$a")
    [[ -d "$dir" ]] || { echo "submit_slurm.sh: -o $a: directory '$dir' does not exist" >&2; exit 2; }
  fi
  prev=$a
done
command -v sbatch >/dev/null || { echo "submit_slurm.sh: sbatch not found (is Slurm installed?)" >&2; exit 2; }
tasks=$(( (last - first) / chunk + 1 ))
mkdir -p "$logdir"
exec sbatch --parsable "${wait[@]}" --job-name=bokeh --array=0-$((tasks - 1)) \
  --ntasks=1 --cpus-per-task="$cpus" --export=ALL \
  --output="$logdir/%A_%a.log" \
  "$here/bokeh_chunk.sh" "$first" "$last" "$chunk" slurm "$@"

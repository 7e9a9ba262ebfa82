#!/usr/bin/env bash
# submit_slurm.sh — submit a shot to Slurm as a job array, a task per chunk of frames.
#
#   submit_slurm.sh [-c CHUNK] [-l LOGDIR] [-w] FIRST LAST -- bokehtool-arguments...
#
#   -c CHUNK   frames a task (default 5)
#   -l LOGDIR  a log file per chunk: LOGDIR/<job>_<chunk>.log (default ./logs)
#   -w         wait for the whole array (sbatch --wait): exit 0 only if every task succeeded
#   Other sbatch options can go in SBATCH_* environment variables (SBATCH_PARTITION, ...).
#
# Example: a 240-frame shot in chunks of 10, defocused:
#   submit_slurm.sh -c 10 1001 1240 -- shot/beauty.#.exr --defocus:focus=4:fstop=2 -o out/dof.#.exr
# Each task runs bokeh_chunk.sh (bokehtool -u --skip-bad-frames --frames A-B ...). A failing
# frame fails its task (State FAILED, ExitCode 1:0) and is named in the chunk's log; run the
# same command again after fixing it: the frames already written are skipped (-u).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
chunk=5 logdir=logs wait=()
while getopts "c:l:w" opt; do
  case $opt in
    c) chunk=$OPTARG ;;
    l) logdir=$OPTARG ;;
    w) wait=(--wait) ;;
    *) exit 2 ;;
  esac
done
shift $((OPTIND - 1))
if [[ $# -lt 4 || "$3" != "--" ]]; then
  echo "usage: $0 [-c CHUNK] [-l LOGDIR] [-w] FIRST LAST -- bokehtool-arguments..." >&2
  exit 2
fi
first=$1 last=$2
shift 3
if ! [[ "$first" =~ ^-?[0-9]+$ && "$last" =~ ^-?[0-9]+$ && "$chunk" =~ ^[0-9]+$ ]] \
   || (( last < first || chunk < 1 )); then
  echo "submit_slurm.sh: frames $first-$last in chunks of $chunk: not a frame range" >&2
  exit 2
fi
command -v sbatch >/dev/null || { echo "submit_slurm.sh: sbatch not found (is Slurm installed?)" >&2; exit 2; }
tasks=$(( (last - first) / chunk + 1 ))
mkdir -p "$logdir"
# The bokehtool on this machine's PATH unless BOKEHTOOL names one (exported to the tasks).
export BOKEHTOOL=${BOKEHTOOL:-$(command -v bokehtool || echo bokehtool)}
exec sbatch --parsable "${wait[@]}" --job-name=bokeh --array=0-$((tasks - 1)) \
  --ntasks=1 --cpus-per-task=1 --export=ALL \
  --output="$logdir/%A_%a.log" \
  "$here/bokeh_chunk.sh" "$first" "$last" "$chunk" slurm "$@"

#!/usr/bin/env bash
# Run libFuzzer targets for a while each, starting from the committed corpus and the past
# findings (tests/fuzz/corpus/<target>, tests/fuzz/regressions/<target>: every one of them
# is replayed first). New inputs go to WORK_DIR/corpus_<target>, findings to
# WORK_DIR/<target>-crash-*, -timeout-*, -oom-*; the script fails naming them.
#
#   run_fuzz.sh BIN_DIR WORK_DIR SECONDS TARGET...   (TARGET: read_image, command_line, ...)
#   run_fuzz.sh --fresh BIN_DIR WORK_DIR ...          (WORK_DIR emptied first: ctest's run)
#   run_fuzz.sh --skip "why"                         (exit 77: ctest's "skipped")
#
# Used by ctest (fuzz_smoke: a few seconds a target) and by `make fuzz` (FUZZ_SECONDS), which
# sets FUZZ_LEDGER=tests/fuzz/runs.csv: each target's executions, seconds and outcome are
# appended there, and tests/fuzz/ledger.py adds them up in docs/robustness.md.
set -u
if [ "${1:-}" = "--skip" ]; then
  echo "fuzz_smoke: skipped: ${2:-}"
  exit 77
fi
if [ "${1:-}" = "--fresh" ]; then
  shift
  rm -rf "$2"
fi
mkdir -p "$2"
bin=$(cd "$1" && pwd) work=$(cd "$2" && pwd) seconds=$3
shift 3
here=$(cd "$(dirname "$0")" && pwd)
export ASAN_OPTIONS=detect_leaks=0${ASAN_OPTIONS:+:$ASAN_OPTIONS}
export UBSAN_OPTIONS=print_stacktrace=1${UBSAN_OPTIONS:+:$UBSAN_OPTIONS}
status=0
for t in "$@"; do
  exe="$bin/fuzz_$t"
  if [ ! -x "$exe" ]; then
    echo "run_fuzz: $exe is not built"
    status=1
    continue
  fi
  mkdir -p "$work/corpus_$t"
  dirs=("$work/corpus_$t")
  for d in "$here/corpus/$t" "$here/regressions/$t" "$work/seeds_$t"; do
    [ -d "$d" ] && dirs+=("$d")
  done
  dict=()
  [ -f "$here/$t.dict" ] && dict=(-dict="$here/$t.dict")
  log="$work/$t.log"
  start=$SECONDS
  (cd "$work" && nice -n "${FUZZ_NICE:-0}" "$exe" -max_total_time="$seconds" -timeout=10 \
     -rss_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$work/$t-" "${dict[@]}" \
     "${dirs[@]}") >"$log" 2>&1
  rc=$?
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  secs=$(sed -n 's/^stat::.*//;s/.*Done \([0-9]*\) runs in \([0-9]*\) second.*/\2/p' "$log" | tail -1)
  secs=${secs:-$((SECONDS - start))}  # a finding stops the run before libFuzzer's summary
  # The ledger (make fuzz: tests/fuzz/runs.csv), so the executions add up across runs.
  if [ -n "${FUZZ_LEDGER:-}" ]; then
    outcome="no finding"
    [ $rc -ne 0 ] && outcome="finding: $(ls "$work/$t-"* 2>/dev/null | head -1 | xargs -r basename)"
    echo "$t,${runs:-0},${secs:-0},${outcome//,/;},$(nproc) cores at nice ${FUZZ_NICE:-0}" >>"$FUZZ_LEDGER"
  fi
  if [ $rc -ne 0 ]; then
    echo "fuzz_$t: FAILED (exit $rc) after ${runs:-?} runs; log: $log; findings:"
    ls "$work/$t-"* 2>/dev/null
    tail -40 "$log"
    status=1
  else
    echo "fuzz_$t: ${runs:-?} runs in ${secs:-?} s, no finding ($(ls "$work/corpus_$t" | wc -l) new inputs)"
  fi
done
exit $status

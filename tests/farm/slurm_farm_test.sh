#!/usr/bin/env bash
# A shot rendered on a one-node Slurm cluster started here, in a scratch folder, through
# examples/farm/submit_slurm.sh (a job array over frame chunks), against a local run.
#
#   slurm_farm_test.sh BOKEHTOOL SOURCE_DIR SCRATCH
#
# Checks: the 12 frames written by the farm are byte-identical to a local run's; a broken
# input frame fails its task, is named in that chunk's log, and the other frames of its
# chunk are still written; a resubmission (-u) skips the 11 frames already written and
# renders the repaired one. Starts munged, slurmctld and slurmd with its own key, sockets,
# ports (16917/16918) and slurm.conf under SCRATCH, and stops exactly those by pid.
# Exit 77 (ctest: skipped), saying why, where Slurm cannot run (not installed, not root).
set -uo pipefail
bokehtool=$1 source_dir=$2 scratch=$3

skip() { echo "SKIPPED: $*"; exit 77; }
for p in munged slurmctld slurmd sbatch scontrol; do
  command -v "$p" >/dev/null || skip "$p is not installed (tools/install-deps.sh installs slurm-wlm and munge)"
done
[[ $(id -u) -eq 0 ]] || skip "a one-node Slurm here runs its daemons as root; this is uid $(id -u)"

rm -rf "$scratch"
mkdir -p "$scratch"/{munge,state,spool,log,in,local,farm,logs}
chmod 755 "$scratch/munge"
pids=()
cleanup() {
  for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null; done
  for pid in "${pids[@]}"; do
    for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -9 "$pid" 2>/dev/null
  done
  return 0
}
trap cleanup EXIT
fail() { echo "FAILED: $*"; for f in "$scratch"/log/*.log; do echo "--- $f"; tail -20 "$f"; done; exit 1; }

# --- munge, with its own key and socket ---------------------------------------------------
dd if=/dev/urandom of="$scratch/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$scratch/munge/munge.key"
socket="$scratch/munge/munge.socket"
munged --force --socket="$socket" --key-file="$scratch/munge/munge.key" \
  --pid-file="$scratch/munge/munged.pid" --log-file="$scratch/log/munged.log" \
  --seed-file="$scratch/munge/munged.seed" 2>"$scratch/log/munged.start" \
  || skip "munged cannot start here: $(head -1 "$scratch/log/munged.start")"
for _ in $(seq 50); do [[ -s "$scratch/munge/munged.pid" ]] && break; sleep 0.1; done
pids+=("$(cat "$scratch/munge/munged.pid")")

# --- slurm.conf ------------------------------------------------------------------------------
host=$(hostname -s)
cpus=$(nproc)
cat > "$scratch/slurm.conf" <<CONF
ClusterName=openbokeh-test
SlurmctldHost=$host
SlurmctldPort=16917
SlurmdPort=16918
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$socket
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
MpiDefault=none
ReturnToService=2
SchedulerType=sched/backfill
StateSaveLocation=$scratch/state
SlurmdSpoolDir=$scratch/spool
SlurmctldPidFile=$scratch/slurmctld.pid
SlurmdPidFile=$scratch/slurmd.pid
SlurmctldLogFile=$scratch/log/slurmctld.log
SlurmdLogFile=$scratch/log/slurmd.log
MinJobAge=600
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=1000 State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF="$scratch/slurm.conf"
slurmctld -c -f "$SLURM_CONF" 2>"$scratch/log/slurmctld.start" \
  || skip "slurmctld cannot start here: $(head -1 "$scratch/log/slurmctld.start")"
for _ in $(seq 50); do [[ -s "$scratch/slurmctld.pid" ]] && break; sleep 0.1; done
[[ -s "$scratch/slurmctld.pid" ]] && pids+=("$(cat "$scratch/slurmctld.pid")")
slurmd -f "$SLURM_CONF" 2>"$scratch/log/slurmd.start" \
  || skip "slurmd cannot start here: $(head -1 "$scratch/log/slurmd.start")"
for _ in $(seq 50); do [[ -s "$scratch/slurmd.pid" ]] && break; sleep 0.1; done
[[ -s "$scratch/slurmd.pid" ]] && pids+=("$(cat "$scratch/slurmd.pid")")
ready=0
for _ in $(seq 150); do
  state=$(sinfo -h -N -o %t 2>/dev/null | head -1)
  [[ "$state" == idle* ]] && { ready=1; break; }
  sleep 0.2
done
(( ready )) || skip "the one-node cluster did not come up within 30 s (node state '${state:-none}'; $scratch/log)"
echo "slurm: node $host idle (slurmctld, slurmd, munged pids ${pids[*]})"

# --- the shot: 12 frames of a built-in scene, defocused ---------------------------------------
# Files record the time they were written (DateTime); a fixed SOURCE_DATE_EPOCH (exported to
# the tasks with the rest of the environment) makes a farm frame and a local one comparable
# byte for byte.
export SOURCE_DATE_EPOCH=1700000000
"$bokehtool" --frames 1-12 --scene "lights:width=160:height=90:seed=#" -o "$scratch/in/shot.#.exr" \
  || fail "making the input frames"
dof=(--defocus:focus=4:fstop=1.4 -o)
"$bokehtool" --frames 1-12 "$scratch/in/shot.#.exr" "${dof[@]}" "$scratch/local/dof.#.exr" \
  || fail "the local run"
# Frame 7 broken (truncated) for the farm's first pass.
cp "$scratch/in/shot.0007.exr" "$scratch/shot.0007.good"
head -c 2000 "$scratch/shot.0007.good" > "$scratch/in/shot.0007.exr"

submit() {
  BOKEHTOOL="$bokehtool" timeout 120 "$source_dir/examples/farm/submit_slurm.sh" -w -c 3 \
    -l "$scratch/logs/$1" 1 12 -- "$scratch/in/shot.#.exr" "${dof[@]}" "$scratch/farm/dof.#.exr"
}
job=$(submit first); status=$?
echo "first submission: job $job, sbatch --wait status $status"
(( status != 0 )) || fail "a broken frame must fail the array (sbatch --wait status 0)"
log7=$(ls "$scratch"/logs/first/*_2.log 2>/dev/null | head -1)
[[ -n "$log7" ]] || fail "no log for chunk 2 (frames 7-9) in $scratch/logs/first"
grep -q "bokehtool ERROR: .*shot.0007.exr.*(frame 7, 1 of 3; skipped, the run goes on)" "$log7" \
  || { cat "$log7"; fail "chunk 2's log does not name frame 7"; }
grep -q -- "--skip-bad-frames: 1 of 3 frames failed: 7" "$log7" || { cat "$log7"; fail "no summary line"; }
scontrol show job "$job" | grep -q "JobState=FAILED.*" || true
failed_tasks=$(scontrol show job "$job" 2>/dev/null | grep -c "JobState=FAILED")
echo "tasks FAILED: $failed_tasks (expected 1)"
[[ $failed_tasks -eq 1 ]] || { scontrol show job "$job"; fail "expected exactly one failed task"; }
for f in $(seq -f %04g 1 12); do
  if [[ $f == 0007 ]]; then
    [[ ! -e "$scratch/farm/dof.$f.exr" ]] || fail "frame 7 written from a broken input"
  else
    cmp -s "$scratch/local/dof.$f.exr" "$scratch/farm/dof.$f.exr" \
      || fail "frame $f differs from the local run (or is missing)"
  fi
done
echo "first submission: 11 frames byte-identical to the local run, frame 7 reported"

# Repaired and resubmitted: only frame 7 is rendered.
cp "$scratch/shot.0007.good" "$scratch/in/shot.0007.exr"
job=$(submit second); status=$?
echo "second submission: job $job, sbatch --wait status $status"
(( status == 0 )) || { cat "$scratch"/logs/second/*.log; fail "the resubmission failed"; }
skipped=$(cat "$scratch"/logs/second/*.log | grep -c -- "-u: frame .* skipped, up to date")
[[ $skipped -eq 11 ]] || { cat "$scratch"/logs/second/*.log; fail "$skipped frames skipped by -u, expected 11"; }
for f in $(seq -f %04g 1 12); do
  cmp -s "$scratch/local/dof.$f.exr" "$scratch/farm/dof.$f.exr" || fail "frame $f differs after the resubmission"
done
echo "second submission: 11 frames skipped (-u), frame 7 rendered; all 12 byte-identical to the local run"
echo "PASSED"

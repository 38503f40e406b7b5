#!/usr/bin/env bash
# A single-node Slurm cluster on this machine (Debian's slurm-wlm and munge, as scripts/setup.sh installs them):
# munged, slurmctld and slurmd are started with a minimal configuration in a temporary folder and stopped after.
# scripts/slurm/reference.sh renders the references of four frames of the moving Cornell box as two sample shards
# each (64x64) through a job array and a dependent merge job; each merged frame must equal a single-machine run of
# all its samples bit for bit (loom image compare). A second submission finds everything done and submits nothing.
# Also measures what going through Slurm costs per task against running the same renders directly.
# If the daemons cannot start, the test fails and prints their logs: Slurm is not mocked, and not skipped.
# Usage: slurm_reference_test.sh LOOM_BINARY SOURCE_DIR
# LOOM_SLURM_SIZE (default 64x64) and LOOM_SLURM_SPP (samples per iteration, default 2; each task runs 4 iterations)
# size the renders: LOOM_SLURM_SIZE=640x360 LOOM_SLURM_SPP=16 makes each task one 64-spp frame at 640x360, the
# figure of docs/CLUSTER.md.
set -euo pipefail
loom="$(cd "$(dirname "$1")" && pwd)/$(basename "$1")"
src="$(cd "$2" && pwd)"
for c in munged slurmctld slurmd sbatch squeue sinfo; do
  command -v "$c" > /dev/null || { echo "FAIL: $c not found (scripts/setup.sh installs slurm-wlm and munge)"; exit 1; }
done
t="$(mktemp -d /tmp/loom-slurm.XXXXXX)"
logs() {
  for f in "$t"/munged.log "$t"/slurmctld.log "$t"/slurmd.log; do
    [ -f "$f" ] && { echo "---- $f"; tail -30 "$f"; }
  done
}
stop() {
  for p in slurmd slurmctld; do [ -f "$t/$p.pid" ] && kill "$(cat "$t/$p.pid")" 2> /dev/null || true; done
  [ -f "$t/munged.pid" ] && kill "$(cat "$t/munged.pid")" 2> /dev/null || true
  sleep 1
  for p in slurmd slurmctld munged; do [ -f "$t/$p.pid" ] && kill -9 "$(cat "$t/$p.pid")" 2> /dev/null || true; done
  [ -n "${KEEP:-}" ] || rm -rf "$t"
}
trap stop EXIT
fail() { echo "FAIL: $*"; logs; exit 1; }

# munge with its own key and socket, so nothing of the machine's is touched.
head -c 1024 /dev/urandom > "$t/munge.key"
chmod 400 "$t/munge.key"
munged --force --socket="$t/munge.sock" --key-file="$t/munge.key" --pid-file="$t/munged.pid" \
  --log-file="$t/munged.log" --seed-file="$t/munge.seed" || fail "munged did not start"

host="$(hostname)"  # slurmd finds its node by this name; the address is given, so nothing needs DNS
port=$((20000 + $$ % 20000))
mkdir -p "$t/state" "$t/spool"
cat > "$t/slurm.conf" <<EOF
ClusterName=loomtest
SlurmctldHost=$host(127.0.0.1)
SlurmUser=$(id -un)
SlurmdUser=$(id -un)
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$t/munge.sock
StateSaveLocation=$t/state
SlurmdSpoolDir=$t/spool
SlurmctldPidFile=$t/slurmctld.pid
SlurmdPidFile=$t/slurmd.pid
SlurmctldPort=$port
SlurmdPort=$((port + 1))
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SchedulerParameters=sched_min_interval=0,batch_sched_delay=0
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
ReturnToService=2
MinJobAge=600
SlurmctldLogFile=$t/slurmctld.log
SlurmdLogFile=$t/slurmd.log
NodeName=$host NodeAddr=127.0.0.1 CPUs=$(nproc) State=UNKNOWN
PartitionName=loom Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF="$t/slurm.conf"
slurmctld || fail "slurmctld did not start"
slurmd || fail "slurmd did not start"
for i in $(seq 60); do
  [ "$(sinfo -h -o %t 2> /dev/null)" = "idle" ] && break
  [ "$i" -eq 60 ] && fail "the node did not become idle in 30 s (sinfo: $(sinfo 2>&1 | tr '\n' ' '))"
  sleep 0.5
done
echo "single-node cluster up: $(sinfo -h -o '%P %t %c CPUs' | head -1)"
# One trivial job first: the controller's first scheduling pass comes seconds after it starts, which is not a cost
# of any job of a running cluster.
warm="$(sbatch --parsable --output=/dev/null --wrap true)" || fail "sbatch refused a trivial job"
for i in $(seq 100); do
  [ -z "$(squeue -h -j "$warm" -o %i 2> /dev/null)" ] && break
  [ "$i" -eq 100 ] && fail "a trivial job did not finish in 20 s: $(squeue 2>&1 | tr '\n' ' ')"
  sleep 0.2
done

scene="$src/data/scenes/cornell_dynamic.gltf"
graph="$src/graphs/ReferenceShard.json"
size="${LOOM_SLURM_SIZE:-64x64}"
sets=(--set PathTracer.samplesPerPixel="${LOOM_SLURM_SPP:-2}" --set PathTracer.device=cpu)
start=$(date +%s%N)
"$src/scripts/slurm/reference.sh" --loom "$loom" --graph "$graph" --scene "$scene" --size "$size" --frames 0-3 \
  --iterations 8 --shards 2 --out "$t/run" --sbatch "--cpus-per-task=$(nproc)" "${sets[@]}" ||
  fail "reference.sh failed"
slurmMs=$((($(date +%s%N) - start) / 1000000))

# The same samples on this machine alone: one held run of all 8 iterations per frame.
start=$(date +%s%N)
for f in 0 1 2 3; do
  "$loom" render --graph "$graph" --scene "$scene" --size "$size" --start-frame $f --hold --frames 8 -q \
    --out "$t/single" "${sets[@]}" 2> /dev/null
done
singleMs=$((($(date +%s%N) - start) / 1000000))
for f in 0000 0001 0002 0003; do
  "$loom" image compare "$t/single/Accumulate.dst.$f.exr" "$t/run/frames/$f/Accumulate.mean.$f.exr" ||
    fail "frame $f: the merged reference differs from the single-machine run"
done
echo "the 4 merged frames equal the single-machine runs bit for bit"

# The same shard renders directly, without Slurm, for the overhead per task.
start=$(date +%s%N)
for f in 0 1 2 3; do
  for s in 0 1; do
    "$loom" render --graph "$graph" --scene "$scene" --size "$size" --start-frame $f --hold --frames 4 \
      --seed-offset $((s * 4)) -q --out "$t/direct/$f/$s" "${sets[@]}" 2> /dev/null
  done
done
for f in 0000 0001 0002 0003; do "$loom" image merge "$t/direct/$((10#$f))"/* -o "$t/direct/m$f" > /dev/null; done
directMs=$((($(date +%s%N) - start) / 1000000))
echo "timing at $size, $((4 * ${LOOM_SLURM_SPP:-2})) spp a task: through Slurm ${slurmMs} ms; the same 8 shard" \
  "renders and 4 merges directly ${directMs} ms ($((directMs / 8)) ms a task); one run per frame ${singleMs} ms;" \
  "Slurm's overhead per job (8 tasks + 1 merge job): $(((slurmMs - directMs) / 9)) ms"

# Resumable: everything exists, nothing is submitted.
again="$("$src/scripts/slurm/reference.sh" --loom "$loom" --graph "$graph" --scene "$scene" --size "$size" \
  --frames 0-3 --iterations 8 --shards 2 --out "$t/run" "${sets[@]}")" || fail "the second submission failed"
echo "$again" | grep -q "merged already" || fail "the second submission did not find the frames done: $again"
# A missing shard is redone alone, and its frame merged again.
rm -rf "$t/run/shards/0002/shard_001" "$t/run/frames/0002"
again="$("$src/scripts/slurm/reference.sh" --loom "$loom" --graph "$graph" --scene "$scene" --size "$size" \
  --frames 0-3 --iterations 8 --shards 2 --out "$t/run" "${sets[@]}")" || fail "the resumed submission failed"
echo "$again" | grep -q "1 of 8 shard task" || fail "the resumed submission did not submit one task: $again"
"$loom" image compare "$t/single/Accumulate.dst.0002.exr" "$t/run/frames/0002/Accumulate.mean.0002.exr" ||
  fail "frame 2 resumed differs"
# A task that fails on its node (a loom that fails task 2's render; arguments loom refuses are refused before
# anything is submitted) is named with its log, the merge is not run, and the command fails.
rm -rf "$t/run/shards/0001" "$t/run/frames/0001"
{
  echo '#!/usr/bin/env bash'
  echo 'if [ "$1" = render ] && [ "${SLURM_ARRAY_TASK_ID:-}" = 2 ]; then echo "task 2 failed on purpose" >&2; exit 1; fi'
  printf 'exec %q "$@"\n' "$loom"
} > "$t/failing-loom"
chmod +x "$t/failing-loom"
if out="$("$src/scripts/slurm/reference.sh" --loom "$t/failing-loom" --graph "$graph" --scene "$scene" \
  --size "$size" --frames 0-3 --iterations 8 --shards 2 --out "$t/run" "${sets[@]}" 2>&1)"; then
  fail "a submission whose tasks fail succeeded: $out"
fi
echo "$out" | grep -q "FAILED: task 2 (frame 1, shard 0)" || fail "the failed task was not reported: $out"
echo "$out" | grep -q "task 2 failed on purpose" || fail "the failed task's log was not shown: $out"
[ ! -d "$t/run/frames/0001" ] || fail "frame 1 was merged although its shards failed"
echo "PASS"

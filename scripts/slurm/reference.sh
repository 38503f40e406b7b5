#!/usr/bin/env bash
# Renders many-sample references of a sequence's frames on a Slurm cluster: one array task per frame and sample
# shard (`loom render --hold --seed-offset`), then one job, dependent on the array (--dependency=afterok), that
# merges each frame's shards (`loom image merge`). Resumable: a shard or frame whose output folder exists is done and
# is not submitted again, so running the same command after a failure redoes only what is missing. Waits for the
# jobs (squeue) and reports failed tasks with their logs.
#
# Usage: scripts/slurm/reference.sh --scene S --frames A-B --iterations N --shards M --out DIR [options]
#   --graph G          graph with an AccumulatePass's partial outputs (default graphs/ReferenceShard.json)
#   --scene S          glTF scene
#   --size WxH         frame size (default 640x360)
#   --frames A-B       the frames to render (one reference each)
#   --iterations N     iterations of the graph per frame (its samplesPerPixel each), split evenly over the shards
#   --shards M         sample shards per frame (array tasks per frame)
#   --out DIR          output folder on storage every node sees: DIR/frames/FRAME/PASS.mean.FRAME.exr
#   --set P.p=v        a graph parameter (repeatable)
#   --loom PATH        the loom binary the nodes run (default: build/release/bin/loom beside this script)
#   --sbatch ARGS      extra sbatch arguments for every job (partition, account, time, ...)
#   --no-wait          submit and return (the job ids are printed)
# Environment: LOOM_THREADS (worker threads per task, default: the CPUs Slurm gives the task).
# Exit: 0 when every frame is merged, 1 when a task or the merge failed (their logs are named), 2 for bad arguments.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
graph="$root/graphs/ReferenceShard.json" scene="" size="640x360" frames="" iterations="" shards="" out=""
loom="$root/build/release/bin/loom" sbatchArgs="" wait=1
sets=()
die() { echo "error: $*" >&2; exit 2; }
while [ $# -gt 0 ]; do
  case "$1" in
    --graph) graph="$2"; shift 2 ;;
    --scene) scene="$2"; shift 2 ;;
    --size) size="$2"; shift 2 ;;
    --frames) frames="$2"; shift 2 ;;
    --iterations) iterations="$2"; shift 2 ;;
    --shards) shards="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --set) sets+=(--set "$2"); shift 2 ;;
    --loom) loom="$2"; shift 2 ;;
    --sbatch) sbatchArgs="$2"; shift 2 ;;
    --no-wait) wait=0; shift ;;
    *) die "unknown argument '$1' (see the usage at the top of $0)" ;;
  esac
done
[ -n "$scene" ] && [ -n "$frames" ] && [ -n "$iterations" ] && [ -n "$shards" ] && [ -n "$out" ] ||
  die "--scene, --frames, --iterations, --shards and --out are required"
[[ "$frames" =~ ^([0-9]+)-([0-9]+)$ ]] || die "--frames '$frames' is not A-B"
first="${BASH_REMATCH[1]}" last="${BASH_REMATCH[2]}"
[ "$first" -le "$last" ] || die "--frames '$frames': A is after B"
[[ "$iterations" =~ ^[1-9][0-9]*$ && "$shards" =~ ^[1-9][0-9]*$ ]] || die "--iterations and --shards are counts"
[ $((iterations % shards)) -eq 0 ] || die "--iterations $iterations is not a multiple of --shards $shards"
[ -x "$loom" ] || die "no loom binary at $loom (build it, or give --loom)"
for f in "$graph" "$scene"; do [ -f "$f" ] || die "no such file: $f"; done
for c in sbatch squeue; do command -v "$c" > /dev/null || die "$c not found: is this a Slurm submit host?"; done
per=$((iterations / shards))
count=$((last - first + 1))
tasks=$((count * shards))
mkdir -p "$out/shards" "$out/frames" "$out/slurm/logs"
out="$(cd "$out" && pwd)"
graph="$(cd "$(dirname "$graph")" && pwd)/$(basename "$graph")"
scene="$(cd "$(dirname "$scene")" && pwd)/$(basename "$scene")"

# The task: frame first + t / shards, shard t % shards, its samples from seed offset shard * per. Written into a
# temporary folder and renamed: a shard's folder exists only when it is complete.
setsQuoted=""
[ ${#sets[@]} -eq 0 ] || setsQuoted="$(printf '%q ' "${sets[@]}")"
cat > "$out/slurm/task.sh" <<EOF
#!/usr/bin/env bash
set -euo pipefail
t=\$SLURM_ARRAY_TASK_ID
frame=\$(( $first + t / $shards )) shard=\$(( t % $shards ))
dest="$out/shards/\$(printf %04d \$frame)/shard_\$(printf %03d \$shard)"
[ -d "\$dest" ] && { echo "shard done already: \$dest"; exit 0; }
tmp="\$dest.partial.\$SLURM_JOB_ID"
rm -rf "\$tmp"
mkdir -p "\$(dirname "\$dest")"
"$loom" render --graph "$graph" --scene "$scene" --size "$size" --start-frame \$frame --hold --frames $per \\
  --seed-offset \$(( shard * $per )) --threads "\${LOOM_THREADS:-\${SLURM_CPUS_ON_NODE:-0}}" --quiet --out "\$tmp" \\
  $setsQuoted
mv "\$tmp" "\$dest"
EOF
cat > "$out/slurm/merge.sh" <<EOF
#!/usr/bin/env bash
set -euo pipefail
for ((frame = $first; frame <= $last; ++frame)); do
  f=\$(printf %04d \$frame)
  dest="$out/frames/\$f"
  [ -d "\$dest" ] && continue
  rm -rf "\$dest.partial"
  "$loom" image merge "$out/shards/\$f"/shard_* -o "\$dest.partial"
  mv "\$dest.partial" "\$dest"
done
EOF
chmod +x "$out/slurm/task.sh" "$out/slurm/merge.sh"

# A shard's folder, which exists only when the shard is complete.
shardDir() { echo "$out/shards/$(printf %04d "$1")/shard_$(printf %03d "$2")"; }

# Only what is missing is submitted.
missing=()
for ((t = 0; t < tasks; ++t)); do
  frame=$((first + t / shards)) shard=$((t % shards))
  [ -d "$(shardDir $frame $shard)" ] || missing+=("$t")
done
merged=0
for ((frame = first; frame <= last; ++frame)); do [ -d "$out/frames/$(printf %04d $frame)" ] && merged=$((merged + 1)); done
if [ ${#missing[@]} -eq 0 ] && [ "$merged" -eq "$count" ]; then
  echo "all $count frame(s) merged already in $out/frames"
  exit 0
fi
# shellcheck disable=SC2086
common=(--parsable --chdir "$out" $sbatchArgs)
jobs=()
dependency=()
array=""
if [ ${#missing[@]} -gt 0 ]; then
  list="$(IFS=,; echo "${missing[*]}")"
  array="$(sbatch "${common[@]}" --job-name loom-shards --array "$list" \
    --output "$out/slurm/logs/task_%A_%a.log" "$out/slurm/task.sh")"
  array="${array%%;*}"
  jobs+=("$array")
  dependency=(--dependency "afterok:$array" --kill-on-invalid-dep=yes)
  echo "submitted $array: ${#missing[@]} of $tasks shard task(s) ($count frame(s) x $shards shard(s), $per iteration(s) each)"
fi
merge="$(sbatch "${common[@]}" "${dependency[@]}" --job-name loom-merge --output "$out/slurm/logs/merge_%j.log" \
  "$out/slurm/merge.sh")"
merge="${merge%%;*}"
jobs+=("$merge")
echo "submitted $merge: the merge of $count frame(s)"
[ "$wait" -eq 1 ] || { echo "jobs: ${jobs[*]}"; exit 0; }

# Wait until no job is queued or running, then judge by the outputs: a shard or frame folder exists only complete.
ids="$(IFS=,; echo "${jobs[*]}")"
while [ -n "$(squeue -h -j "$ids" -o %i 2> /dev/null)" ]; do sleep 0.2; done
failed=0
for ((t = 0; t < tasks; ++t)); do
  frame=$((first + t / shards)) shard=$((t % shards))
  if [ ! -d "$(shardDir $frame $shard)" ]; then
    failed=1
    log="$out/slurm/logs/task_${array:-none}_$t.log"
    [ -f "$log" ] || log=""
    echo "FAILED: task $t (frame $frame, shard $shard): ${log:-no log}" >&2
    [ -n "$log" ] && tail -5 "$log" | sed 's/^/    /' >&2
  fi
done
for ((frame = first; frame <= last; ++frame)); do
  if [ ! -d "$out/frames/$(printf %04d $frame)" ]; then
    failed=1
    echo "FAILED: frame $frame was not merged (log: $out/slurm/logs/merge_$merge.log)" >&2
  fi
done
[ "$failed" -eq 0 ] || { echo "run the same command again to redo only what is missing" >&2; exit 1; }
echo "done: $count frame(s) in $out/frames"

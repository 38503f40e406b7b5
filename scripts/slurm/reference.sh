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
#   --frames A-B       the frames to render (one reference each), decimal: 010-012 is frames 10, 11 and 12
#   --iterations N     iterations of the graph per frame (its samplesPerPixel each), split evenly over the shards
#   --shards M         sample shards per frame (array tasks per frame), 2 or more: a frame's shards are merged
#   --out DIR          output folder on storage every node sees: DIR/frames/FRAME/PASS.mean.FRAME.exr
#   --set P.p=v        a graph parameter (repeatable)
#   --loom PATH        the loom binary the nodes run (default: build/release/bin/loom beside this script)
#   --sbatch ARGS      extra sbatch arguments for every job (partition, account, time, ...), split into words at
#                      whitespace and passed to sbatch as they are: never evaluated, no quotes or expansions
#   --no-wait          submit and return (the job ids are printed)
# Everything is checked before anything is submitted: the numbers first (decimal, and against the limits of
# `loom render` before bash's arithmetic could overflow: frames up to 1000000000, at most 1000000 iterations a task,
# frame + --iterations - 1 at most 4294967295), then the first and last task's exact `loom render` command, run dry
# (`--dry-run`) on this host: the graph, scene, size, --set and every limit as the tasks would meet them.
# Values reach the tasks as data: the job scripts hold them as quoted assignments and never evaluate them.
# Environment: LOOM_THREADS (worker threads per task, default: the CPUs Slurm gives the task).
# Exit: 0 when every frame is merged, 1 when a task or the merge failed (their logs are named), 2 for bad arguments.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
graph="$root/graphs/ReferenceShard.json" scene="" size="640x360" frames="" iterations="" shards="" out="" first="" last=""
loom="$root/build/release/bin/loom" sbatchArgs="" wait=1
sets=()
die() { echo "error: $*" >&2; exit 2; }

# The limits of the tasks' `loom render` (apps/loom/RenderCommand.cpp), and of Slurm's job arrays.
maxFrame=1000000000          # --start-frame
maxPerTask=1000000           # --frames
maxHeldIndex=4294967295      # --start-frame + --seed-offset + --frames - 1: a held frame's last iteration index
maxTasks=4000001             # the largest MaxArraySize Slurm allows: array indices 0 to 4000000

while [ $# -gt 0 ]; do
  opt="$1"
  case "$opt" in
    --no-wait) wait=0; shift; continue ;;
    --graph | --scene | --size | --frames | --iterations | --shards | --out | --set | --loom | --sbatch)
      [ $# -ge 2 ] || die "$opt needs a value"
      value="$2"
      shift 2
      ;;
    *) die "unknown argument '$opt' (see the usage at the top of $0)" ;;
  esac
  case "$opt" in
    --graph) graph="$value" ;;
    --scene) scene="$value" ;;
    --size) size="$value" ;;
    --frames) frames="$value" ;;
    --iterations) iterations="$value" ;;
    --shards) shards="$value" ;;
    --out) out="$value" ;;
    --set) sets+=(--set "$value") ;;
    --loom) loom="$value" ;;
    --sbatch) sbatchArgs="$value" ;;
  esac
done
[ -n "$scene" ] && [ -n "$frames" ] && [ -n "$iterations" ] && [ -n "$shards" ] && [ -n "$out" ] ||
  die "--scene, --frames, --iterations, --shards and --out are required"

# Numbers are read as decimal digit strings: leading zeros dropped (never octal), and compared by length first, so
# that no value overflows bash's arithmetic before it is known to be small.
decimal() {  # VARIABLE OPTION TEXT: VARIABLE = TEXT without leading zeros, or die
  [[ "$3" =~ ^[0-9]+$ ]] || die "$2 '$3' is not a decimal number"
  local v="${3#"${3%%[!0]*}"}"
  printf -v "$1" %s "${v:-0}"
}
atMost() {  # A B: digit strings without leading zeros, A <= B
  [ ${#1} -lt ${#2} ] || { [ ${#1} -eq ${#2} ] && ! [[ "$1" > "$2" ]]; }
}
[[ "$frames" =~ ^([^-]+)-([^-]+)$ ]] || die "--frames '$frames' is not A-B (e.g. 0-63)"
firstText="${BASH_REMATCH[1]}" lastText="${BASH_REMATCH[2]}"
decimal first --frames "$firstText"
decimal last --frames "$lastText"
atMost "$last" "$maxFrame" ||
  die "--frames '$frames': frame $last is beyond loom render's last frame ($maxFrame, its --start-frame limit)"
atMost "$first" "$last" || die "--frames '$frames': A is after B"
decimal iterations --iterations "$iterations"
decimal shards --shards "$shards"
[ "$iterations" != 0 ] || die "--iterations must be 1 or more"
[ "$shards" != 0 ] || die "--shards must be 2 or more"
[ "$shards" != 1 ] || die "--shards 1: loom image merge needs two or more shards per frame; give --shards 2 or" \
  "more (or render one frame's reference directly: loom render --hold --start-frame K --frames N)"
atMost "$iterations" "$maxHeldIndex" ||
  die "--iterations $iterations: too many (a held frame's iterations of loom render end at index $maxHeldIndex)"
atMost "$shards" "$iterations" || die "--iterations $iterations is not a multiple of --shards $shards"
[ $((iterations % shards)) -eq 0 ] || die "--iterations $iterations is not a multiple of --shards $shards"
per=$((iterations / shards))
[ "$per" -le "$maxPerTask" ] || die "--iterations $iterations over --shards $shards is $per iterations a task;" \
  "loom render runs at most $maxPerTask (its --frames limit): give more --shards"
[ $((last + iterations - 1)) -le "$maxHeldIndex" ] ||
  die "--frames '$frames' --iterations $iterations: frame $last's last iteration would be index" \
    "$((last + iterations - 1)), past loom render's $maxHeldIndex (--start-frame + --seed-offset + --frames - 1):" \
    "give fewer iterations"
count=$((last - first + 1))
[ "$shards" -le "$maxTasks" ] && [ $((count * shards)) -le "$maxTasks" ] ||
  die "$count frame(s) x $shards shard(s) is more tasks than a Slurm job array holds ($maxTasks)"
tasks=$((count * shards))
if [ -n "${LOOM_THREADS:-}" ]; then
  [[ "$LOOM_THREADS" =~ ^[0-9]{1,4}$ ]] && [ $((10#$LOOM_THREADS)) -le 1024 ] ||
    die "LOOM_THREADS='$LOOM_THREADS' is not a thread count (0 to 1024, 0: one per core)"
fi

# Paths: absolute, since the tasks run in --out on other nodes.
absolute() {  # VARIABLE PATH
  case "$2" in
    /*) printf -v "$1" %s "$2" ;;
    *) printf -v "$1" %s "$PWD/$2" ;;
  esac
}
if [[ "$loom" != */* ]]; then
  found="$(command -v -- "$loom")" || die "no loom binary '$loom' on PATH (give --loom a path)"
  loom="$found"
fi
absolute loom "$loom"
absolute graph "$graph"
absolute scene "$scene"
absolute out "$out"
[ -f "$loom" ] && [ -x "$loom" ] || die "no loom binary at $loom (build it, or give --loom)"
for f in "$graph" "$scene"; do [ -f "$f" ] || die "no such file: $f"; done
existing="$out"  # the nearest part of --out that exists must be a writable folder
while [ ! -e "$existing" ]; do
  existing="${existing%/*}"
  existing="${existing:-/}"
done
[ -d "$existing" ] || die "--out $out: $existing is not a folder"
[ -w "$existing" ] || die "--out $out: $existing is not writable"
for c in sbatch squeue; do command -v "$c" > /dev/null || die "$c not found: is this a Slurm submit host?"; done
# --sbatch: words at whitespace, as they are (no globbing, no quotes, no expansion).
sbatchWords=()
read -r -d '' -a sbatchWords <<< "$sbatchArgs" || true

# What the tasks' `loom render` would refuse (the graph, the scene, --size, --set, its frame and seed limits), found
# here before anything is submitted: the first and the last task's exact commands (the last has the highest frame
# and seed offset), run dry (`--dry-run`: checked, nothing rendered or written).
for t in 0 $((tasks - 1)); do
  frame=$((first + t / shards)) shard=$((t % shards))
  if ! refusal="$("$loom" render --dry-run --graph "$graph" --scene "$scene" --size "$size" --start-frame "$frame" \
    --hold --frames "$per" --seed-offset "$((shard * per))" --threads "${LOOM_THREADS:-0}" --quiet \
    --out "$out/shards/dry-run" "${sets[@]}" 2>&1 > /dev/null)"; then
    die "the tasks would fail: loom render refuses task $t (frame $frame, shard $shard):"$'\n'"$refusal"
  fi
done

mkdir -p -- "$out/shards" "$out/frames" "$out/slurm/logs"

# The job scripts: first this run's values as quoted assignments, then a fixed script that only reads them (Slurm
# keeps a copy of each script as it is at submission). The task: frame first + t / shards, shard t % shards, its
# samples from seed offset shard * per, rendered into a temporary folder and renamed: a shard's folder exists only
# when it is complete. The merge: each frame's shards, in the same way.
values() {
  (
    export LC_ALL=C  # %q quotes byte by byte
    echo '#!/usr/bin/env bash'
    echo "# Written by scripts/slurm/reference.sh. This run's values:"
    echo 'set -euo pipefail'
    printf 'loom=%q\ngraph=%q\nscene=%q\nsize=%q\nout=%q\n' "$loom" "$graph" "$scene" "$size" "$out"
    printf 'first=%q\nlast=%q\nshards=%q\nper=%q\n' "$first" "$last" "$shards" "$per"
    printf 'sets=('
    [ ${#sets[@]} -eq 0 ] || printf ' %q' "${sets[@]}"
    printf ' )\n'
  )
}
{
  values
  cat << 'EOF'
t=$((10#${SLURM_ARRAY_TASK_ID:?is not set: this script is a Slurm array task}))
frame=$((first + t / shards)) shard=$((t % shards))
printf -v dest '%s/shards/%04d/shard_%03d' "$out" "$frame" "$shard"
if [ -d "$dest" ]; then
  echo "shard done already: $dest"
  exit 0
fi
tmp="$dest.partial.${SLURM_JOB_ID:?is not set}"
rm -rf -- "$tmp"
mkdir -p -- "${dest%/*}"
"$loom" render --graph "$graph" --scene "$scene" --size "$size" --start-frame "$frame" --hold --frames "$per" \
  --seed-offset "$((shard * per))" --threads "${LOOM_THREADS:-${SLURM_CPUS_ON_NODE:-0}}" --quiet --out "$tmp" \
  "${sets[@]}"
mv -T -- "$tmp" "$dest"
EOF
} > "$out/slurm/task.sh"
{
  values
  cat << 'EOF'
for ((frame = first; frame <= last; ++frame)); do
  printf -v f %04d "$frame"
  dest="$out/frames/$f"
  [ ! -d "$dest" ] || continue
  parts=()
  for ((shard = 0; shard < shards; ++shard)); do
    printf -v part '%s/shards/%s/shard_%03d' "$out" "$f" "$shard"
    parts+=("$part")
  done
  rm -rf -- "$dest.partial"
  "$loom" image merge "${parts[@]}" -o "$dest.partial"
  mv -T -- "$dest.partial" "$dest"
done
EOF
} > "$out/slurm/merge.sh"
chmod +x "$out/slurm/task.sh" "$out/slurm/merge.sh"

# A shard's folder, which exists only when the shard is complete; a frame's merged folder, likewise.
shardDir() { printf '%s/shards/%04d/shard_%03d' "$out" "$1" "$2"; }
frameDir() { printf '%s/frames/%04d' "$out" "$1"; }

# Only what is missing is submitted.
missing=()
for ((t = 0; t < tasks; ++t)); do
  frame=$((first + t / shards)) shard=$((t % shards))
  [ -d "$(shardDir "$frame" "$shard")" ] || missing+=("$t")
done
merged=0
for ((frame = first; frame <= last; ++frame)); do
  [ ! -d "$(frameDir "$frame")" ] || merged=$((merged + 1))
done
if [ ${#missing[@]} -eq 0 ] && [ "$merged" -eq "$count" ]; then
  echo "all $count frame(s) merged already in $out/frames"
  exit 0
fi
# Logs are named relative to --chdir: sbatch reads % and \ in --output as a pattern, and --out may hold either.
common=(--parsable --chdir "$out" "${sbatchWords[@]}")
jobs=()
dependency=()
array=""
if [ ${#missing[@]} -gt 0 ]; then
  # The missing tasks as ranges: 0-5,8,10-11.
  list="" i=0
  while [ "$i" -lt ${#missing[@]} ]; do
    a=${missing[i]} b=${missing[i]}
    while [ $((i + 1)) -lt ${#missing[@]} ] && [ "${missing[i + 1]}" -eq $((b + 1)) ]; do
      i=$((i + 1)) b=${missing[i]}
    done
    list+="${list:+,}$a"
    [ "$b" -eq "$a" ] || list+="-$b"
    i=$((i + 1))
  done
  array="$(sbatch "${common[@]}" --job-name loom-shards --array "$list" \
    --output "slurm/logs/task_%A_%a.log" "$out/slurm/task.sh")"
  array="${array%%;*}"
  jobs+=("$array")
  dependency=(--dependency "afterok:$array" --kill-on-invalid-dep=yes)
  echo "submitted $array: ${#missing[@]} of $tasks shard task(s) ($count frame(s) x $shards shard(s), $per iteration(s) each)"
fi
if ! merge="$(sbatch "${common[@]}" "${dependency[@]}" --job-name loom-merge --output "slurm/logs/merge_%j.log" \
  "$out/slurm/merge.sh")"; then
  # The shards would be rendered and never merged: take them back.
  [ -z "$array" ] || scancel "$array" 2> /dev/null || true
  echo "error: sbatch refused the merge job${array:+; the shard array $array was cancelled}" >&2
  exit 1
fi
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
  if [ ! -d "$(shardDir "$frame" "$shard")" ]; then
    failed=1
    log="$out/slurm/logs/task_${array:-none}_$t.log"
    [ -f "$log" ] || log=""
    echo "FAILED: task $t (frame $frame, shard $shard): ${log:-no log}" >&2
    [ -z "$log" ] || tail -5 -- "$log" | sed 's/^/    /' >&2
  fi
done
for ((frame = first; frame <= last; ++frame)); do
  if [ ! -d "$(frameDir "$frame")" ]; then
    failed=1
    echo "FAILED: frame $frame was not merged (log: $out/slurm/logs/merge_$merge.log)" >&2
  fi
done
[ "$failed" -eq 0 ] || { echo "run the same command again to redo only what is missing" >&2; exit 1; }
echo "done: $count frame(s) in $out/frames"

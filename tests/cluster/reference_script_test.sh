#!/usr/bin/env bash
# scripts/slurm/reference.sh without a cluster. Stand-ins for sbatch, squeue and scancel, first on PATH, record their
# arguments; sbatch runs each job at once, here, in order: an array's tasks (--array lists of ranges,
# SLURM_ARRAY_TASK_ID, SLURM_JOB_ID) in the job's --chdir with its --output log, and a dependent job (afterok) only
# when every task of the job it depends on succeeded.
# Checks:
# - frame numbers are decimal: 010-012 renders and merges frames 10, 11 and 12 (the merged EXRs' loomHeldFrame);
# - a rerun finds everything done; deleted shards are submitted again alone, as ranges of array indices;
# - every bad argument is refused with exit 2 and its message before anything is submitted or created;
# - a command substitution, backtick, quote, backslash, % pattern, glob or newline in any value (--out, --scene,
#   --graph, --loom, --set, --sbatch) reaches the tasks and sbatch as plain text and never runs; real renders land
#   in a folder named literally so.
# Usage: reference_script_test.sh LOOM_BINARY SOURCE_DIR
set -euo pipefail
loom="$(cd "$(dirname "$1")" && pwd)/$(basename "$1")"
src="$(cd "$2" && pwd)"
script="$src/scripts/slurm/reference.sh"
t="$(mktemp -d /tmp/loom-reference-script.XXXXXX)"
trap '[ -n "${KEEP:-}" ] || rm -rf "$t"' EXIT
passed=0 failed=0
pass() { passed=$((passed + 1)); echo "ok: $*"; }
fail() { failed=$((failed + 1)); echo "FAIL: $*"; }

# The stand-ins. SLURM_STATE is their state: sbatch.log (one line per call, each argument %q-quoted), job ids, failed jobs.
mkdir "$t/bin" "$t/slurm-state" "$t/cwd"
export SLURM_STATE="$t/slurm-state"
cat > "$t/bin/sbatch" << 'EOF'
#!/usr/bin/env bash
set -uo pipefail
{ printf '%q ' "$@"; echo; } >> "$SLURM_STATE/sbatch.log"
array="" chdir="$PWD" output="slurm-%j.out" dependency=""
while [ $# -gt 0 ]; do
  case "$1" in
    --array) array="$2"; shift 2 ;;
    --chdir) chdir="$2"; shift 2 ;;
    --output) output="$2"; shift 2 ;;
    --dependency) dependency="$2"; shift 2 ;;
    --job-name) shift 2 ;;
    --*) shift ;;  # flags and --option=value words: accepted
    *) break ;;
  esac
done
[ $# -ge 1 ] && [ -x "$1" ] || { echo "fake sbatch: no executable batch script" >&2; exit 1; }
script="$1"
next() {
  local n
  n=$(($(cat "$SLURM_STATE/ids" 2> /dev/null || echo 100) + 1))
  echo "$n" > "$SLURM_STATE/ids"
  echo "$n"
}
job="$(next)"
logFile() {  # ARRAY_INDEX JOB_ID
  local p="$output"
  p="${p//\%A/$job}" p="${p//\%a/$1}" p="${p//\%j/$2}"
  [[ "$p" == /* ]] || p="$chdir/$p"
  printf %s "$p"
}
if [ -n "$dependency" ] && [ -e "$SLURM_STATE/failed.${dependency#afterok:}" ]; then
  touch "$SLURM_STATE/cancelled.$job"  # --kill-on-invalid-dep=yes
elif [ -n "$array" ]; then
  IFS=, read -r -a items <<< "$array"
  for item in "${items[@]}"; do
    if [[ "$item" =~ ^([0-9]+)-([0-9]+)$ ]]; then
      a=${BASH_REMATCH[1]} b=${BASH_REMATCH[2]}
    elif [[ "$item" =~ ^[0-9]+$ ]]; then
      a=$item b=$item
    else
      echo "fake sbatch: array item '$item' not understood" >&2
      exit 1
    fi
    for ((i = a; i <= b; ++i)); do
      id="$(next)"
      (cd "$chdir" && SLURM_ARRAY_JOB_ID=$job SLURM_ARRAY_TASK_ID=$i SLURM_JOB_ID=$id exec "$script") \
        > "$(logFile "$i" "$id")" 2>&1 || touch "$SLURM_STATE/failed.$job"
    done
  done
else
  (cd "$chdir" && SLURM_JOB_ID=$job exec "$script") > "$(logFile "" "$job")" 2>&1 || touch "$SLURM_STATE/failed.$job"
fi
echo "$job;local"
EOF
for c in squeue scancel; do
  printf '#!/usr/bin/env bash\n{ printf "%%q " "$@"; echo; } >> "$SLURM_STATE/%s.log"\n' "$c" > "$t/bin/$c"
done
chmod +x "$t/bin/"*
export PATH="$t/bin:$PATH"
export LOOM_THREADS=1
calls() { if [ -f "$SLURM_STATE/sbatch.log" ]; then wc -l < "$SLURM_STATE/sbatch.log"; else echo 0; fi; }

# The frame a merged reference holds: its EXR header's loomHeldFrame (a string attribute).
heldFrame() {
  python3 - "$1" << 'PY'
import struct, sys
data = open(sys.argv[1], "rb").read(1 << 16)
key = b"loomHeldFrame\0string\0"
i = data.index(key) + len(key)
n = struct.unpack("<i", data[i:i + 4])[0]
print(data[i + 4:i + 4 + n].decode())
PY
}
heldFrames() {  # OUT FRAME...: the held frames of OUT's merged references, or "missing"
  local out="$1" f held=""
  shift
  for f in "$@"; do held+="$(heldFrame "$out/frames/$f/Accumulate.mean.$f.exr" 2> /dev/null || echo missing) "; done
  echo "${held% }"
}

scene="$src/data/scenes/cornell_dynamic.gltf"
graph="$src/graphs/ReferenceShard.json"
small=(--size 32x24 --iterations 2 --shards 2 --set PathTracer.samplesPerPixel=1 --set PathTracer.device=cpu)

# --- Frame numbers are decimal.
out="$t/octal"
run=("$script" --loom "$loom" --graph "$graph" --scene "$scene" "${small[@]}" --frames 010-012 --out "$out")
if "${run[@]}" > "$t/octal.log" 2>&1; then
  held="$(heldFrames "$out" 0010 0011 0012)"
  if [ "$held" = "10 11 12" ] && [ "$(ls "$out/frames")" = $'0010\n0011\n0012' ]; then
    pass "--frames 010-012 renders and merges frames 10, 11 and 12"
  else
    fail "--frames 010-012: held frames '$held', frame folders: $(ls "$out/frames" | tr '\n' ' ')"
  fi
else
  fail "--frames 010-012 exited $?: $(tail -5 "$t/octal.log")"
fi
# Resumable: nothing is submitted again; deleted shards are, alone, as ranges (tasks 2, 3 and 5 of 0-5).
before="$(calls)"
if again="$("${run[@]}" 2>&1)" && [[ "$again" == *"merged already"* ]] && [ "$(calls)" = "$before" ]; then
  pass "a rerun finds every frame merged and submits nothing"
else
  fail "the rerun: $again (sbatch calls $before -> $(calls))"
fi
rm -rf "$out/shards/0011" "$out/shards/0012/shard_001" "$out/frames/0011" "$out/frames/0012"
if again="$("${run[@]}" 2>&1)" && grep -qF -- "--array $(printf %q 2-3,5) " "$SLURM_STATE/sbatch.log" &&
  [[ "$again" == *"3 of 6 shard task"* ]] && [ "$(heldFrames "$out" 0011 0012)" = "11 12" ]; then
  pass "deleted shards are submitted again alone (--array 2-3,5) and their frames merged"
else
  fail "resuming deleted shards: $again; $(tail -2 "$SLURM_STATE/sbatch.log")"
fi

# --- Bad arguments: exit 2, the message, and nothing submitted or created.
refused() {  # NAME MESSAGE COMMAND...
  local name="$1" message="$2" before rc=0
  shift 2
  before="$(calls)"
  rm -rf "$t/bad"
  (cd "$t/cwd" && "$@") > "$t/bad.log" 2>&1 || rc=$?
  if [ "$rc" -eq 2 ] && grep -qF -- "$message" "$t/bad.log" && [ "$(calls)" = "$before" ] && [ ! -e "$t/bad" ]; then
    pass "$name: exit 2, '$message'"
  else
    fail "$name: exit $rc, sbatch calls $before -> $(calls), output folder $([ -e "$t/bad" ] && echo made || echo absent): $(cat "$t/bad.log")"
  fi
}
bad=("$script" --loom "$loom" --graph "$graph" --scene "$scene" "${small[@]}" --frames 0-1 --out "$t/bad")
refused "--shards 1" "--shards 1: loom image merge needs two or more" "${bad[@]}" --iterations 2 --shards 1
refused "--shards 0" "--shards must be 2 or more" "${bad[@]}" --shards 0
refused "--iterations 0" "--iterations must be 1 or more" "${bad[@]}" --iterations 0
refused "--iterations 3 --shards 2" "not a multiple of --shards 2" "${bad[@]}" --iterations 3
refused "--size 0x0" "--size" "${bad[@]}" --size 0x0
refused "--size big" "--size" "${bad[@]}" --size 99999999999999999999x2
refused "--set Nope.x=1" "Nope" "${bad[@]}" --set Nope.x=1
refused "--set PathTracer.samplesPerPixel=-1" "samplesPerPixel" "${bad[@]}" --set PathTracer.samplesPerPixel=-1
refused "--frames past --start-frame's limit" "beyond loom render's last frame (1000000000" \
  "${bad[@]}" --frames 999999999-1000000001
refused "--frames of 25 digits" "beyond loom render's last frame" "${bad[@]}" --frames 0-9999999999999999999999999
refused "--frames 5-3" "A is after B" "${bad[@]}" --frames 5-3
refused "--frames 08" "is not A-B" "${bad[@]}" --frames 08
refused "--frames 0x1-2" "'0x1' is not a decimal number" "${bad[@]}" --frames 0x1-2
refused "--frames -1-2" "is not A-B" "${bad[@]}" --frames -1-2
refused "iterations per task past --frames' limit" "loom render runs at most 1000000" \
  "${bad[@]}" --iterations 2000002 --shards 2
refused "--iterations 2^64" "--iterations 18446744073709551616: too many" "${bad[@]}" --iterations 18446744073709551616
refused "iterations past the held index limit" "frame 1000000000's last iteration would be index 4299999999" \
  "${bad[@]}" --frames 999999999-1000000000 --iterations 3300000000 --shards 4000
refused "too many tasks" "more tasks than a Slurm job array holds" "${bad[@]}" --frames 0-1000 --shards 8000 \
  --iterations 8000
refused "--out last without its value" "--out needs a value" "${bad[@]}" --out
refused "--set last without its value" "--set needs a value" "${bad[@]}" --set
refused "--sbatch last without its value" "--sbatch needs a value" "${bad[@]}" --sbatch
refused "an unknown argument" "unknown argument '--bogus'" "${bad[@]}" --bogus
refused "a missing scene" "no such file" "${bad[@]}" --scene "$t/nothing.gltf"
refused "a scene loom cannot load" "loom render refuses task 0" "${bad[@]}" --scene "$graph"
refused "a graph loom cannot load" "loom render refuses task 0" "${bad[@]}" --graph "$scene"
refused "no loom binary" "no loom binary" "${bad[@]}" --loom "$t/nothing/loom"
refused "LOOM_THREADS=x" "LOOM_THREADS='x' is not a thread count" env LOOM_THREADS=x "${bad[@]}"
refused "LOOM_THREADS=2000" "LOOM_THREADS='2000' is not a thread count" env LOOM_THREADS=2000 "${bad[@]}"
: > "$t/file"
refused "--out a file" "is not a folder" "${bad[@]}" --out "$t/file/bad"

# --- Values are data. Every path and value holds a command substitution, a backtick command, quotes, a backslash,
# sbatch's % patterns, a glob and a newline; were any of them evaluated, a PWNED file would appear (relative ones
# in the folder the command ran in: the cwd, or --out through --chdir).
odd=$'odd "dq\' sq $(touch PWNED1) `touch PWNED2` \\b %A%a%j %% *[x]? ;&|<>\nline2'
mkdir -p "$t/$odd/bin"
cp "$graph" "$t/$odd/ReferenceShard.json"
cp "$scene" "$t/$odd/scene.gltf"
noPwned() { [ -z "$(find "$t" "$src" -maxdepth 4 -name 'PWNED*' -print -quit)" ]; }
# A loom that records its arguments (NUL-separated, one file per call) and makes the folders it would write.
export FAKE_LOOM_CALLS="$t/fake-loom"
mkdir "$FAKE_LOOM_CALLS"
cat > "$t/$odd/bin/loom" << 'EOF'
#!/usr/bin/env bash
name="$1"
for a in "$@"; do [ "$a" != --dry-run ] || name=dry-run; done
printf '%s\0' "$@" > "$(mktemp "$FAKE_LOOM_CALLS/$name.XXXXXX")"
[ "$name" != dry-run ] || exit 0
while [ $# -gt 0 ]; do
  case "$1" in --out | -o) mkdir -p -- "$2" && : > "$2/fake.exr" ;; esac
  shift
done
EOF
chmod +x "$t/$odd/bin/loom"
setValue="PathTracer.samplesPerPixel=1 \$(touch PWNED3) \`touch PWNED4\` \"'\\"
sbatchWords=("--comment=\$(touch\${IFS}PWNED5)" "--begin=\`touch\${IFS}PWNED6\`" "--x=\"'\\" "--glob=*" "--y=%j")
out="$t/$odd/out"
before="$(calls)"
rc=0
(cd "$t/cwd" && "$script" --loom "$t/$odd/bin/loom" --graph "$t/$odd/ReferenceShard.json" \
  --scene "$t/$odd/scene.gltf" --size 32x24 --frames 7-7 --iterations 4 --shards 2 --set "$setValue" \
  --sbatch "${sbatchWords[*]}" --out "$out") > "$t/odd.log" 2>&1 || rc=$?
argAfter() {  # CALL_FILE OPTION: the argument after OPTION in a recorded call
  local args i
  mapfile -d '' args < "$1"
  for ((i = 0; i + 1 < ${#args[@]}; ++i)); do [ "${args[i]}" != "$2" ] || { printf %s "${args[i + 1]}"; return; }; done
  return 1
}
problems=""
[ "$rc" -eq 0 ] || problems+="exit $rc: $(tail -5 "$t/odd.log"); "
renders=("$FAKE_LOOM_CALLS"/render.*)
[ ${#renders[@]} -eq 2 ] || problems+="${#renders[@]} renders, not 2; "
offsets=""
for r in "${renders[@]}"; do
  [ -f "$r" ] || continue
  [ "$(argAfter "$r" --graph)" = "$t/$odd/ReferenceShard.json" ] || problems+="render --graph $(argAfter "$r" --graph); "
  [ "$(argAfter "$r" --scene)" = "$t/$odd/scene.gltf" ] || problems+="render --scene $(argAfter "$r" --scene); "
  [ "$(argAfter "$r" --set)" = "$setValue" ] || problems+="render --set $(argAfter "$r" --set); "
  [ "$(argAfter "$r" --start-frame)" = 7 ] || problems+="render --start-frame $(argAfter "$r" --start-frame); "
  [[ "$(argAfter "$r" --out)" == "$out/shards/0007/shard_00"[01]".partial."* ]] ||
    problems+="render --out $(argAfter "$r" --out); "
  offsets+="$(argAfter "$r" --seed-offset) "
done
[ "$(tr ' ' '\n' <<< "$offsets" | sort -n | xargs)" = "0 2" ] || problems+="seed offsets $offsets; "
merges=("$FAKE_LOOM_CALLS"/image.*)
if [ -f "${merges[0]}" ]; then
  mapfile -d '' args < "${merges[0]}"
  expected=(image merge "$out/shards/0007/shard_000" "$out/shards/0007/shard_001" -o "$out/frames/0007.partial")
  [ "${args[*]}" = "${expected[*]}" ] || problems+="merge called as: ${args[*]}; "
else
  problems+="no merge; "
fi
dry=("$FAKE_LOOM_CALLS"/dry-run.*)
[ ${#dry[@]} -eq 2 ] || problems+="${#dry[@]} dry runs, not 2 (the first and the last task); "
dryOffsets=""
for d in "${dry[@]}"; do
  [ -f "$d" ] || continue
  [ "$(argAfter "$d" --set)" = "$setValue" ] || problems+="dry run --set $(argAfter "$d" --set); "
  dryOffsets+="$(argAfter "$d" --seed-offset) "
done
[ "$(tr ' ' '\n' <<< "$dryOffsets" | sort -n | xargs)" = "0 2" ] || problems+="dry-run seed offsets $dryOffsets; "
[ -d "$out/frames/0007" ] && [ -d "$out/shards/0007/shard_001" ] || problems+="the outputs are not in --out; "
logs=("$out/slurm/logs/"*.log)
[ ${#logs[@]} -eq 3 ] || problems+="${#logs[@]} job logs in --out, not 3; "
[ "$(calls)" -eq $((before + 2)) ] || problems+="$(($(calls) - before)) sbatch calls, not 2; "
for w in "${sbatchWords[@]}"; do
  [ "$(tail -2 "$SLURM_STATE/sbatch.log" | grep -cF -- " $(printf %q "$w") ")" -eq 2 ] ||
    problems+="sbatch did not get '$w' as one word in both jobs; "
done
noPwned || problems+="a value was run as a command: $(find "$t" "$src" -maxdepth 4 -name 'PWNED*' | head -3); "
if [ -z "$problems" ]; then
  pass "odd characters in --out, --scene, --graph, --loom, --set and --sbatch reach the tasks as plain text"
else
  fail "odd characters: $problems"
fi

# The same with the real loom (through a link in the odd folder) and real renders: frames 08-09 (not octal) land
# in the literally named folder.
ln -s "$loom" "$t/$odd/bin/loom-real"
out="$t/$odd/real"
rc=0
(cd "$t/cwd" && "$script" --loom "$t/$odd/bin/loom-real" --graph "$t/$odd/ReferenceShard.json" \
  --scene "$t/$odd/scene.gltf" "${small[@]}" --frames 08-09 --sbatch "${sbatchWords[*]}" --out "$out") \
  > "$t/real.log" 2>&1 || rc=$?
held="$(heldFrames "$out" 0008 0009)"
if [ "$rc" -eq 0 ] && [ "$held" = "8 9" ] && noPwned; then
  pass "real renders of --frames 08-09 land in a folder named with odd characters"
else
  fail "real renders into an odd folder: exit $rc, held frames '$held': $(tail -5 "$t/real.log")"
fi

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]

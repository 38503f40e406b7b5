#!/usr/bin/env bash
# tools/bench_pathtracer.sh's table, from stand-ins for its two programs (the Embree anchor and
# loom_bench_pathtracer) so that it runs in a moment: on a build with the CUDA backend and no usable device, the
# skipped CUDA benchmarks (no paths/s counter) are named and left out of the table; with a device, the CPU and CUDA
# rows are both shown, neither in the place of the other.
# Usage: bench_pathtracer_test.sh SOURCE_DIR
set -euo pipefail
src="$(cd "$1" && pwd)"
t="$(mktemp -d /tmp/loom-bench-pt-test.XXXXXX)"
trap 'rm -rf "$t"' EXIT
passed=0 failed=0
pass() { passed=$((passed + 1)); echo "ok: $*"; }
fail() { failed=$((failed + 1)); echo "FAIL: $*"; }

# The script as it is, beside a stand-in anchor; a stand-in build folder per case.
mkdir -p "$t/tools"
cp "$src/tools/bench_pathtracer.sh" "$t/tools/"
cat > "$t/tools/anchor_embree_pathtracer.sh" << 'A'
#!/usr/bin/env bash
while [ $# -gt 0 ]; do [ "$1" = --out ] && out="$2"; shift; done
mkdir -p "$out"
printf 'length\tms_per_frame\tpaths_per_s\n1\t10.0\t100000000\n3\t20.0\t50000000\n8\t40.0\t25000000\n' > "$out/results.tsv"
A
chmod +x "$t/tools/anchor_embree_pathtracer.sh"
# BUILD/bin/loom_bench_pathtracer writing the JSON of Google Benchmark: the CPU runs, then the CUDA runs as given.
fakeBuild() {  # FOLDER CUDA_ENTRY_TEMPLATE (with L for the path length)
  mkdir -p "$1/bin"
  {
    echo '#!/usr/bin/env bash'
    echo 'for a; do case "$a" in --benchmark_out=*) out="${a#*=}" ;; esac; done'
    echo 'cat > "$out" << "J"'
    echo '{"context": {}, "benchmarks": ['
    for L in 1 3 8; do
      echo "{\"name\": \"BM_PathTracer/$L/min_time:3.000/real_time\", \"run_type\": \"iteration\"," \
        "\"real_time\": $((L * 5)).0, \"paths/s\": $((200000000 / L)).0},"
    done
    for L in 1 3 8; do echo "${2//L/$L}$([ "$L" = 8 ] || echo ,)"; done
    echo ']}'
    echo 'J'
  } > "$1/bin/loom_bench_pathtracer"
  chmod +x "$1/bin/loom_bench_pathtracer"
}

bench() {  # BUILD: runs the script, prints its output, removes the raw results it leaves in /tmp
  local output rc=0
  output="$("$t/tools/bench_pathtracer.sh" "$1" 2>&1)" || rc=$?
  rm -rf -- "$(sed -n 's/^(raw results in \(\/tmp\/loom-bench-pt\..*\))$/\1/p' <<< "$output")"
  printf '%s\n' "$output"
  return "$rc"
}

# No usable CUDA device: the CUDA entries carry an error and no counters.
fakeBuild "$t/nogpu" '{"name": "BM_PathTracerCuda/L/min_time:2.000/real_time", "run_type": "iteration", "error_occurred": true, "error_message": "no usable CUDA device", "real_time": 0.0}'
if table="$(bench "$t/nogpu")"; then
  rows="$(grep -c '^| [0-9]' <<< "$table" || true)"
  if [ "$rows" -eq 3 ] && grep -q '^| 1 | 10.0 | 100.00 M | cpu | 5.0 | 200.00 M | 2.00x |$' <<< "$table" &&
    grep -q '^| 8 | 40.0 | 25.00 M | cpu | 40.0 | 25.00 M | 1.00x |$' <<< "$table" &&
    [ "$(grep -c '^skipped: BM_PathTracerCuda/[138]/.*(no usable CUDA device)$' <<< "$table")" -eq 3 ]; then
    pass "skipped CUDA benchmarks are named and left out of the table"
  else
    fail "without a device, the table is wrong: $table"
  fi
else
  fail "without a device, the script failed: $table"
fi

# A device: a CUDA row per length beside the CPU row.
fakeBuild "$t/gpu" '{"name": "BM_PathTracerCuda/L/min_time:2.000/real_time", "run_type": "iteration", "real_time": 1.0, "paths/s": 1000000000.0}'
if table="$(bench "$t/gpu")"; then
  if [ "$(grep -c '^| [0-9]' <<< "$table")" -eq 6 ] &&
    grep -q '^| 3 | 20.0 | 50.00 M | cpu | 15.0 | 66.67 M | 1.33x |$' <<< "$table" &&
    grep -q '^| 3 | 20.0 | 50.00 M | cuda | 1.0 | 1000.00 M | 20.00x |$' <<< "$table" && ! grep -q skipped <<< "$table"; then
    pass "with a device, the CPU and CUDA rows are both shown"
  else
    fail "with a device, the table is wrong: $table"
  fi
else
  fail "with a device, the script failed: $table"
fi

# Nothing measured at all is an error, not an empty table.
fakeBuild "$t/none" '{"name": "BM_PathTracerCuda/L/min_time:2.000/real_time", "run_type": "iteration", "error_occurred": true, "error_message": "x"}'
sed -i '/"BM_PathTracer\//d' "$t/none/bin/loom_bench_pathtracer"
if table="$(bench "$t/none")"; then
  fail "with no throughput at all, the script succeeded: $table"
elif grep -q "no benchmark of loom_bench_pathtracer reported paths/s" <<< "$table"; then
  pass "with no throughput at all, the script fails and says why"
else
  fail "with no throughput at all, the message is wrong: $table"
fi

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]

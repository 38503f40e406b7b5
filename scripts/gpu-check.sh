#!/usr/bin/env bash
# The GPU check, for a machine with an NVIDIA GPU: builds Loom with the path tracer's CUDA backend, runs the GPU
# tests (the frame on the device against the CPU path tracer's, the kernels run on the host, the BVH against
# Embree), then measures path-tracing throughput on the data Cornell box at 1280x720, 1 spp, path lengths 1, 3 and
# 8 on the GPU and on the CPU (and the Embree tutorial path tracer where Debian's embree-tools is installed), and the
# default graph's path tracer at 1280x720 on the GPU; then the graph on the device: the passes placed on cuda against
# emulated (ShippedGraphs.GpuGraphsOnCudaMatchEmulated), `loom check --device cuda` of the GPU graph, and its frame
# time end to end and per pass at 1280x720 and 1920x1080. Prints the tables. About 6 minutes on a 16-core machine
# with one GPU (most of it the build).
# Usage: scripts/gpu-check.sh [build dir, default build/cuda]
#        scripts/gpu-check.sh --prebuilt DIR   skip the build: DIR holds bin/ and plugins/ of a build made with
#                                               LOOM_CUDA=ON elsewhere (for a GPU machine without the dependencies)
set -euo pipefail
cd "$(dirname "$0")/.."
prebuilt=0
if [ "${1:-}" = "--prebuilt" ]; then prebuilt=1; shift; fi
build="${1:-build/cuda}"
out="$(mktemp -d /tmp/loom-gpu-check.XXXXXX)"
if command -v nvidia-smi > /dev/null; then nvidia-smi -L; else echo "nvidia-smi not found: is the driver installed?"; fi

# The build: the release preset's options with the backend required.
if [ "$prebuilt" = 0 ]; then
  if ! command -v cmake > /dev/null || ! command -v ninja > /dev/null; then ./scripts/setup.sh; fi
  cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DLOOM_CUDA=ON > "$out/configure.log"
  cmake --build "$build" -j "$(nproc)" > "$out/build.log" || { tail -30 "$out/build.log"; exit 1; }
fi

# The tests that touch the backend. CudaDevice.* is skipped (not failed) without a usable device: say so loudly.
status=0
"$build/bin/loom_tests" \
  --gtest_filter='CudaDevice.*:CudaKernelsOnHost.*:Bvh.*:AlphaMode.Bvh*:ShippedGraphs.GpuGraphsOnCudaMatchEmulated' 2>&1 |
  tee "$out/tests.log" | grep -E '^\[ +(OK|FAILED|SKIPPED|PASSED) |^\[ .* frame |Failure|Expected|Which is|actual' ||
  true
grep -q "^\[  PASSED  \]" "$out/tests.log" && ! grep -q "^\[  FAILED  \]" "$out/tests.log" || status=1
if grep -q "^\[  SKIPPED \]" "$out/tests.log"; then
  echo "WARNING: the GPU frame test was skipped (no usable CUDA device)"
fi

# Throughput: Loom on the GPU and on the CPU (Google Benchmark), the Embree tutorial where it is installed.
"$build/bin/loom_bench_pathtracer" --benchmark_filter='BM_PathTracer(Cuda)?/' --benchmark_min_time=1 \
  --benchmark_format=json --benchmark_out="$out/loom.json" > "$out/bench.log" 2>&1 || true
anchor="$out/none.tsv"
if command -v pathtracer > /dev/null; then
  tools/anchor_embree_pathtracer.sh --no-install --out "$out/anchor" --frames 10 --warmup 2 > "$out/anchor.log" 2>&1 &&
    anchor="$out/anchor/results.tsv" || true
fi

# The default graph at 1280x720 on the GPU: the path tracer's time per frame (median of 30 after 10 warm-up).
build_loom="$build/bin/loom"
"$build_loom" render --graph graphs/PathTracerSVGF.json --scene data/scenes/cornell_dynamic.gltf --size 1280x720 \
  --frames 40 --set PathTracer.device=cuda --out "$out/default" --quiet --stats "$out/default.json" \
  > "$out/default.log" 2>&1 || echo "the default graph on the GPU failed: see $out/default.log"

# The GPU graph (every pass placed on cuda, G-buffer from GBufferRT): its plan, and 40 frames at two sizes.
"$build_loom" check graphs/PathTracerSVGF_GPU.json --device cuda --size 1280x720 > "$out/gpu_plan.txt" 2>&1 || true
sed -n '/^Devices:/,/^Memory/p' "$out/gpu_plan.txt"
for size in 1280x720 1920x1080; do
  "$build_loom" render --graph graphs/PathTracerSVGF_GPU.json --scene data/scenes/cornell_dynamic.gltf --size "$size" \
    --frames 40 --device cuda --out "$out/gpu_$size" --quiet --stats "$out/gpu_$size.json" > "$out/gpu_$size.log" 2>&1 ||
    echo "the GPU graph at $size failed: see $out/gpu_$size.log"
done

python3 - "$out/loom.json" "$anchor" "$out/default.json" "$out/gpu_1280x720.json" "$out/gpu_1920x1080.json" <<'PY'
import csv, json, os, statistics, sys
loom = {}
if os.path.exists(sys.argv[1]):
    for b in json.load(open(sys.argv[1])).get("benchmarks", []):
        name, length = b["name"].split("/")[:2]
        if b.get("error_occurred"):
            loom[(name, int(length))] = None
        else:
            loom[(name, int(length))] = (b["real_time"], b["paths/s"])
anchor = {}
if os.path.exists(sys.argv[2]):
    rows = list(csv.reader(open(sys.argv[2]), delimiter="\t"))
    for r in rows[1:]:
        d = dict(zip(rows[0], r))
        anchor[int(d["length"])] = (float(d["ms_per_frame"]), float(d["paths_per_s"]))
def cell(v):
    return "n/a" if not v else f"{v[0]:.2f} ms, {v[1]/1e6:.1f} M/s"
print("\n| path length | CUDA | CPU | Embree tutorial (CPU) | CUDA / CPU |")
print("|---|---|---|---|---|")
for L in (1, 3, 8):
    g, c, a = loom.get(("BM_PathTracerCuda", L)), loom.get(("BM_PathTracer", L)), anchor.get(L)
    ratio = f"{g[1]/c[1]:.1f}x" if g and c else "n/a"
    print(f"| {L} | {cell(g)} | {cell(c)} | {cell(a)} | {ratio} |")
if os.path.exists(sys.argv[3]):
    frames = json.load(open(sys.argv[3]))["frames"][10:]
    ms = [f["passes"]["PathTracer"]["ms"] for f in frames if "PathTracer" in f.get("passes", {})]
    if ms:
        print(f"\nDefault graph (PathTracerSVGF, cornell_dynamic, 1280x720, 1 spp, 3 bounces) on the GPU: "
              f"PathTracer {statistics.median(ms):.2f} ms/frame (median of {len(ms)}; goal: under 5 ms)")
rows = []
for path, size, goal in ((sys.argv[4], "1280x720", 5.0), (sys.argv[5], "1920x1080", 10.0)):
    if not os.path.exists(path):
        continue
    frames = json.load(open(path))["frames"][10:]
    if not frames:
        continue
    passes = sorted(frames[0]["passes"])
    total = statistics.median(sum(f["passes"][p]["ms"] for p in f["passes"]) for f in frames)
    per = ", ".join(f"{p} {statistics.median(f['passes'][p]['ms'] for f in frames):.2f}" for p in passes)
    rows.append(f"| {size} | {total:.2f} ms (goal {goal:g}) | {per} |")
if rows:
    print("\n| PathTracerSVGF_GPU on cuda | all passes, median of 30 | per pass (ms) |\n|---|---|---|")
    print("\n".join(rows))
PY
echo "(logs and raw results in $out)"
exit "$status"

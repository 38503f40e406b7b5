#!/usr/bin/env bash
# The equal-error `loom bench` runs over the data scenes at 640x360 and 1280x720 with a static camera, a moving
# camera and a moving object (their last results, measured before the energy-compensated BRDF, are in the git
# history of docs/BENCHMARKS.md; rerun this to replace them). References are cached
# (~/.cache/loom/references or $LOOM_CACHE), so a rerun only pays for the graphs and the brute-force curve.
#
#   tools/bench_docs.sh [OUT]          (OUT defaults to build/bench; plots are copied to docs/img/)
#   CASES="360p-static 720p-static" tools/bench_docs.sh    (a subset)
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-build/bench}
LOOM=${LOOM:-build/release/bin/loom}
GRAPHS=(--graph PathTracerSVGF --graph PathTracerSVGFDirectIndirect --graph PathTracerATrous
        --graph PathTracerAccumulate)
BOX=data/scenes/cornell_box.gltf
DYN=data/scenes/cornell_dynamic.gltf

run() {  # name, then loom bench arguments
  local name=$1
  shift
  if [ -n "${CASES:-}" ] && [[ " $CASES " != *" $name "* ]]; then return; fi
  echo "== $name: loom bench $*" >&2
  "$LOOM" bench "$@" "${GRAPHS[@]}" --out "$OUT/$name" --plot
  mkdir -p docs/img
  cp "$OUT/$name/plot.png" "docs/img/bench_$name.png"
}

# 640x360: 32 frames, 16 of them warm-up.
run 360p-static --scene $BOX --size 640x360 --frames 32 --warmup 16 --reference-spp 1024
run 360p-orbit  --scene $BOX --camera-path orbit --size 640x360 --frames 32 --warmup 16 --reference-spp 64
run 360p-object --scene $DYN --size 640x360 --frames 32 --warmup 16 --reference-spp 64
# 1280x720: the moving cases have 8 measured frames after the 16 warm-up frames and a 32 spp reference (each
# reference spp costs about 0.8 s per frame at this size on the shared 2-core machine).
run 720p-static --scene $BOX --size 1280x720 --frames 32 --warmup 16 --reference-spp 256 --brute-force-max 16
run 720p-orbit  --scene $BOX --camera-path orbit --size 1280x720 --frames 24 --warmup 16 --reference-spp 32
run 720p-object --scene $DYN --size 1280x720 --frames 24 --warmup 16 --reference-spp 32
# A sweep: the A-trous graph's level count on the moving camera (the reference is the 360p-orbit one, cached).
if [ -z "${CASES:-}" ] || [[ " $CASES " == *" 360p-orbit-sweep "* ]]; then
  "$LOOM" bench --scene $BOX --camera-path orbit --size 640x360 --frames 32 --warmup 16 --reference-spp 64 \
    --graph PathTracerATrous --sweep SVGF.iterations=1,2,3,4,5 --out "$OUT/360p-orbit-sweep" --plot
  cp "$OUT/360p-orbit-sweep/plot.png" docs/img/bench_360p-orbit-sweep.png
fi

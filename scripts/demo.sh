#!/usr/bin/env bash
# Builds Loom and renders the data scenes through the shipped graphs.
# Images are written to out/demo/:
#   pattern/    the graph machinery on test passes (PNG), with a dump of every Blur field
#   gbuffer/    every G-buffer channel of the animated Cornell box, 8 frames (EXR)
#   pathtraced/ the Cornell box path traced and accumulated, 8 frames x 16 spp (EXR, linear HDR)
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/build.sh release
loom=build/release/bin/loom
out=out/demo
rm -rf "$out"
mkdir -p "$out/pattern" "$out/gbuffer" "$out/pathtraced"

"$loom" check graphs/TestPattern.json --size 512x512 --dot "$out/pattern/graph.dot" > "$out/pattern/plan.txt"
"$loom" render --graph graphs/TestPattern.json --size 512x512 --frames 8 --out "$out/pattern" \
  --dump 'Blur.*' --dump-frames 7 --stats "$out/pattern/stats.json"

"$loom" render --graph graphs/GBufferRaster.json --scene data/scenes/cornell_dynamic.gltf --size 320x240 \
  --frames 8 --fps 8 --jitter halton --out "$out/gbuffer"

"$loom" render --graph graphs/Reference.json --scene data/scenes/cornell_box.gltf --size 320x320 \
  --frames 8 --set PathTracer.samplesPerPixel=16 --out "$out/pathtraced"

echo
echo "Images written to $out/:"
for d in pattern gbuffer pathtraced; do
  echo "  $d/: $(ls "$out/$d" | wc -l) files, e.g. $(ls "$out/$d" | grep -E '\.(png|exr)$' | tail -1)"
done

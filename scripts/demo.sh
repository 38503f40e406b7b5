#!/usr/bin/env bash
# Builds Loom and renders the data scenes through the shipped graphs.
# Images are written to out/demo/:
#   pattern/    the graph machinery on test passes (PNG), with a dump of every Blur field
#   gbuffer/    every G-buffer channel of the animated Cornell box, 8 frames (EXR)
#   pathtraced/ the Cornell box path traced and accumulated, 8 frames x 16 spp (EXR, linear HDR)
#   denoised/   the default graph (PathTracerSVGF: G-buffer, 1 spp path tracing, SVGF, tone mapping) on the
#               animated Cornell box, 30 frames (PNG), and side_by_side.png of the last frame:
#               1 spp input | SVGF | reference (256 spp), all through the same tone map
#   sequence/   another renderer's frames: Blender's 8-frame Cornell sequence (data/sequences) through
#               DenoiseSequence (PNG), and side_by_side.png of its last frame: 4 spp | SVGF | 4096 spp
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/build.sh release
loom=build/release/bin/loom
out=out/demo
rm -rf "$out"
mkdir -p "$out/pattern" "$out/gbuffer" "$out/pathtraced" "$out/denoised" "$out/asset" "$out/sequence"

"$loom" check graphs/TestPattern.json --size 512x512 --dot "$out/pattern/graph.dot" > "$out/pattern/plan.txt"
"$loom" render --graph graphs/TestPattern.json --size 512x512 --frames 8 --out "$out/pattern" \
  --dump 'Blur.*' --dump-frames 7 --stats "$out/pattern/stats.json"

"$loom" render --graph graphs/GBufferRaster.json --scene data/scenes/cornell_dynamic.gltf --size 320x240 \
  --frames 8 --fps 8 --jitter halton --out "$out/gbuffer"

"$loom" render --graph graphs/Reference.json --scene data/scenes/cornell_box.gltf --size 320x320 \
  --frames 8 --set PathTracer.samplesPerPixel=16 --out "$out/pathtraced"

# The default graph on the dynamic scene. Its last frame is rendered again as the noisy input and as a reference,
# with the same frame index (same random numbers, same animation time) and the same tone map.
scene=data/scenes/cornell_dynamic.gltf
size=320x240
frames=30
last=$((frames - 1))
common=(--scene "$scene" --size "$size" --fps 30 --jitter halton --quiet)
"$loom" check graphs/PathTracerSVGF.json --size "$size" --dot "$out/denoised/graph.dot" > "$out/denoised/plan.txt"
"$loom" render --graph graphs/PathTracerSVGF.json "${common[@]}" --frames "$frames" --out "$out/denoised" \
  --stats "$out/denoised/stats.json"
"$loom" render --graph graphs/PathTracerRaw.json "${common[@]}" --start-frame "$last" --frames 1 \
  --out "$out/denoised/noisy"
# (No warm-up: the accumulation restarts at every frame of a moving scene, so frames before the last add nothing.)
"$loom" render --graph graphs/PathTracerAccumulate.json "${common[@]}" --start-frame "$last" --frames 1 \
  --warmup 0 --set PathTracer.samplesPerPixel=256 --out "$out/denoised/reference"
frame=$(printf '%04d' "$last")
"$loom" image montage "$out/denoised/noisy/ToneMap.dst.$frame.png" "$out/denoised/ToneMap.dst.$frame.png" \
  "$out/denoised/reference/ToneMap.dst.$frame.png" -o "$out/denoised/side_by_side.png"

# A small textured, normal-mapped, metallic object under an environment, the orbit camera moving round it.
"$loom" render --graph graphs/PathTracerSVGF.json --scene data/scenes/asset.gltf --env 0.25,0.3,0.4 \
  --camera-path orbit --size 320x240 --frames 16 --quiet --out "$out/asset"

# Frames Blender rendered (multilayer EXR), denoised by the same SVGF; the noisy input and Blender's reference go
# through the same graph with SVGF off, so all three share the tone map.
seq=(--graph graphs/DenoiseSequence.json --size 64x48 --frames 8 --quiet)
"$loom" render "${seq[@]}" --out "$out/sequence"
"$loom" render "${seq[@]}" --set SVGF.enabled=false --out "$out/sequence/noisy"
"$loom" render "${seq[@]}" --set SVGF.enabled=false --out "$out/sequence/reference" \
  --set 'Frames.color=data/sequences/blender_cornell/reference_####.exr:ViewLayer.Combined'
"$loom" image montage "$out/sequence/noisy/ToneMap.dst.0007.png" "$out/sequence/ToneMap.dst.0007.png" \
  "$out/sequence/reference/ToneMap.dst.0007.png" -o "$out/sequence/side_by_side.png"

echo
echo "Images written to $out/:"
for d in pattern gbuffer pathtraced denoised asset sequence; do
  echo "  $d/: $(ls "$out/$d" | wc -l) files, e.g. $(ls "$out/$d" | grep -E '\.(png|exr)$' | tail -1)"
done
echo "  side by side (1 spp | SVGF | 256 spp reference): $out/denoised/side_by_side.png"
echo "  Blender's frames (4 spp | SVGF | 4096 spp reference): $out/sequence/side_by_side.png"

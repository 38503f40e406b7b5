#!/bin/sh
# Makes data/sequences/loom_lightstep/: data/scenes/cornell_lightstep.gltf rendered by Loom's own path tracer at
# 64x48 on a 120 fps clock, the 44 frames 33 to 76 (the ceiling light dims to a quarter at 20.5/60 s, between frames
# 40 and 41, and stays dim until frame 80), as the files `loom render --dump` writes (ImageSequence's loom preset
# reads them), plus a many-sample reference of each frame. Eight frames before the step give SVGF a full-length
# history (its blend weight reaches alpha after five); the 36 after it let SVGF without temporal gradients settle
# again (a lag figure needs the segment's last half flat: 24 frames were not enough). The folder's README.md says what the files hold. Run from the repository root, after a release build:
#
#     tools/make_loom_lightstep.sh [OUT]      # OUT: data/sequences/loom_lightstep
#
# Every random number comes from the frame index and PathTracer.seed, both fixed here, and the passes run on the
# CPU, so a rerun writes the same pixels.
set -eu

LOOM=${LOOM:-build/release/bin/loom}
OUT=${1:-data/sequences/loom_lightstep}
SCENE=data/scenes/cornell_lightstep.gltf
SIZE=64x48
FPS=120             # the scene's clock: twice the scene's 60 fps, so the dim stretch lasts 40 frames
FIRST=33            # the first frame: graph frame 0 of DenoiseSequence is file 33 (Frames.firstFrame=33)
FRAMES=44           # frames 33..76; the light dims at frame 41, sequence frame 8
SPP=1               # the noisy input, as the default graph renders it
REF_ITERATIONS=64   # the reference: 64 held iterations of 64 spp, 4096 spp a frame
REF_SEED=7919       # the reference's paths are not the noisy frames' (those use seed 0)
# The noisy frames' path tracer (graphs/PathTracerSVGF_GPU.json: 3 bounces, indirect clamp 10, Russian roulette
# from bounce 2); the reference uses the same, so the noisy frames converge to it.
TRACER="--set PathTracer.maxBounces=3 --set PathTracer.indirectClamp=10 --set PathTracer.rrStartBounce=2"

[ -x "$LOOM" ] || { echo "error: $LOOM not found: build first (cmake --build --preset release)" >&2; exit 2; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT INT TERM

# The noisy frames: the default graph's sources (GBufferRT, the path tracer) dumped. No warm-up: nothing they
# write depends on earlier frames, and the camera does not move (mvec is 0, no jitter).
"$LOOM" render --graph graphs/PathTracerSVGF_GPU.json --device cpu --scene "$SCENE" --size "$SIZE" --fps "$FPS" \
    --start-frame "$FIRST" --frames "$FRAMES" --warmup 0 --quiet --out "$work/noisy" $TRACER \
    --set PathTracer.samplesPerPixel="$SPP" \
    --dump PathTracer.color --dump PathTracer.albedo --dump PathTracer.specAlbedo --dump PathTracer.emission \
    --dump GBuffer.normW --dump GBuffer.linearZ --dump GBuffer.mvec --dump GBuffer.meshId

mkdir -p "$OUT"
rm -f "$OUT"/PathTracer.*.exr "$OUT"/GBuffer.*.exr "$OUT"/reference_*.exr
for field in PathTracer.color PathTracer.albedo PathTracer.specAlbedo PathTracer.emission \
             GBuffer.normW GBuffer.linearZ GBuffer.mvec GBuffer.meshId; do
    cp "$work/noisy/$field".*.exr "$OUT/"
done

# The references: each frame held at its own time for REF_ITERATIONS iterations (graphs/Reference.json).
frame=$FIRST
while [ "$frame" -lt $((FIRST + FRAMES)) ]; do
    "$LOOM" render --graph graphs/Reference.json --device cpu --scene "$SCENE" --size "$SIZE" --fps "$FPS" \
        --start-frame "$frame" --frames "$REF_ITERATIONS" --hold --quiet --out "$work/ref" $TRACER \
        --set PathTracer.seed="$REF_SEED"
    number=$(printf %04d "$frame")
    cp "$work/ref/Accumulate.dst.$number.exr" "$OUT/reference_$number.exr"
    frame=$((frame + 1))
done
echo "wrote $OUT"

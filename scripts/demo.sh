#!/usr/bin/env bash
# Builds Loom and renders the default scene through the default graph.
# Images are written to out/demo/.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/build.sh release
loom=build/release/bin/loom
graph=graphs/TestPattern.json
out=out/demo
rm -rf "$out"
mkdir -p "$out"
"$loom" check "$graph" --size 512x512 --dot "$out/graph.dot" > "$out/plan.txt"
"$loom" render --graph "$graph" --size 512x512 --frames 8 --out "$out" \
  --dump 'Blur.*' --dump-frames 7 --stats "$out/stats.json"
echo
echo "Images written to $out/:"
ls "$out"

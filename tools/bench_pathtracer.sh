#!/usr/bin/env bash
# Path-tracing throughput, Loom against its anchor in one run: the Embree
# tutorial path tracer (tools/anchor_embree_pathtracer.sh) and Loom's
# loom_bench_pathtracer, both on data/scenes/cornell_box.gltf at 1280x720,
# 1 spp, path lengths 1, 3 and 8, all cores. Prints paths/s and the ratio.
# Usage: tools/bench_pathtracer.sh [build dir, default build/release]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="${1:-$ROOT/build/release}"
OUT="$(mktemp -d /tmp/loom-bench-pt.XXXXXX)"
"$ROOT/tools/anchor_embree_pathtracer.sh" --out "$OUT/anchor" --frames 20 --warmup 3 > "$OUT/anchor.log"
"$BUILD/bin/loom_bench_pathtracer" --benchmark_format=json --benchmark_out="$OUT/loom.json" > /dev/null
python3 - "$OUT/anchor/results.tsv" "$OUT/loom.json" <<'PY'
import csv, json, sys
anchor = {}
with open(sys.argv[1]) as f:
    rows = list(csv.reader(f, delimiter="\t"))
    head = rows[0]
    for r in rows[1:]:
        d = dict(zip(head, r))
        anchor[int(d["length"])] = (float(d["ms_per_frame"]), float(d["paths_per_s"]))
loom = {}
for b in json.load(open(sys.argv[2]))["benchmarks"]:
    L = int(b["name"].split("/")[1])
    loom[L] = (b["real_time"], b["paths/s"])
print("| path length | Embree tutorial ms/frame | paths/s | Loom ms/frame | paths/s | Loom / Embree |")
print("|---|---|---|---|---|---|")
for L in sorted(loom):
    a, l = anchor[L], loom[L]
    print(f"| {L} | {a[0]:.1f} | {a[1]/1e6:.2f} M | {l[0]:.1f} | {l[1]/1e6:.2f} M | {l[1]/a[1]:.2f}x |")
PY
echo "(raw results in $OUT)"

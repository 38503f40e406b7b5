#!/usr/bin/env bash
# Path-tracing throughput, Loom against its anchor in one run: the Embree
# tutorial path tracer (tools/anchor_embree_pathtracer.sh) and Loom's
# loom_bench_pathtracer, both on data/scenes/cornell_box.gltf at 1280x720,
# 1 spp, path lengths 1, 3 and 8, all cores. Prints paths/s and the ratio, a row
# per device Loom ran on (the CUDA benchmarks are skipped, and named, where no
# device is usable).
# Usage: tools/bench_pathtracer.sh [build dir, default build/release]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="${1:-$ROOT/build/release}"
OUT="$(mktemp -d /tmp/loom-bench-pt.XXXXXX)"
trap 'echo "(raw results in $OUT)"' EXIT
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
# One row per benchmark that ran (BM_PathTracer: the CPU; BM_PathTracerCuda: the CUDA backend). Entries that
# carry no throughput are named and left out: a CUDA benchmark on a machine without a usable device is skipped
# with its reason, and aggregates (--benchmark_repetitions) summarize the runs.
loom, skipped = {}, []
for b in json.load(open(sys.argv[2]))["benchmarks"]:
    name = b["name"]
    if b.get("run_type", "iteration") != "iteration":
        continue
    if b.get("error_occurred") or b.get("skipped") or "paths/s" not in b:
        skipped.append(f"{name} ({b.get('error_message') or 'no paths/s counter'})")
        continue
    family, length = name.split("/")[:2]
    device = "cuda" if family.endswith("Cuda") else "cpu"
    loom[(int(length), device)] = (b["real_time"], b["paths/s"])
print("| path length | Embree tutorial ms/frame | paths/s | Loom device | Loom ms/frame | paths/s | Loom / Embree |")
print("|---|---|---|---|---|---|---|")
for (L, device) in sorted(loom):
    l = loom[(L, device)]
    if L in anchor:
        a = anchor[L]
        print(f"| {L} | {a[0]:.1f} | {a[1]/1e6:.2f} M | {device} | {l[0]:.1f} | {l[1]/1e6:.2f} M | {l[1]/a[1]:.2f}x |")
    else:
        print(f"| {L} | - | - | {device} | {l[0]:.1f} | {l[1]/1e6:.2f} M | - |")
for s in skipped:
    print(f"skipped: {s}")
if not loom:
    sys.exit("error: no benchmark of loom_bench_pathtracer reported paths/s")
PY

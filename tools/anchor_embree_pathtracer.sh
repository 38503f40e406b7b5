#!/usr/bin/env bash
# Anchor for the path-tracing throughput goal: Embree's own tutorial path
# tracer, as shipped by Debian (package embree-tools, binary `pathtracer`),
# rendering the data Cornell box at 1280x720, 1 spp, for several maximum path
# lengths. Prints ms/frame and paths/s for each length and saves one 1-spp
# image per length. See docs/ANCHOR.md for the protocol and its caveats.
#
# This script only calls the installed binaries (pathtracer, assimp); it does
# not build, vendor or patch any Embree code.
#
# Usage: tools/anchor_embree_pathtracer.sh [options]
#   --out DIR        output folder (default: /tmp/loom-anchor)
#   --scene FILE     glTF scene (default: data/scenes/cornell_box.gltf)
#   --lengths "L.."  maximum path lengths (default: "1 3 8")
#   --frames N       timed frames per length (default: 30)
#   --warmup N       untimed frames per length, incl. the BVH build (default: 5)
#   --threads N      render threads (default: nproc, i.e. all cores, as Loom)
#   --size W H       resolution (default: 1280 720)
#   --spp N          samples per pixel per frame (default: 1)
#   --isa ISA        force an Embree ISA (sse4.2, avx2, avx512); default: auto
#   --no-install     never try to apt-get install the packages
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
OUT=/tmp/loom-anchor
SCENE="$ROOT/data/scenes/cornell_box.gltf"
LENGTHS="1 3 8"
FRAMES=30
WARMUP=5
THREADS="$(nproc)"
W=1280; H=720
SPP=1
ISA=""
INSTALL=1

while [ $# -gt 0 ]; do
  case "$1" in
    --out) OUT="$2"; shift 2 ;;
    --scene) SCENE="$2"; shift 2 ;;
    --lengths) LENGTHS="$2"; shift 2 ;;
    --frames) FRAMES="$2"; shift 2 ;;
    --warmup) WARMUP="$2"; shift 2 ;;
    --threads) THREADS="$2"; shift 2 ;;
    --size) W="$2"; H="$3"; shift 3 ;;
    --spp) SPP="$2"; shift 2 ;;
    --isa) ISA="$2"; shift 2 ;;
    --no-install) INSTALL=0; shift ;;
    -h|--help) sed -n '2,25p' "$0"; exit 0 ;;
    *) echo "unknown option: $1" >&2; exit 2 ;;
  esac
done

# --- 1. packages (idempotent) ------------------------------------------------
need_pkgs=()
command -v pathtracer >/dev/null 2>&1 || need_pkgs+=(embree-tools)
command -v assimp     >/dev/null 2>&1 || need_pkgs+=(assimp-utils)
if [ ${#need_pkgs[@]} -gt 0 ]; then
  if [ "$INSTALL" = 1 ] && [ "$(id -u)" = 0 ]; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get install -y "${need_pkgs[@]}" >/dev/null 2>&1 \
      || { apt-get update -qq && apt-get install -y "${need_pkgs[@]}" >/dev/null; }
  else
    echo "missing packages: ${need_pkgs[*]} (run as root, or apt-get install them)" >&2
    exit 1
  fi
fi
PT="$(command -v pathtracer)"
PT_VER="$(dpkg-query -W -f='${Version}' embree-tools 2>/dev/null || echo unknown)"
ASSIMP_VER="$(dpkg-query -W -f='${Version}' assimp-utils 2>/dev/null || echo unknown)"

# --- 2. glTF -> OBJ ----------------------------------------------------------
mkdir -p "$OUT/scene"
NAME="$(basename "$SCENE" .gltf)"
OBJ="$OUT/scene/$NAME.obj"
MTL="$OUT/scene/$NAME.mtl"
assimp export "$SCENE" "$OBJ" >"$OUT/scene/assimp.log" 2>&1 \
  || { cat "$OUT/scene/assimp.log" >&2; exit 1; }

# assimp bakes the node transforms into the vertices but drops the camera and
# KHR_materials_emissive_strength (Ke = emissiveFactor only). Restore Ke to the
# true radiance (factor * strength) in the .mtl for the record, then derive the
# camera and the light for the command line. Embree's OBJ loader ignores Ke and
# the Embree 3 tutorials implement no area/quad/triangle lights (their
# ISPCScene leaves them "not implemented"), so the emitter is replaced by a
# point light of intensity I = L * A just below the emitter's centre (same
# on-axis irradiance as the Lambertian quad), shaded upwards by the emitter quad
# itself, which stays in the scene as geometry.
mapfile -t DERIVED < <(python3 - "$SCENE" "$OBJ" "$MTL" <<'EOF'
import json, math, sys
gltf_path, obj_path, mtl_path = sys.argv[1:4]
g = json.load(open(gltf_path))

def qmat(q):
    x, y, z, w = q
    return [[1-2*(y*y+z*z), 2*(x*y-z*w), 2*(x*z+y*w)],
            [2*(x*y+z*w), 1-2*(x*x+z*z), 2*(y*z-x*w)],
            [2*(x*z-y*w), 2*(y*z+x*w), 1-2*(x*x+y*y)]]
def local(n):
    if 'matrix' in n:
        m = n['matrix']; return [[m[c*4+r] for c in range(4)] for r in range(4)]
    R = qmat(n.get('rotation', [0, 0, 0, 1])); s = n.get('scale', [1, 1, 1])
    t = n.get('translation', [0, 0, 0])
    return [[R[r][0]*s[0], R[r][1]*s[1], R[r][2]*s[2], t[r]] for r in range(3)] + [[0, 0, 0, 1]]
def mul(a, b):
    return [[sum(a[r][k]*b[k][c] for k in range(4)) for c in range(4)] for r in range(4)]
parent = {c: i for i, n in enumerate(g['nodes']) for c in n.get('children', [])}
def world(i):
    m = local(g['nodes'][i])
    while i in parent:
        i = parent[i]; m = mul(local(g['nodes'][i]), m)
    return m

# camera: first node with a camera
ci = next(i for i, n in enumerate(g['nodes']) if 'camera' in n)
M = world(ci)
cam = g['cameras'][g['nodes'][ci]['camera']]['perspective']
p = [M[r][3] for r in range(3)]
fwd = [-M[r][2] for r in range(3)]
up = [M[r][1] for r in range(3)]
nf = math.sqrt(sum(c*c for c in fwd)); nu = math.sqrt(sum(c*c for c in up))
vi = [p[r] + fwd[r]/nf for r in range(3)]
up = [c/nu for c in up]
f = lambda v: ' '.join('%.6g' % c for c in v)
cam_args = '--vp %s --vi %s --vu %s --fov %.6g' % (f(p), f(vi), f(up), math.degrees(cam['yfov']))

# emissive radiance per material name: emissiveFactor * emissive strength
radiance = {}
for m in g.get('materials', []):
    e = m.get('emissiveFactor', [0, 0, 0])
    s = m.get('extensions', {}).get('KHR_materials_emissive_strength', {}).get('emissiveStrength', 1.0)
    if max(e) > 0:
        radiance[m.get('name', '')] = [c*s for c in e]

# patch Ke in the .mtl (documentation value only: embree ignores Ke)
lines, cur = [], None
for line in open(mtl_path):
    t = line.split()
    if t[:1] == ['newmtl']:
        cur = line[len('newmtl'):].strip()
    elif t[:1] == ['Ke'] and cur in radiance:
        line = 'Ke %s\n' % ' '.join('%.6g' % c for c in radiance[cur])
    lines.append(line)
open(mtl_path, 'w').writelines(lines)

# emitter geometry from the OBJ (transforms already baked by assimp)
V, area, cen, nrm, Lsum, mat = [], 0.0, [0, 0, 0], [0, 0, 0], None, None
for line in open(obj_path):
    t = line.split()
    if not t: continue
    if t[0] == 'v': V.append([float(c) for c in t[1:4]])
    elif t[0] == 'usemtl': mat = line[len('usemtl'):].strip()
    elif t[0] == 'f' and mat in radiance:
        idx = [int(c.split('/')[0]) for c in t[1:]]
        idx = [i-1 if i > 0 else len(V)+i for i in idx]
        for k in range(1, len(idx)-1):
            a, b, c = V[idx[0]], V[idx[k]], V[idx[k+1]]
            e1 = [b[r]-a[r] for r in range(3)]; e2 = [c[r]-a[r] for r in range(3)]
            cr = [e1[1]*e2[2]-e1[2]*e2[1], e1[2]*e2[0]-e1[0]*e2[2], e1[0]*e2[1]-e1[1]*e2[0]]
            A = 0.5*math.sqrt(sum(x*x for x in cr))
            area += A
            cen = [cen[r] + A*(a[r]+b[r]+c[r])/3 for r in range(3)]
            nrm = [nrm[r] + 0.5*cr[r] for r in range(3)]
            Lsum = radiance[mat]
if area <= 0:
    sys.exit('no emissive faces found in %s' % obj_path)
cen = [c/area for c in cen]
nn = math.sqrt(sum(c*c for c in nrm)); nrm = [c/nn for c in nrm]
pos = [cen[r] + 0.01*nrm[r] for r in range(3)]          # 1 cm in front of the emitter
I = [c*area for c in Lsum]                                # on-axis intensity L*A
print(cam_args)
print('--pointlight %s %s' % (f(pos), f(I)))
EOF
)
[ ${#DERIVED[@]} -eq 2 ] || { echo "could not derive camera/light from $SCENE" >&2; exit 1; }
read -r -a CAM_ARGS <<<"${DERIVED[0]}"
read -r -a LIGHT_ARGS <<<"${DERIVED[1]}"

COMMON=(-i "$OBJ" "${CAM_ARGS[@]}" "${LIGHT_ARGS[@]}"
        --size "$W" "$H" --spp "$SPP" --threads "$THREADS")
[ -n "$ISA" ] && COMMON+=(--isa "$ISA")

# PPM (what the tutorial writes) -> PNG, standard library only
ppm2png() {
  python3 - "$1" "$2" <<'EOF'
import struct, sys, zlib
d = open(sys.argv[1], 'rb').read()
magic, dims, maxv, px = d.split(b'\n', 3)
assert magic == b'P6' and maxv == b'255'
w, h = map(int, dims.split())
rows = b''.join(b'\0' + px[y*w*3:(y+1)*w*3] for y in range(h))
ch = lambda t, b: struct.pack('>I', len(b)) + t + b + struct.pack('>I', zlib.crc32(t + b))
open(sys.argv[2], 'wb').write(b'\x89PNG\r\n\x1a\n'
    + ch(b'IHDR', struct.pack('>IIBBBBB', w, h, 8, 2, 0, 0, 0))
    + ch(b'IDAT', zlib.compress(rows, 6)) + ch(b'IEND', b''))
EOF
}

# --- 3. measure -----------------------------------------------------------------
CPU="$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
echo "anchor: Embree tutorial path tracer ($PT, embree-tools $PT_VER; assimp-utils $ASSIMP_VER)"
echo "scene:  $SCENE -> $OBJ"
echo "cpu:    $CPU, $(nproc) logical cores; threads=$THREADS${ISA:+ isa=$ISA}"
echo "cmd:    pathtracer ${COMMON[*]} --max-path-length L --benchmark $WARMUP $FRAMES"
printf '%-8s %10s %10s %10s %14s %12s\n' "length" "ms/frame" "min ms" "max ms" "paths/s" "Mrays/s"
RESULTS="$OUT/results.tsv"
printf 'length\tms_per_frame\tmin_ms\tmax_ms\tpaths_per_s\tmrays_per_s\twidth\theight\tspp\tthreads\n' >"$RESULTS"
for L in $LENGTHS; do
  LOG="$OUT/pathtracer_L$L.log"
  "$PT" "${COMMON[@]}" --max-path-length "$L" --benchmark "$WARMUP" "$FRAMES" >"$LOG" 2>&1 \
    || { cat "$LOG" >&2; exit 1; }
  # BENCHMARK_RENDER_{MIN,AVG,MAX} are frames/s (1/frame time), averaged over the timed frames
  read -r AVG MINF MAXF MRAYS < <(awk '
    /^BENCHMARK_RENDER_AVG /{a=$2} /^BENCHMARK_RENDER_MIN /{mn=$2} /^BENCHMARK_RENDER_MAX /{mx=$2}
    /^BENCHMARK_RENDER_MRAYPS_AVG /{r=$2} END{print a, mn, mx, r}' "$LOG")
  [ -n "$AVG" ] || { echo "no benchmark output in $LOG" >&2; exit 1; }
  python3 - "$L" "$AVG" "$MINF" "$MAXF" "$MRAYS" "$W" "$H" "$SPP" "$THREADS" "$RESULTS" <<'EOF'
import sys
L, avg, mn, mx, mr = sys.argv[1], *map(float, sys.argv[2:6])
w, h, spp, thr = map(int, sys.argv[6:10])
ms = 1000.0/avg
paths = w*h*spp*avg
print('%-8s %10.2f %10.2f %10.2f %14.4g %12.2f' % (L, ms, 1000.0/mx, 1000.0/mn, paths, mr))
open(sys.argv[10], 'a').write('%s\t%.3f\t%.3f\t%.3f\t%.6g\t%.3f\t%d\t%d\t%d\t%d\n'
                              % (L, ms, 1000.0/mx, 1000.0/mn, paths, mr, w, h, spp, thr))
EOF
  # one single-frame (1 spp) image per length, for comparison with Loom's
  IMG="$OUT/embree_pathtracer_L$L"
  "$PT" "${COMMON[@]}" --max-path-length "$L" -o "$IMG.ppm" >"$OUT/image_L$L.log" 2>&1 \
    || { cat "$OUT/image_L$L.log" >&2; exit 1; }
  ppm2png "$IMG.ppm" "$IMG.png"
done
echo "results: $RESULTS; images: $OUT/embree_pathtracer_L{$(echo $LENGTHS | tr ' ' ,)}.png"

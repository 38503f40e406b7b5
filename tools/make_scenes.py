#!/usr/bin/env python3
"""Generates Loom's test scenes (glTF 2.0, embedded buffers and images).

    python3 tools/make_scenes.py              # writes data/scenes/*.gltf, then validates them
    python3 tools/make_scenes.py --check      # only validates the existing files
    python3 tools/make_scenes.py --out DIR    # writes somewhere else

Standard library only (json, struct, base64, zlib, math). The output is
deterministic: running the script twice gives byte-identical files.

Conventions: glTF 2.0, right-handed, +Y up, metres. Every file is a single
self-contained .gltf with one buffer and PNG images embedded as base64 data
URIs. Every primitive has NORMAL; flat surfaces have separate vertices per
face. Triangles are counter-clockwise seen from the side the normal points to.
One bufferView per accessor, tightly packed (no byteStride), 4-byte aligned.

Scenes:
  cornell_box.gltf      classic Cornell box, two boxes, emissive ceiling light
  cornell_dynamic.gltf  same room, animated sphere / box / camera
  cornell_lightstep.gltf  the Cornell box whose ceiling light steps between full
                        and a quarter intensity (KHR_animation_pointer)
  materials.gltf        textures, normal maps (with and without TANGENT),
                        roughness/metallic sweep, punctual lights, emissive
  sky_sphere.gltf       one glossy sphere and a sun; the rest of the frame is environment
  asset.gltf            a small worn-paint steel torus knot on a plinth under an environment:
                        textured, normal-mapped, metallic (for denoiser quality claims)
"""
import argparse
import base64
import json
import math
import os
import re
import struct
import sys
import zlib

GENERATOR = "Loom tools/make_scenes.py"
MAX_FILE_BYTES = 1 << 20

# glTF enums
BYTE, UBYTE, SHORT, USHORT, UINT, FLOAT = 5120, 5121, 5122, 5123, 5125, 5126
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
COMPONENT_FMT = {BYTE: "b", UBYTE: "B", SHORT: "h", USHORT: "H", UINT: "I", FLOAT: "f"}
COMPONENT_SIZE = {BYTE: 1, UBYTE: 1, SHORT: 2, USHORT: 2, UINT: 4, FLOAT: 4}
LINEAR_FILTER, REPEAT = 9729, 10497

EXT_EMISSIVE = "KHR_materials_emissive_strength"
EXT_LIGHTS = "KHR_lights_punctual"
EXT_POINTER = "KHR_animation_pointer"


# ----------------------------------------------------------------------------
# Small math helpers (tuples, float64)

def add(a, b): return tuple(x + y for x, y in zip(a, b))
def sub(a, b): return tuple(x - y for x, y in zip(a, b))
def mul(a, s): return tuple(x * s for x in a)
def dot(a, b): return sum(x * y for x, y in zip(a, b))
def cross(a, b): return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
def length(a): return math.sqrt(dot(a, a))
def normalize(a):
    n = length(a)
    return tuple(x / n for x in a)


def num(x, digits=7):
    """A JSON-friendly float: rounded, no negative zero."""
    v = round(float(x), digits)
    return 0.0 if v == 0 else v


def nums(seq, digits=7):
    return [num(x, digits) for x in seq]


def quat_axis_angle(axis, radians):
    """Quaternion (x, y, z, w) rotating by `radians` about `axis` (right-hand rule)."""
    ax = normalize(axis)
    s = math.sin(radians / 2)
    return (ax[0] * s, ax[1] * s, ax[2] * s, math.cos(radians / 2))


def quat_rotate(q, v):
    x, y, z, w = q
    u = (x, y, z)
    t = mul(cross(u, v), 2.0)
    return add(add(v, mul(t, w)), cross(u, t))


def quat_mul(a, b):
    """Hamilton product a * b (rotate by b, then by a)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def quat_from_basis(r, u, b):
    """Quaternion of the rotation whose matrix columns are r (x), u (y), b (z)."""
    m00, m01, m02 = r[0], u[0], b[0]
    m10, m11, m12 = r[1], u[1], b[1]
    m20, m21, m22 = r[2], u[2], b[2]
    tr = m00 + m11 + m22
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = ((m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, 0.25 * s)
    elif m00 > m11 and m00 > m22:
        s = math.sqrt(1.0 + m00 - m11 - m22) * 2
        q = (0.25 * s, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s)
    elif m11 > m22:
        s = math.sqrt(1.0 + m11 - m00 - m22) * 2
        q = ((m01 + m10) / s, 0.25 * s, (m12 + m21) / s, (m02 - m20) / s)
    else:
        s = math.sqrt(1.0 + m22 - m00 - m11) * 2
        q = ((m02 + m20) / s, (m12 + m21) / s, 0.25 * s, (m10 - m01) / s)
    if q[3] < 0:
        q = tuple(-c for c in q)
    return normalize(q)


def quat_look_at(eye, target, up=(0.0, 1.0, 0.0)):
    """Rotation of a camera / spot light (which look down local -Z, +Y up) at `eye` facing `target`."""
    f = normalize(sub(target, eye))
    r = normalize(cross(f, up))
    u = cross(r, f)
    q = quat_from_basis(r, u, mul(f, -1.0))
    assert length(sub(quat_rotate(q, (0.0, 0.0, -1.0)), f)) < 1e-9
    return q


def mat_identity():
    return [[1.0 if i == j else 0.0 for j in range(4)] for i in range(4)]


def mat_mul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def mat_trs(t=(0, 0, 0), q=(0, 0, 0, 1), s=(1, 1, 1)):
    x, y, z, w = q
    r = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    m = mat_identity()
    for i in range(3):
        for j in range(3):
            m[i][j] = r[i][j] * s[j]
        m[i][3] = t[i]
    return m


def mat_point(m, p):
    return tuple(m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3] for i in range(3))


# ----------------------------------------------------------------------------
# PNG encoding (and a full decoder for validation)

def _png_chunk(tag, data):
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)


def _paeth(a, b, c):
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    if pa <= pb and pa <= pc:
        return a
    return b if pb <= pc else c


def encode_png(width, height, rows, srgb, vary_filters=False):
    """rows: `height` bytes objects of width*3 RGB bytes (row 0 = top).

    srgb adds an sRGB chunk (colour data); data maps (normals, roughness) get
    none. vary_filters cycles the row filter through None/Sub/Up/Average/Paeth
    so that decoders are exercised on all five."""
    bpp = 3
    out = bytearray()
    prev = bytes(width * bpp)
    for y, row in enumerate(rows):
        assert len(row) == width * bpp
        ftype = (y % 5) if vary_filters else 0
        out.append(ftype)
        if ftype == 0:
            out += row
        else:
            for i in range(len(row)):
                a = row[i - bpp] if i >= bpp else 0
                b = prev[i]
                c = prev[i - bpp] if i >= bpp else 0
                pred = (0, a, b, (a + b) >> 1, _paeth(a, b, c))[ftype]
                out.append((row[i] - pred) & 0xFF)
        prev = row
    png = b"\x89PNG\r\n\x1a\n"
    png += _png_chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
    if srgb:
        png += _png_chunk(b"sRGB", b"\x00")
    png += _png_chunk(b"IDAT", zlib.compress(bytes(out), 9))
    png += _png_chunk(b"IEND", b"")
    return png


def decode_png(data):
    """Decodes 8-bit RGB/RGBA/grey non-interlaced PNGs; returns (w, h, channels, rows). Raises on any defect."""
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("not a PNG signature")
    pos, idat, ihdr, seen_end = 8, bytearray(), None, False
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        tag = data[pos + 4:pos + 8]
        body = data[pos + 8:pos + 8 + n]
        (crc,) = struct.unpack(">I", data[pos + 8 + n:pos + 12 + n])
        if len(body) != n or zlib.crc32(tag + body) & 0xFFFFFFFF != crc:
            raise ValueError("bad chunk %r" % tag)
        if tag == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif tag == b"IDAT":
            idat += body
        elif tag == b"IEND":
            seen_end = True
            break
        pos += 12 + n
    if ihdr is None or not seen_end:
        raise ValueError("missing IHDR or IEND")
    w, h, depth, ctype, comp, filt, interlace = ihdr
    channels = {0: 1, 2: 3, 4: 2, 6: 4}.get(ctype)
    if depth != 8 or channels is None or comp or filt or interlace:
        raise ValueError("unsupported PNG format %r" % (ihdr,))
    raw = zlib.decompress(bytes(idat))
    stride = w * channels
    if len(raw) != h * (stride + 1):
        raise ValueError("IDAT size %d != %d" % (len(raw), h * (stride + 1)))
    rows, prev = [], bytearray(stride)
    for y in range(h):
        ftype = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        if ftype > 4:
            raise ValueError("bad filter type %d" % ftype)
        for i in range(stride):
            a = line[i - channels] if i >= channels else 0
            b = prev[i]
            c = prev[i - channels] if i >= channels else 0
            pred = (0, a, b, (a + b) >> 1, _paeth(a, b, c))[ftype]
            line[i] = (line[i] + pred) & 0xFF
        rows.append(bytes(line))
        prev = line
    return w, h, channels, rows


# ----------------------------------------------------------------------------
# Textures

def checker_rows(size=256, checks=8, c0=(214, 208, 196), c1=(46, 52, 66)):
    """Base-colour checker (sRGB values), checks x checks squares; top-left square is c0."""
    cell = size // checks
    rows = []
    for y in range(size):
        row = bytearray()
        for x in range(size):
            row += bytes(c0 if ((x // cell) + (y // cell)) % 2 == 0 else c1)
        rows.append(bytes(row))
    return rows


ROUGHNESS_STRIPES = (0.1, 0.4, 0.7, 1.0)  # G, left to right (along +u)
METALLIC_STRIPES = (0.0, 1.0, 0.0, 1.0)   # B, top to bottom (along +v)


def metal_rough_rows(size=128):
    """Linear data: R = 1 (unused occlusion), G = roughness (4 vertical stripes), B = metallic (4 horizontal stripes)."""
    band = size // 4
    rows = []
    for y in range(size):
        row = bytearray()
        metal = round(METALLIC_STRIPES[y // band] * 255)
        for x in range(size):
            row += bytes((255, round(ROUGHNESS_STRIPES[x // band] * 255), metal))
        rows.append(bytes(row))
    return rows


def normal_map_rows(size=128, bumps=4, radius=0.8, height=0.55):
    """Tangent-space normal map (linear, RGB = n * 0.5 + 0.5) of raised domes.

    +X (red) points to increasing u (image right), +Y (green) to decreasing v
    (image up, the glTF / OpenGL convention), +Z out of the surface. On the
    upper half of each dome (as the image is displayed) green > 0.5; on its
    right half red > 0.5."""
    cell = size / bumps
    rows = []
    for py in range(size):
        row = bytearray()
        for px in range(size):
            # cell-local coordinates in [-1, 1]; x right, y up
            lx = ((px + 0.5) % cell) / cell * 2 - 1
            ly = -(((py + 0.5) % cell) / cell * 2 - 1)
            r2 = (lx * lx + ly * ly) / (radius * radius)
            if r2 < 1:
                # h = height * (1 - r2)^2; dh/dx = height * 2 (1 - r2) * (-2 lx / R^2)
                k = height * 2 * (1 - r2) * (-2 / (radius * radius))
                dhdx, dhdy = k * lx, k * ly
            else:
                dhdx = dhdy = 0.0
            n = normalize((-dhdx, -dhdy, 1.0))
            row += bytes(max(0, min(255, round((c * 0.5 + 0.5) * 255))) for c in n)
        rows.append(bytes(row))
    return rows


# ----------------------------------------------------------------------------
# Geometry. A geometry is a dict: P (positions), N (normals), optional UV and
# T (tangents, 4-tuples), I (triangle indices, CCW from the normal side).

def quad(center, normal, uaxis, half_u, half_v, uv_scale=(1.0, 1.0)):
    """A rectangle facing `normal`. uaxis is the direction of increasing texture
    u; v = cross(normal, uaxis) is "up" in the texture (decreasing glTF v), so
    the tangent is (uaxis, +1)."""
    n = normalize(normal)
    u = normalize(uaxis)
    assert abs(dot(n, u)) < 1e-12
    v = cross(n, u)
    su, sv = uv_scale
    corners = ((-1, -1), (1, -1), (1, 1), (-1, 1))
    P = [add(center, add(mul(u, a * half_u), mul(v, b * half_v))) for a, b in corners]
    UV = [((a + 1) / 2 * su, (1 - (b + 1) / 2) * sv) for a, b in corners]
    g = {"P": P, "N": [n] * 4, "UV": UV, "T": [u + (1.0,)] * 4, "I": [0, 1, 2, 0, 2, 3]}
    assert dot(cross(sub(P[1], P[0]), sub(P[2], P[0])), n) > 0
    return g


def merge(*geoms):
    out = {"P": [], "N": [], "UV": [], "T": [], "I": []}
    for g in geoms:
        base = len(out["P"])
        for k in ("P", "N", "UV", "T"):
            out[k] += g[k]
        out["I"] += [base + i for i in g["I"]]
    return out


def box(half=(0.5, 0.5, 0.5), center=(0.0, 0.0, 0.0)):
    """Axis-aligned box, outward normals, 24 vertices, UV 0..1 on each face."""
    hx, hy, hz = half
    faces = (
        ((1, 0, 0), (0, 0, -1), hz, hy, hx),
        ((-1, 0, 0), (0, 0, 1), hz, hy, hx),
        ((0, 1, 0), (1, 0, 0), hx, hz, hy),
        ((0, -1, 0), (1, 0, 0), hx, hz, hy),
        ((0, 0, 1), (1, 0, 0), hx, hy, hz),
        ((0, 0, -1), (-1, 0, 0), hx, hy, hz),
    )
    return merge(*[quad(add(center, mul(n, d)), n, u, a, b) for n, u, a, b, d in faces])


def uv_sphere(radius, segments, rings):
    """UV sphere centred at the origin: (segments+1) x (rings+1) vertices (seam
    and pole vertices duplicated), smooth normals, u around +Y (from +Z towards
    +X), v = 0 at the north (+Y) pole. Pole-degenerate triangles are left out."""
    P, N, UV, I = [], [], [], []
    for j in range(rings + 1):
        theta = math.pi * j / rings
        for i in range(segments + 1):
            phi = 2 * math.pi * i / segments
            n = (math.sin(theta) * math.sin(phi), math.cos(theta), math.sin(theta) * math.cos(phi))
            if j == 0 or j == rings:
                n = (0.0, 1.0 if j == 0 else -1.0, 0.0)
            N.append(n)
            P.append(mul(n, radius))
            UV.append((i / segments, j / rings))
    row = segments + 1
    for j in range(rings):
        for i in range(segments):
            a, b, c, d = j * row + i, (j + 1) * row + i, (j + 1) * row + i + 1, j * row + i + 1
            if j != rings - 1:
                I += [a, b, c]
            if j != 0:
                I += [a, c, d]
    return {"P": P, "N": N, "UV": UV, "T": [], "I": I}


# ----------------------------------------------------------------------------
# glTF document builder

class Gltf:
    def __init__(self):
        self.bin = bytearray()
        self.textures_rows = {}  # image name -> generated RGB rows (for the round-trip check)
        self.notes = {}
        self.d = {
            "asset": {"version": "2.0", "generator": GENERATOR},
            "extensionsUsed": [],
            "scene": 0,
            "scenes": [],
            "nodes": [],
            "cameras": [],
            "meshes": [],
            "materials": [],
            "textures": [],
            "images": [],
            "samplers": [],
            "accessors": [],
            "bufferViews": [],
            "buffers": [],
            "animations": [],
            "extensions": {},
        }

    def _list(self, key, item):
        self.d[key].append(item)
        return len(self.d[key]) - 1

    def use_extension(self, name):
        if name not in self.d["extensionsUsed"]:
            self.d["extensionsUsed"].append(name)

    def buffer_view(self, data, target=None):
        while len(self.bin) % 4:
            self.bin.append(0)
        bv = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data)}
        if target is not None:
            bv["target"] = target
        self.bin += data
        return self._list("bufferViews", bv)

    def accessor(self, values, ctype, atype, target=None, minmax=False, name=None):
        """values: flat list of scalars, or a list of tuples (flattened here)."""
        flat = []
        for v in values:
            if isinstance(v, (tuple, list)):
                flat.extend(v)
            else:
                flat.append(v)
        ncomp = COMPONENTS[atype]
        assert len(flat) % ncomp == 0
        count = len(flat) // ncomp
        data = struct.pack("<%d%s" % (len(flat), COMPONENT_FMT[ctype]), *flat)
        acc = {"bufferView": self.buffer_view(data, target), "componentType": ctype, "count": count, "type": atype}
        if name:
            acc["name"] = name
        if minmax:
            stored = struct.unpack("<%d%s" % (len(flat), COMPONENT_FMT[ctype]), data)
            cols = [stored[c::ncomp] for c in range(ncomp)]
            acc["min"] = [min(c) for c in cols]
            acc["max"] = [max(c) for c in cols]
        return self._list("accessors", acc)

    def geometry(self, g, index_type, uv=True, tangents=False):
        """Writes a geometry's vertex and index data; returns (attributes, indices accessor)."""
        attrs = {
            "POSITION": self.accessor(g["P"], FLOAT, "VEC3", ARRAY_BUFFER, minmax=True),
            "NORMAL": self.accessor([normalize(n) for n in g["N"]], FLOAT, "VEC3", ARRAY_BUFFER),
        }
        if tangents:
            attrs["TANGENT"] = self.accessor(g["T"], FLOAT, "VEC4", ARRAY_BUFFER)
        if uv:
            attrs["TEXCOORD_0"] = self.accessor(g["UV"], FLOAT, "VEC2", ARRAY_BUFFER)
        limit = {UBYTE: 255, USHORT: 65535, UINT: 2 ** 32 - 1}[index_type]
        assert max(g["I"]) < limit and len(g["P"]) <= limit
        idx = self.accessor(g["I"], index_type, "SCALAR", ELEMENT_ARRAY_BUFFER)
        return attrs, idx

    def mesh(self, name, primitives):
        """primitives: list of (attributes, indices accessor, material)."""
        prims = [{"attributes": dict(a), "indices": i, "material": m, "mode": 4} for a, i, m in primitives]
        return self._list("meshes", {"name": name, "primitives": prims})

    def material(self, name, base, metallic, roughness, emissive=None, emissive_strength=None,
                 double_sided=False, base_tex=None, mr_tex=None, normal_tex=None, normal_scale=1.0):
        pbr = {"baseColorFactor": nums(tuple(base) + ((1.0,) if len(base) == 3 else ()), 6),
               "metallicFactor": num(metallic), "roughnessFactor": num(roughness)}
        if base_tex is not None:
            pbr["baseColorTexture"] = {"index": base_tex, "texCoord": 0}
        if mr_tex is not None:
            pbr["metallicRoughnessTexture"] = {"index": mr_tex, "texCoord": 0}
        m = {"name": name, "pbrMetallicRoughness": pbr}
        if normal_tex is not None:
            m["normalTexture"] = {"index": normal_tex, "texCoord": 0, "scale": num(normal_scale)}
        if emissive is not None:
            m["emissiveFactor"] = nums(emissive, 6)
        if emissive_strength is not None:
            self.use_extension(EXT_EMISSIVE)
            m["extensions"] = {EXT_EMISSIVE: {"emissiveStrength": num(emissive_strength)}}
        m["doubleSided"] = double_sided
        return self._list("materials", m)

    def sampler(self):
        return self._list("samplers", {"magFilter": LINEAR_FILTER, "minFilter": LINEAR_FILTER,
                                       "wrapS": REPEAT, "wrapT": REPEAT})

    def image_png(self, name, png):
        uri = "data:image/png;base64," + base64.b64encode(png).decode("ascii")
        return self._list("images", {"name": name, "mimeType": "image/png", "uri": uri})

    def texture(self, name, image, sampler):
        return self._list("textures", {"name": name, "sampler": sampler, "source": image})

    def node(self, name, mesh=None, t=None, r=None, s=None, children=None, camera=None, light=None):
        n = {"name": name}
        if mesh is not None:
            n["mesh"] = mesh
        if camera is not None:
            n["camera"] = camera
        if light is not None:
            n["extensions"] = {EXT_LIGHTS: {"light": light}}
        if t is not None:
            n["translation"] = nums(t)
        if r is not None:
            n["rotation"] = nums(r)
        if s is not None:
            n["scale"] = nums(s)
        if children:
            n["children"] = list(children)
        return self._list("nodes", n)

    def camera(self, name, yfov, aspect, znear, zfar):
        return self._list("cameras", {"name": name, "type": "perspective", "perspective": {
            "yfov": num(yfov), "aspectRatio": num(aspect), "znear": num(znear), "zfar": num(zfar)}})

    def light(self, light):
        self.use_extension(EXT_LIGHTS)
        lights = self.d["extensions"].setdefault(EXT_LIGHTS, {"lights": []})["lights"]
        lights.append(light)
        return len(lights) - 1

    def scene(self, name, roots):
        return self._list("scenes", {"name": name, "nodes": list(roots)})

    def animation(self, name, channels):
        """channels: list of (node, path, times, values, interpolation); values
        are tuples (for CUBICSPLINE: inTangent, value, outTangent per key)."""
        anim = {"name": name, "channels": [], "samplers": []}
        out_type = {"translation": "VEC3", "rotation": "VEC4", "scale": "VEC3"}
        for node, path, times, values, interp in channels:
            per_key = 3 if interp == "CUBICSPLINE" else 1
            assert len(values) == per_key * len(times)
            assert all(b > a for a, b in zip(times, times[1:]))
            inp = self.accessor(times, FLOAT, "SCALAR", minmax=True)
            out = self.accessor(values, FLOAT, out_type[path])
            anim["samplers"].append({"input": inp, "output": out, "interpolation": interp})
            anim["channels"].append({"sampler": len(anim["samplers"]) - 1, "target": {"node": node, "path": path}})
        return self._list("animations", anim)

    def pointer_animation(self, name, channels):
        """KHR_animation_pointer channels: list of (pointer, output type, times, values, interpolation)."""
        self.use_extension(EXT_POINTER)
        anim = {"name": name, "channels": [], "samplers": []}
        for pointer, out_type, times, values, interp in channels:
            assert len(values) == (3 if interp == "CUBICSPLINE" else 1) * len(times)
            assert all(b > a for a, b in zip(times, times[1:]))
            inp = self.accessor(times, FLOAT, "SCALAR", minmax=True)
            out = self.accessor(values, FLOAT, out_type)
            anim["samplers"].append({"input": inp, "output": out, "interpolation": interp})
            anim["channels"].append({"sampler": len(anim["samplers"]) - 1, "target": {
                "path": "pointer", "extensions": {EXT_POINTER: {"pointer": pointer}}}})
        return self._list("animations", anim)

    def serialize(self):
        d = dict(self.d)
        d["buffers"] = [{"name": "embedded", "byteLength": len(self.bin),
                         "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(self.bin)).decode("ascii")}]
        for k in list(d):
            if isinstance(d[k], (list, dict)) and not d[k]:
                del d[k]
        text = json.dumps(d, indent=1, ensure_ascii=True)
        # keep short numeric arrays (vectors, quaternions, child lists) on one line
        text = re.sub(r"\[\s*(-?[0-9.e+-]+(?:,\s*-?[0-9.e+-]+)*)\s*\]",
                      lambda m: "[" + ", ".join(x.strip() for x in m.group(1).split(",")) + "]", text)
        return (text + "\n").encode("ascii")


# ----------------------------------------------------------------------------
# Scenes

CORNELL_WHITE = (0.725, 0.71, 0.68)
CORNELL_RED = (0.63, 0.065, 0.05)
CORNELL_GREEN = (0.14, 0.45, 0.091)
CORNELL_LIGHT_EMISSION = (1.0, 0.7059, 0.2353)
CORNELL_LIGHT_STRENGTH = 17.0
CORNELL_CAMERA_POS = (0.0, 1.0, 3.9)


def add_cornell_room(g):
    """The Cornell room (x, z in [-1, 1], y in [0, 2], open at z = +1) and its
    ceiling light. Returns (root node, white material)."""
    white = g.material("CornellWhite", CORNELL_WHITE, 0.0, 1.0)
    red = g.material("CornellRed", CORNELL_RED, 0.0, 1.0)
    green = g.material("CornellGreen", CORNELL_GREEN, 0.0, 1.0)
    light = g.material("CeilingLightEmitter", (0.78, 0.78, 0.78), 0.0, 1.0,
                       emissive=CORNELL_LIGHT_EMISSION, emissive_strength=CORNELL_LIGHT_STRENGTH)
    walls = (  # name, centre, inward normal, u axis, material
        ("Floor", (0, 0, 0), (0, 1, 0), (1, 0, 0), white),
        ("Ceiling", (0, 2, 0), (0, -1, 0), (1, 0, 0), white),
        ("BackWall", (0, 1, -1), (0, 0, 1), (1, 0, 0), white),
        ("LeftWallRed", (-1, 1, 0), (1, 0, 0), (0, 0, -1), red),
        ("RightWallGreen", (1, 1, 0), (-1, 0, 0), (0, 0, 1), green),
    )
    children = []
    for name, c, n, u, mat in walls:
        attrs, idx = g.geometry(quad(c, n, u, 1.0, 1.0), USHORT, uv=False)
        children.append(g.node(name, g.mesh(name, [(attrs, idx, mat)])))
    # z in [-0.22, 0.16] -> centre -0.03, half 0.19; u = +X so v = cross(-Y, X) = +Z
    attrs, idx = g.geometry(quad((0.0, 1.98, -0.03), (0, -1, 0), (1, 0, 0), 0.24, 0.19), UBYTE, uv=False)
    children.append(g.node("CeilingLight", g.mesh("CeilingLightQuad", [(attrs, idx, light)])))
    return g.node("CornellRoom", children=children), white


def footprint(t, yaw, sx, sz):
    """World XZ corners of a box footprint (unit box scaled by sx, sz, rotated by yaw about Y)."""
    q = quat_axis_angle((0, 1, 0), yaw)
    pts = []
    for a, b in ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)):
        p = add(quat_rotate(q, (a * sx, 0.0, b * sz)), t)
        pts.append((p[0], p[2]))
    return pts


def polygons_overlap(p, q):
    """Separating-axis test for two convex 2D polygons."""
    for poly in (p, q):
        for i in range(len(poly)):
            e = sub(poly[(i + 1) % len(poly)], poly[i])
            axis = (-e[1], e[0])
            pa = [dot(axis, v) for v in p]
            pb = [dot(axis, v) for v in q]
            if max(pa) < min(pb) or max(pb) < min(pa):
                return False
    return True


def inside_room(pts, margin=0.0):
    return all(-1 + margin <= x <= 1 - margin and -1 + margin <= z <= 1 - margin for x, z in pts)


def cornell_camera(g):
    return g.camera("CornellCamera", math.radians(39.6), 1.0, 0.05, 100.0)


def make_cornell_box():
    g = Gltf()
    room, white = add_cornell_room(g)
    # One unit cube (base on y = 0) instanced twice; the nodes scale, rotate
    # and place it. The "Boxes" group is offset by +0.1 in z and the children
    # compensate, so a loader must compose parent * child to get them right.
    attrs, idx = g.geometry(box((0.5, 0.5, 0.5), (0.0, 0.5, 0.0)), USHORT, uv=False)
    unit_box = g.mesh("UnitBoxWhite", [(attrs, idx, white)])
    group_t = (0.0, 0.0, 0.1)
    short_c, short_yaw = (0.33, 0.0, 0.29), math.radians(-17)
    tall_c, tall_yaw = (-0.34, 0.0, -0.29), math.radians(17)
    fs, ft = footprint(short_c, short_yaw, 0.6, 0.6), footprint(tall_c, tall_yaw, 0.6, 0.6)
    assert inside_room(fs, 0.05) and inside_room(ft, 0.05) and not polygons_overlap(fs, ft)
    short = g.node("ShortBox", unit_box, t=sub(short_c, group_t), r=quat_axis_angle((0, 1, 0), short_yaw), s=(0.6, 0.6, 0.6))
    tall = g.node("TallBox", unit_box, t=sub(tall_c, group_t), r=quat_axis_angle((0, 1, 0), tall_yaw), s=(0.6, 1.2, 0.6))
    boxes = g.node("Boxes", t=group_t, children=[short, tall])
    cam = g.node("Camera", camera=cornell_camera(g), t=CORNELL_CAMERA_POS)
    g.scene("CornellBox", [room, boxes, cam])
    return g


def hermite(p0, m0, p1, m1, dt, s):
    """glTF CUBICSPLINE segment: m0 = out-tangent of key k, m1 = in-tangent of key k+1 (per second)."""
    s2, s3 = s * s, s * s * s
    return tuple((2 * s3 - 3 * s2 + 1) * a + (s3 - 2 * s2 + s) * dt * b + (-2 * s3 + 3 * s2) * c + (s3 - s2) * dt * d
                 for a, b, c, d in zip(p0, m0, p1, m1))


def sample_cubic(times, triplets, t):
    for k in range(len(times) - 1):
        if times[k] <= t <= times[k + 1]:
            dt = times[k + 1] - times[k]
            return hermite(triplets[k][1], triplets[k][2], triplets[k + 1][1], triplets[k + 1][0], dt, (t - times[k]) / dt)
    raise ValueError(t)


DYN_SPHERE_RADIUS = 0.3
DYN_SPHERE_KEYS = ((-0.5, 0.3, 0.3), (0.5, 0.3, 0.3), (0.5, 0.9, 0.0), (-0.5, 0.3, 0.3))
DYN_BOX_POS = (-0.45, 0.0, -0.45)
DYN_CAMERA_TARGET = (0.0, 1.0, 0.0)


def make_cornell_dynamic():
    g = Gltf()
    room, white = add_cornell_room(g)
    glossy = g.material("GlossySphere", (0.9, 0.9, 0.95), 0.0, 0.3)
    attrs, idx = g.geometry(uv_sphere(DYN_SPHERE_RADIUS, 48, 24), UINT, uv=False)
    sphere = g.node("Sphere", g.mesh("GlossySphere48x24", [(attrs, idx, glossy)]), t=DYN_SPHERE_KEYS[0])
    # 0.3 m cube with its base at the node origin, so scaling keeps it on the floor.
    attrs, idx = g.geometry(box((0.15, 0.15, 0.15), (0.0, 0.15, 0.0)), USHORT, uv=False)
    spin = g.node("SpinningBox", g.mesh("SmallBoxWhite", [(attrs, idx, white)]), t=DYN_BOX_POS)
    cam = g.node("Camera", camera=cornell_camera(g), t=CORNELL_CAMERA_POS)
    g.scene("CornellDynamic", [room, sphere, spin, cam])

    # Sphere: LINEAR translation over 4 s; check it stays inside the room and clear of the box.
    times = [0.0, 4.0 / 3.0, 8.0 / 3.0, 4.0]
    for k in range(len(times) - 1):
        for i in range(101):
            p = add(DYN_SPHERE_KEYS[k], mul(sub(DYN_SPHERE_KEYS[k + 1], DYN_SPHERE_KEYS[k]), i / 100))
            assert all(-1 + DYN_SPHERE_RADIUS <= p[a] <= 1 - DYN_SPHERE_RADIUS for a in (0, 2))
            assert DYN_SPHERE_RADIUS - 1e-9 <= p[1] <= 2 - DYN_SPHERE_RADIUS
            # box (scaled up to 1.3): within 0.15 * 1.3 * sqrt(2) of its axis, below y = 0.39
            dxz = math.hypot(p[0] - DYN_BOX_POS[0], p[2] - DYN_BOX_POS[2])
            assert dxz > DYN_SPHERE_RADIUS + 0.15 * 1.3 * math.sqrt(2) or p[1] - DYN_SPHERE_RADIUS > 0.39
    objects = [(sphere, "translation", times, list(DYN_SPHERE_KEYS), "LINEAR")]
    # Box: one full turn about +Y in 2 s, 9 keys 45 degrees apart. The key
    # quaternions stay sign-continuous (the last is (0, 0, 0, -1)), so
    # neighbours have a positive dot product and slerp turns the short way.
    spin_times = [0.25 * k for k in range(9)]
    spin_keys = [quat_axis_angle((0, 1, 0), 2 * math.pi * k / 8) for k in range(9)]
    objects.append((spin, "rotation", spin_times, spin_keys, "LINEAR"))
    # Box: uniform scale with STEP interpolation (jumps at 1, 2, 3 and 4 s).
    objects.append((spin, "scale", [0.0, 1.0, 2.0, 3.0, 4.0],
                    [(1, 1, 1), (1.3, 1.3, 1.3), (1, 1, 1), (0.7, 0.7, 0.7), (1, 1, 1)], "STEP"))
    g.animation("ObjectMotion", objects)

    # Camera: CUBICSPLINE translation (0, 1, 3.9) -> (0.4, 1.1, 3.5) -> back, a
    # smooth closed loop: the tangents (m/s) are equal in and out at every key
    # and the first key's out-tangent equals the last key's in-tangent.
    cam_times = [0.0, 2.0, 4.0]
    end_tan = (0.0, 0.06, 0.0)
    mid_tan = (0.1, 0.0, 0.1)
    far = (0.4, 1.1, 3.5)
    triplets = [(end_tan, CORNELL_CAMERA_POS, end_tan), (mid_tan, far, mid_tan), (end_tan, CORNELL_CAMERA_POS, end_tan)]
    cam_values = [v for trip in triplets for v in trip]
    # Camera: LINEAR yaw keys every 0.5 s keeping the room centre straight ahead
    # (yaw = atan2(x - tx, z - tz); camera looks down -Z). At t = 0 and 4 s this is identity.
    rot_times = [0.5 * k for k in range(9)]
    rot_keys = []
    for t in rot_times:
        p = sample_cubic(cam_times, triplets, t)
        yaw = math.atan2(p[0] - DYN_CAMERA_TARGET[0], p[2] - DYN_CAMERA_TARGET[2])
        rot_keys.append(quat_axis_angle((0, 1, 0), yaw))
    g.animation("CameraMotion", [(cam, "translation", cam_times, cam_values, "CUBICSPLINE"),
                                 (cam, "rotation", rot_times, rot_keys, "LINEAR")])
    g.notes = {"camera_max_yaw_deg": max(math.degrees(2 * math.atan2(q[1], q[3])) for q in rot_keys)}
    return g


# The light steps between frames (k + 0.5) / 60 and (k + 1) / 60 at 60 fps, so no frame time lands on a key: the first
# frame with the new intensity is frame k + 1 for a step at (k + 0.5) / 60 s (21, 41, 61, 81).
LIGHTSTEP_FPS = 60.0
LIGHTSTEP_FRAMES = (20.5, 40.5, 60.5, 80.5)
LIGHTSTEP_LOW = 0.25  # the dim state, as a fraction of the full strength


def make_cornell_lightstep():
    g = make_cornell_box()
    g.d["scenes"][0]["name"] = "CornellLightStep"
    light = [m["name"] for m in g.d["materials"]].index("CeilingLightEmitter")
    full = CORNELL_LIGHT_STRENGTH
    times = [0.0] + [f / LIGHTSTEP_FPS for f in LIGHTSTEP_FRAMES]
    values = [full if k % 2 == 0 else LIGHTSTEP_LOW * full for k in range(len(times))]
    pointer = "/materials/%d/extensions/%s/emissiveStrength" % (light, EXT_EMISSIVE)
    g.pointer_animation("LightStep", [(pointer, "SCALAR", times, values, "STEP")])
    return g


GOLD = (1.0, 0.766, 0.336)
BLUE_PLASTIC = (0.1, 0.25, 0.8)
SPHERE_ROUGHNESS = (0.05, 0.25, 0.5, 0.75, 1.0)
MAT_CAMERA_POS = (0.0, 1.6, 5.0)
MAT_CAMERA_TARGET = (0.0, 0.5, 0.0)


def make_materials():
    g = Gltf()
    smp = g.sampler()

    def png_texture(name, rows, srgb):
        g.textures_rows[name] = rows
        png = encode_png(len(rows[0]) // 3, len(rows), rows, srgb, vary_filters=True)
        return g.texture(name, g.image_png(name, png), smp)

    checker = png_texture("Checker256_sRGB", checker_rows(), True)
    metal_rough = png_texture("MetalRoughStripes128_linear", metal_rough_rows(), False)
    normal_map = png_texture("BumpNormals128_linear", normal_map_rows(), False)

    m_floor = g.material("CheckerFloor", (1, 1, 1), 0.0, 0.8, base_tex=checker)
    m_spheres = []
    for k, rough in enumerate(SPHERE_ROUGHNESS):
        if k % 2 == 0:
            m_spheres.append(g.material("Gold_Rough%03d" % round(rough * 100), GOLD, 1.0, rough))
        else:
            m_spheres.append(g.material("BluePlastic_Rough%03d" % round(rough * 100), BLUE_PLASTIC, 0.0, rough))
    m_striped = g.material("StripedMetalRough", (0.9, 0.9, 0.9), 1.0, 1.0, mr_tex=metal_rough)
    m_bumpy = g.material("BumpyNormalMapped", (0.8, 0.8, 0.8), 0.0, 0.35, normal_tex=normal_map)
    m_card = g.material("DoubleSidedCheckerCard", (0.6, 0.9, 0.6), 0.0, 0.6, base_tex=checker, double_sided=True)
    m_emit = g.material("EmissivePanel", (0.8, 0.8, 0.8), 0.0, 1.0, emissive=(1, 1, 1), emissive_strength=8.0)
    m_housing = g.material("LightHousingDarkGrey", (0.05, 0.05, 0.05), 0.0, 0.5)

    roots = []
    # Floor: 6 x 6 m, UV 0..4 (the checker repeats 4 times: 32 x 32 checks).
    attrs, idx = g.geometry(quad((0, 0, 0), (0, 1, 0), (1, 0, 0), 3.0, 3.0, uv_scale=(4.0, 4.0)), USHORT)
    roots.append(g.node("Floor", g.mesh("CheckerFloor6x6", [(attrs, idx, m_floor)])))

    # Five spheres sharing one set of vertex/index accessors, one mesh each (different materials).
    attrs, idx = g.geometry(uv_sphere(0.35, 32, 16), UINT)
    for k, m in enumerate(m_spheres):
        mesh = g.mesh("Sphere32x16_" + g.d["materials"][m]["name"], [(attrs, idx, m)])
        roots.append(g.node("Sphere%d" % k, mesh, t=(-1.6 + 0.8 * k, 0.35, 0.0)))

    # Metallic-roughness striped box (0.7 m cube on the floor, turned 30 degrees).
    attrs, idx = g.geometry(box((0.35, 0.35, 0.35)), USHORT)
    roots.append(g.node("StripedBox", g.mesh("StripedMetalRoughBox", [(attrs, idx, m_striped)]),
                        t=(-2.45, 0.35, -0.3), r=quat_axis_angle((0, 1, 0), math.radians(30))))

    # Normal-mapped panels (1 x 1 m, facing +Z): A has TANGENT, B shares A's
    # other accessors but has no TANGENT, so the loader must generate it and
    # both panels should shade identically (expected tangent: +X, w = +1).
    panel = quad((0, 0, 0), (0, 0, 1), (1, 0, 0), 0.5, 0.5)
    attrs, idx = g.geometry(panel, USHORT, tangents=True)
    attrs_b = {k: v for k, v in attrs.items() if k != "TANGENT"}
    roots.append(g.node("NormalPanelWithTangents", g.mesh("NormalMapPanelWithTangents", [(attrs, idx, m_bumpy)]),
                        t=(-0.75, 1.25, -1.0)))
    roots.append(g.node("NormalPanelNoTangents", g.mesh("NormalMapPanelNoTangents", [(attrs_b, idx, m_bumpy)]),
                        t=(0.75, 1.25, -1.0)))

    # Double-sided thin card (0.8 x 1.0 m); its geometric normal points away
    # from the camera, so the camera sees the back face.
    attrs, idx = g.geometry(quad((0, 0, 0), (0, 0, 1), (1, 0, 0), 0.4, 0.5), UBYTE)
    card_rot = quat_axis_angle((0, 1, 0), math.radians(210))
    card_pos = (2.4, 0.55, -0.6)
    assert dot(quat_rotate(card_rot, (0, 0, 1)), sub(MAT_CAMERA_POS, card_pos)) < 0
    roots.append(g.node("DoubleSidedCard", g.mesh("DoubleSidedCardQuad", [(attrs, idx, m_card)]), t=card_pos, r=card_rot))

    # Emissive light panel: one mesh, two primitives (emitter quad, UNSIGNED_BYTE
    # indices; housing box, UNSIGNED_SHORT), tilted 30 degrees to face down and forward.
    attrs_e, idx_e = g.geometry(quad((0, 0, 0), (0, 0, 1), (1, 0, 0), 0.6, 0.15), UBYTE, uv=False)
    attrs_h, idx_h = g.geometry(box((0.65, 0.2, 0.03), (0.0, 0.0, -0.035)), USHORT, uv=False)
    roots.append(g.node("EmissivePanel", g.mesh("EmissivePanelWithHousing", [(attrs_e, idx_e, m_emit), (attrs_h, idx_h, m_housing)]),
                        t=(0.0, 2.3, -1.7), r=quat_axis_angle((1, 0, 0), math.radians(30))))

    # Punctual lights.
    point = g.light({"name": "WarmPointLight", "type": "point", "color": [1.0, 0.85, 0.7], "intensity": 30.0})
    roots.append(g.node("PointLight", t=(1.5, 2.5, 2.0), light=point))
    spot_pos, spot_target = (-2.6, 3.0, 1.6), (-2.0, 0.3, -0.2)
    spot = g.light({"name": "CoolSpotLight", "type": "spot", "color": [0.85, 0.9, 1.0], "intensity": 80.0,
                    "spot": {"innerConeAngle": 0.3, "outerConeAngle": 0.5}})
    roots.append(g.node("SpotLight", t=spot_pos, r=quat_look_at(spot_pos, spot_target), light=spot))

    cam = g.camera("MaterialsCamera", 0.8, 16.0 / 9.0, 0.05, 100.0)
    roots.append(g.node("Camera", camera=cam, t=MAT_CAMERA_POS, r=quat_look_at(MAT_CAMERA_POS, MAT_CAMERA_TARGET)))
    g.scene("Materials", roots)
    return g


SKY_CAMERA_POS = (0.0, 0.4, 4.0)


def make_sky_sphere():
    g = Gltf()
    # One glossy sphere on nothing: the rest of the frame is environment (given with --env), so most camera
    # rays miss. A sun (directional light) lights it besides the environment.
    attrs, idx = g.geometry(uv_sphere(0.5, 32, 16), USHORT)
    glossy = g.material("GlossyOrange", (0.9, 0.45, 0.1), 0.0, 0.3)
    roots = [g.node("Sphere", g.mesh("Sphere", [(attrs, idx, glossy)]))]
    sun = g.light({"name": "Sun", "type": "directional", "color": [1.0, 0.95, 0.85], "intensity": 3.0})
    roots.append(g.node("Sun", r=quat_look_at((0.0, 0.0, 0.0), (-0.4, -1.0, -0.6)), light=sun))
    cam = g.camera("SkyCamera", 0.8, 16.0 / 9.0, 0.05, 100.0)
    roots.append(g.node("Camera", camera=cam, t=SKY_CAMERA_POS, r=quat_look_at(SKY_CAMERA_POS, (0.0, 0.0, 0.0))))
    g.scene("SkySphere", roots)
    return g


# ----------------------------------------------------------------------------
# asset.gltf: a small, detailed "real asset"-like object under an environment

def _hash01(ix, iy, seed):
    """Deterministic lattice hash in [0, 1)."""
    h = (ix * 374761393 + iy * 668265263 + seed * 1442695041) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    h ^= h >> 16
    return h / 4294967296.0


def value_noise(x, y, period_x, period_y, seed):
    """Smooth value noise on a lattice that repeats every period_x x period_y cells (x, y in cells)."""
    ix, iy = math.floor(x), math.floor(y)
    fx, fy = x - ix, y - iy
    sx, sy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    x0, x1 = ix % period_x, (ix + 1) % period_x
    y0, y1 = iy % period_y, (iy + 1) % period_y
    a, b = _hash01(x0, y0, seed), _hash01(x1, y0, seed)
    c, d = _hash01(x0, y1, seed), _hash01(x1, y1, seed)
    return (a + (b - a) * sx) + ((c + (d - c) * sx) - (a + (b - a) * sx)) * sy


def tile_fbm(u, v, cells_u, cells_v, octaves, seed):
    """Fractal sum of value noise over one texture tile (u, v in [0, 1)), tileable in both directions; in [0, 1)."""
    total, amp, norm = 0.0, 1.0, 0.0
    for o in range(octaves):
        f = 1 << o
        total += amp * value_noise(u * cells_u * f, v * cells_v * f, cells_u * f, cells_v * f, seed + 101 * o)
        norm += amp
        amp *= 0.5
    return total / norm


ASSET_TEX = 128                  # texels on a side of each asset texture (one square tile)
ASSET_PAINT = (150, 30, 22)      # sRGB: red paint
ASSET_PRIMER = (176, 168, 148)   # sRGB: the primer seen at the edges of paint chips
ASSET_METAL = (212, 206, 196)    # sRGB: bare steel under the paint (linear about 0.66, 0.62, 0.55)
ASSET_RIVET_RINGS = (6, ASSET_TEX - 7)  # texel columns of the two rings of rivets beside the seam at u = 0
ASSET_RIVETS_AROUND = 8


def asset_layers(size=ASSET_TEX):
    """Worn paint over steel, as per-texel layers of one tileable square tile (x along u, y along v, row 0 = top).

    Returns (kind, height, fine): kind 0 = paint, 1 = primer (chip edge), 2 = bare metal (chip, scratch or
    rivet head); height in texels (paint raised over metal, rivet domes, scratch and seam grooves, shallow
    dents); fine = a [0, 1) grain for colour and roughness variation."""
    kind = [[0] * size for _ in range(size)]
    height = [[0.0] * size for _ in range(size)]
    fine = [[0.0] * size for _ in range(size)]
    scratch = [[0.0] * size for _ in range(size)]
    # Scratches: short straight strokes (deterministic), stamped with wrap-around; depth fades along the stroke.
    for k in range(18):
        x0, y0 = _hash01(k, 1, 77) * size, _hash01(k, 2, 77) * size
        ang = (_hash01(k, 3, 77) - 0.5) * 1.2 + (math.pi / 2 if k % 4 == 0 else 0.0)
        ln = 6 + _hash01(k, 4, 77) * 26
        steps = int(ln * 2)
        for s in range(steps + 1):
            t = s / steps
            px, py = x0 + math.cos(ang) * ln * t, y0 + math.sin(ang) * ln * t
            depth = math.sin(math.pi * t) ** 0.5
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    cx, cy = math.floor(px) + dx, math.floor(py) + dy
                    dist = math.hypot(cx + 0.5 - px, cy + 0.5 - py)
                    w = max(0.0, 1.0 - dist / 1.1) * depth
                    if w > scratch[cy % size][cx % size]:
                        scratch[cy % size][cx % size] = w
    cell = size / ASSET_RIVETS_AROUND
    for y in range(size):
        v = (y + 0.5) / size
        for x in range(size):
            u = (x + 0.5) / size
            wear = tile_fbm(u, v, 6, 6, 5, 11)
            dent = tile_fbm(u, v, 3, 3, 2, 29)
            fine[y][x] = tile_fbm(u, v, 16, 64, 2, 43)  # brushed grain: streaks along u
            h = 10.0 * dent
            if wear > 0.545:
                k = 2
            elif wear > 0.52:
                k, h = 1, h + 0.4
            else:
                k, h = 0, h + 0.8
            sc = scratch[y][x]
            if sc > 0.25:
                k, h = 2, h - 0.9 * sc
            # the seam between panels: a groove across the tile at u = 0
            ds = min(x + 0.5, size - x - 0.5)
            if ds < 1.5:
                h -= 1.2 * (1.5 - ds) / 1.5
            # rivets: domes of radius 2.6 texels in two rings beside the seam; their worn tops are bare metal
            for rx in ASSET_RIVET_RINGS:
                ry = (math.floor(y / cell) + 0.5) * cell
                r2 = ((x + 0.5 - (rx + 0.5)) ** 2 + (y + 0.5 - ry) ** 2) / (2.6 * 2.6)
                if r2 < 1:
                    h = max(h, 0.8 + 2.2 * (1 - r2))
                    if r2 < 0.45:
                        k = 2
            kind[y][x] = k
            height[y][x] = h
    return kind, height, fine


def asset_base_color_rows(layers):
    kind, _, fine = layers
    rows = []
    for krow, frow in zip(kind, fine):
        row = bytearray()
        for k, f in zip(krow, frow):
            c = (ASSET_PAINT, ASSET_PRIMER, ASSET_METAL)[k]
            g = (f - 0.5) * (28 if k == 0 else 36)  # paint mottling, metal brushing
            row += bytes(max(0, min(255, round(ch + g))) for ch in c)
        rows.append(bytes(row))
    return rows


def asset_metal_rough_rows(layers):
    """Linear: R = 1 (unused occlusion), G = roughness, B = metallic. Bare metal is metallic 1 with roughness
    0.12-0.3 along the brushing; paint (0.55-0.75) and primer (0.85) are dielectric."""
    kind, _, fine = layers
    rows = []
    for krow, frow in zip(kind, fine):
        row = bytearray()
        for k, f in zip(krow, frow):
            rough = (0.55 + 0.2 * f, 0.85, 0.12 + 0.18 * f)[k]
            row += bytes((255, round(rough * 255), 255 if k == 2 else 0))
        rows.append(bytes(row))
    return rows


def asset_normal_rows(layers, strength=0.55):
    """Tangent-space normals (linear, OpenGL convention as in normal_map_rows) from the height field by central
    differences with wrap-around: +X red along +u (image right), +Y green up the image (decreasing v)."""
    _, h, _ = layers
    n_ = len(h)
    rows = []
    for y in range(n_):
        row = bytearray()
        for x in range(n_):
            dhdx = (h[y][(x + 1) % n_] - h[y][(x - 1) % n_]) * 0.5 * strength
            dhdup = (h[(y - 1) % n_][x] - h[(y + 1) % n_][x]) * 0.5 * strength  # row y - 1 is up
            n = normalize((-dhdx, -dhdup, 1.0))
            row += bytes(max(0, min(255, round((c * 0.5 + 0.5) * 255))) for c in n)
        rows.append(bytes(row))
    return rows


def torus_knot_point(t, p=2, q=3):
    """The (p, q) torus knot in its own frame (the knot winds about +Y; x, z in [-3, 3], y in [-1, 1])."""
    r = 2 + math.cos(q * t)
    return (r * math.cos(p * t), math.sin(q * t), r * math.sin(p * t))


def torus_knot(scale, tube, rings, sides, tiles_target=None):
    """A tube of radius `tube` around the (2, 3) torus knot scaled by `scale`: rings + 1 rings of sides + 1
    vertices (the first ring repeated at the end, the first vertex of each ring repeated at its end, for the UV
    seams), spaced evenly along the curve. Frames are parallel-transported and the closing twist is spread
    evenly, so the last ring lands on the first. u runs along the curve (a whole number of texture tiles, each
    as long as the tube's circumference), v around it. TANGENT is the curve direction (increasing u), w = +1;
    smooth normals. Returns (geometry, number of tiles along u)."""
    dense = 8192
    pts = [mul(torus_knot_point(2 * math.pi * i / dense), scale) for i in range(dense + 1)]
    cum = [0.0]
    for a, b in zip(pts, pts[1:]):
        cum.append(cum[-1] + length(sub(b, a)))
    total = cum[-1]
    tiles = max(1, round(total / (2 * math.pi * tube)))

    def t_at(s):  # curve parameter at arc length s (linear within the dense table)
        lo, hi = 0, dense
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if cum[mid] <= s:
                lo = mid
            else:
                hi = mid
        f = (s - cum[lo]) / (cum[hi] - cum[lo])
        return 2 * math.pi * (lo + f) / dense

    centres, tangents = [], []
    for i in range(rings):
        t = t_at(total * i / rings)
        eps = 1e-5
        centres.append(mul(torus_knot_point(t), scale))
        tangents.append(normalize(sub(torus_knot_point(t + eps), torus_knot_point(t - eps))))
    # parallel transport of the first normal, then the closing twist spread over the loop
    n1 = [normalize(sub((0.0, 1.0, 0.0), mul(tangents[0], tangents[0][1])))]
    for i in range(1, rings + 1):
        tt = tangents[i % rings]
        prev = n1[-1]
        n1.append(normalize(sub(prev, mul(tt, dot(prev, tt)))))
    end, start = n1[rings], n1[0]
    twist = math.atan2(dot(cross(start, end), tangents[0]), dot(start, end))
    frames = []
    for i in range(rings):
        tt = tangents[i]
        a = -twist * i / rings
        b = cross(tt, n1[i])
        fa = add(mul(n1[i], math.cos(a)), mul(b, math.sin(a)))
        frames.append((fa, cross(tt, fa), tt))
    P, N, UV, T, I = [], [], [], [], []
    for i in range(rings + 1):
        fa, fb, tt = frames[i % rings]
        c = centres[i % rings]
        for j in range(sides + 1):
            th = 2 * math.pi * (j % sides) / sides
            n = add(mul(fa, math.cos(th)), mul(fb, math.sin(th)))
            N.append(n)
            P.append(add(c, mul(n, tube)))
            UV.append((tiles * i / rings, j / sides))
            T.append(tt + (1.0,))
    row = sides + 1
    for i in range(rings):
        for j in range(sides):
            a, b, c, d = i * row + j, (i + 1) * row + j, (i + 1) * row + j + 1, i * row + j + 1
            I += [a, c, b, a, d, c]
    g = {"P": P, "N": N, "UV": UV, "T": T, "I": I}
    # winding and the tangent frame: outward CCW faces; bitangent cross(N, T) * w points up the image (-v)
    a, b, c = (P[I[k]] for k in range(3))
    assert dot(cross(sub(b, a), sub(c, a)), N[I[0]]) > 0
    assert dot(cross(N[0], T[0][:3]), sub(P[1], P[0])) < 0
    return g, tiles


def sub_rings(g, sides, first, last):
    """Rings first..last (inclusive) of a tube geometry as a geometry of its own."""
    row = sides + 1
    lo, hi = first * row, (last + 1) * row
    out = {k: g[k][lo:hi] for k in ("P", "N", "UV", "T")}
    out["I"] = []
    for t in range(0, len(g["I"]), 3):
        tri = g["I"][t:t + 3]
        if all(lo <= i < hi for i in tri):
            out["I"] += [i - lo for i in tri]
    return out


def cylinder(radius, y0, y1, sides):
    """Vertical cylinder with flat caps: smooth side normals, separate cap vertices; UV u around, v down."""
    P, N, UV, I = [], [], [], []
    for j in range(sides + 1):
        th = 2 * math.pi * (j % sides) / sides
        n = (math.sin(th), 0.0, math.cos(th))
        for y, v in ((y1, 0.0), (y0, 1.0)):
            P.append((radius * n[0], y, radius * n[2]))
            N.append(n)
            UV.append((j / sides, v))
    for j in range(sides):
        a, b, c, d = 2 * j, 2 * j + 1, 2 * j + 3, 2 * j + 2
        I += [a, b, c, a, c, d]
    for y, up in ((y1, 1.0), (y0, -1.0)):
        base = len(P)
        P.append((0.0, y, 0.0))
        N.append((0.0, up, 0.0))
        UV.append((0.5, 0.5))
        for j in range(sides):
            th = 2 * math.pi * j / sides
            P.append((radius * math.sin(th), y, radius * math.cos(th)))
            N.append((0.0, up, 0.0))
            UV.append((0.5 + 0.5 * math.sin(th), 0.5 - 0.5 * math.cos(th)))
        for j in range(sides):
            k0, k1 = base + 1 + j, base + 1 + (j + 1) % sides
            I += [base, k0, k1] if up > 0 else [base, k1, k0]
    return {"P": P, "N": N, "UV": UV, "T": [], "I": I}


def transform_geometry(g, q, t):
    """Rotates (quaternion q) and then translates (t) positions, normals and tangents."""
    out = dict(g)
    out["P"] = [add(quat_rotate(q, p), t) for p in g["P"]]
    out["N"] = [normalize(quat_rotate(q, n)) for n in g["N"]]
    out["T"] = [quat_rotate(q, tt[:3]) + (tt[3],) for tt in g["T"]]
    return out


ASSET_KNOT_SCALE = 0.1           # the (2, 3) knot's curve spans x, z in [-0.3, 0.3]
ASSET_KNOT_TUBE = 0.05
ASSET_KNOT_RINGS, ASSET_KNOT_SIDES = 192, 12
ASSET_KNOT_TILT = math.radians(62)   # about +X: the knot's plane stands up from the horizontal
ASSET_KNOT_YAW = math.radians(25)
ASSET_PLINTH_TOP = 0.16          # y of the plinth's top face; the plinth stands on y = 0
ASSET_STEM_TOP = 0.26
ASSET_CAMERA_DIR = (0.55, 0.42, 1.0)  # from the object's centre towards the camera
ASSET_CAMERA_DIST = 2.5
ASSET_YFOV = 0.6


def make_asset():
    g = Gltf()
    smp = g.sampler()

    def png_texture(name, rows, srgb):
        g.textures_rows[name] = rows
        png = encode_png(len(rows[0]) // 3, len(rows), rows, srgb, vary_filters=True)
        return g.texture(name, g.image_png(name, png), smp)

    layers = asset_layers()
    base = png_texture("WornPaintBaseColor128_sRGB", asset_base_color_rows(layers), True)
    mr = png_texture("WornPaintMetalRough128_linear", asset_metal_rough_rows(layers), False)
    nrm = png_texture("WornPaintNormals128_linear", asset_normal_rows(layers), False)
    m_knot = g.material("WornPaintedSteel", (1, 1, 1), 1.0, 1.0, base_tex=base, mr_tex=mr, normal_tex=nrm)
    m_plinth = g.material("PlinthDarkStone", (0.1, 0.1, 0.11), 0.0, 0.4)
    m_stem = g.material("StemDarkSteel", (0.35, 0.35, 0.37), 1.0, 0.35)

    # The knot: tilted and yawed, then lifted so that its lowest tube centre sits on the stem's top.
    knot, tiles = torus_knot(ASSET_KNOT_SCALE, ASSET_KNOT_TUBE, ASSET_KNOT_RINGS, ASSET_KNOT_SIDES)
    q = quat_mul(quat_axis_angle((0, 1, 0), ASSET_KNOT_YAW), quat_axis_angle((1, 0, 0), ASSET_KNOT_TILT))
    knot = transform_geometry(knot, q, (0.0, 0.0, 0.0))
    low = min(knot["P"], key=lambda p: p[1])
    lift = (-low[0], ASSET_STEM_TOP + ASSET_KNOT_TUBE * 0.5 - low[1], -low[2])
    knot = transform_geometry(knot, (0.0, 0.0, 0.0, 1.0), lift)
    # Two primitives of one material: the first half of the rings with TANGENT, the second half without (the
    # loader generates it); the halves meet at rings 0 and 96, which both hold, so they should shade seamlessly.
    half = ASSET_KNOT_RINGS // 2
    attrs_a, idx_a = g.geometry(sub_rings(knot, ASSET_KNOT_SIDES, 0, half), USHORT, tangents=True)
    attrs_b, idx_b = g.geometry(sub_rings(knot, ASSET_KNOT_SIDES, half, ASSET_KNOT_RINGS), USHORT)
    roots = [g.node("TorusKnot", g.mesh("TorusKnotWornPaint", [(attrs_a, idx_a, m_knot), (attrs_b, idx_b, m_knot)]))]

    # A two-step plinth (a slab and a narrower block) and a steel stem up into the knot's lowest tube.
    slab_h, block_h = 0.05, ASSET_PLINTH_TOP - 0.05
    plinth = merge(box((0.23, slab_h / 2, 0.23), (0.0, slab_h / 2, 0.0)),
                   box((0.18, block_h / 2, 0.18), (0.0, slab_h + block_h / 2, 0.0)))
    attrs, idx = g.geometry(plinth, UBYTE, uv=False)
    roots.append(g.node("Plinth", g.mesh("PlinthTwoStep", [(attrs, idx, m_plinth)])))
    attrs, idx = g.geometry(cylinder(0.018, ASSET_PLINTH_TOP, ASSET_STEM_TOP, 16), UBYTE, uv=False)
    roots.append(g.node("Stem", g.mesh("StemCylinder", [(attrs, idx, m_stem)])))

    sun = g.light({"name": "Sun", "type": "directional", "color": [1.0, 0.96, 0.88], "intensity": 4.0})
    roots.append(g.node("Sun", r=quat_look_at((0.0, 0.0, 0.0), (-0.5, -1.0, -0.35)), light=sun))
    rim = g.light({"name": "RimLight", "type": "directional", "color": [0.8, 0.88, 1.0], "intensity": 2.0})
    roots.append(g.node("RimLight", r=quat_look_at((0.0, 0.0, 0.0), (0.6, -0.5, 0.8)), light=rim))

    # The camera looks at the centre of everything's bounds, the point an orbit turns about.
    allp = knot["P"] + plinth["P"]
    centre = tuple((min(p[a] for p in allp) + max(p[a] for p in allp)) / 2 for a in range(3))
    eye = add(centre, mul(normalize(ASSET_CAMERA_DIR), ASSET_CAMERA_DIST))
    cam = g.camera("AssetCamera", ASSET_YFOV, 4.0 / 3.0, 0.05, 100.0)
    roots.append(g.node("Camera", camera=cam, t=eye, r=quat_look_at(eye, centre)))
    g.scene("Asset", roots)
    g.notes = {"asset_knot_tiles": tiles, "asset_centre": centre, "asset_eye": eye}
    return g


SCENES = (
    ("cornell_box.gltf", make_cornell_box),
    ("cornell_dynamic.gltf", make_cornell_dynamic),
    ("cornell_lightstep.gltf", make_cornell_lightstep),
    ("materials.gltf", make_materials),
    ("sky_sphere.gltf", make_sky_sphere),
    ("asset.gltf", make_asset),
)


# ----------------------------------------------------------------------------
# Validation (re-reads the written files)

class Invalid(Exception):
    pass


def check(cond, msg):
    if not cond:
        raise Invalid(msg)


def decode_data_uri(uri, mime):
    prefix = "data:%s;base64," % mime
    check(uri.startswith(prefix), "uri is not a %s base64 data URI" % mime)
    return base64.b64decode(uri[len(prefix):], validate=True)


def validate(path):
    """Checks one file; returns a summary dict. Raises Invalid naming the problem."""
    raw = open(path, "rb").read()
    check(len(raw) < MAX_FILE_BYTES, "file is %d bytes (limit %d)" % (len(raw), MAX_FILE_BYTES))
    d = json.loads(raw)
    check(d["asset"]["version"] == "2.0" and d["asset"].get("generator") == GENERATOR, "asset")
    check("extensionsRequired" not in d, "extensionsRequired must be absent")
    used = set(d.get("extensionsUsed", []))

    buffers = [decode_data_uri(b["uri"], "application/octet-stream") for b in d["buffers"]]
    for i, b in enumerate(d["buffers"]):
        check(len(buffers[i]) == b["byteLength"], "buffer %d byteLength" % i)
    views = d.get("bufferViews", [])
    for i, v in enumerate(views):
        check("byteStride" not in v, "bufferView %d has byteStride" % i)
        check(v.get("byteOffset", 0) % 4 == 0, "bufferView %d not 4-byte aligned" % i)
        check(v.get("byteOffset", 0) + v["byteLength"] <= len(buffers[v["buffer"]]), "bufferView %d overruns its buffer" % i)

    def read(ai):
        a = d["accessors"][ai]
        v = views[a["bufferView"]]
        ncomp, csize = COMPONENTS[a["type"]], COMPONENT_SIZE[a["componentType"]]
        off = a.get("byteOffset", 0)
        check(off % csize == 0, "accessor %d misaligned" % ai)
        check(off + a["count"] * ncomp * csize <= v["byteLength"], "accessor %d overruns bufferView %d" % (ai, a["bufferView"]))
        start = v.get("byteOffset", 0) + off
        vals = struct.unpack_from("<%d%s" % (a["count"] * ncomp, COMPONENT_FMT[a["componentType"]]), buffers[v["buffer"]], start)
        if a["componentType"] == FLOAT:
            check(all(math.isfinite(x) for x in vals), "accessor %d has NaN/Inf" % ai)
        if "min" in a or "max" in a:
            cols = [vals[c::ncomp] for c in range(ncomp)]
            check(a["min"] == [min(c) for c in cols] and a["max"] == [max(c) for c in cols], "accessor %d min/max wrong" % ai)
        return [tuple(vals[i:i + ncomp]) for i in range(0, len(vals), ncomp)] if ncomp > 1 else list(vals)

    for ai in range(len(d.get("accessors", []))):
        read(ai)

    # images, textures, samplers
    images = []
    for i, im in enumerate(d.get("images", [])):
        png = decode_data_uri(im["uri"], "image/png")
        try:
            images.append(decode_png(png))
        except (ValueError, zlib.error) as e:
            raise Invalid("image %d (%s): %s" % (i, im.get("name"), e))
    for i, t in enumerate(d.get("textures", [])):
        check(0 <= t["source"] < len(images), "texture %d source" % i)
        s = d["samplers"][t["sampler"]]
        check(s == {"magFilter": 9729, "minFilter": 9729, "wrapS": 10497, "wrapT": 10497}, "sampler %d" % t["sampler"])

    # materials
    for i, m in enumerate(d.get("materials", [])):
        pbr = m.get("pbrMetallicRoughness", {})
        check("metallicFactor" in pbr and "roughnessFactor" in pbr, "material %d lacks explicit metallic/roughness" % i)
        for key, holder in (("baseColorTexture", pbr), ("metallicRoughnessTexture", pbr), ("normalTexture", m), ("emissiveTexture", m)):
            if key in holder:
                check(0 <= holder[key]["index"] < len(d["textures"]), "material %d %s" % (i, key))
        for ext in m.get("extensions", {}):
            check(ext in used, "material %d uses %s not in extensionsUsed" % (i, ext))

    # meshes
    triangles = {}
    for mi, mesh in enumerate(d["meshes"]):
        tris = 0
        for pi, p in enumerate(mesh["primitives"]):
            where = "mesh %d (%s) primitive %d" % (mi, mesh.get("name"), pi)
            at = p["attributes"]
            check(p.get("mode", 4) == 4, where + ": not triangles")
            check("POSITION" in at and "NORMAL" in at, where + ": POSITION and NORMAL required")
            pa = d["accessors"][at["POSITION"]]
            check("min" in pa and "max" in pa, where + ": POSITION min/max missing")
            P, N = read(at["POSITION"]), read(at["NORMAL"])
            spec = {"POSITION": ("VEC3", FLOAT), "NORMAL": ("VEC3", FLOAT), "TANGENT": ("VEC4", FLOAT), "TEXCOORD_0": ("VEC2", FLOAT)}
            for name, ai in at.items():
                a = d["accessors"][ai]
                check(name in spec and (a["type"], a["componentType"]) == spec[name], where + ": attribute " + name)
                check(a["count"] == len(P), where + ": attribute counts differ")
                check(views[a["bufferView"]].get("target") == ARRAY_BUFFER, where + ": vertex bufferView target")
            check(all(abs(length(n) - 1) < 1e-5 for n in N), where + ": normals not unit length")
            if "TANGENT" in at:
                T = read(at["TANGENT"])
                check(all(abs(length(t[:3]) - 1) < 1e-5 and t[3] in (-1.0, 1.0) for t in T), where + ": bad tangents")
                check(all(abs(dot(t[:3], n)) < 1e-5 for t, n in zip(T, N)), where + ": tangent not orthogonal to normal")
            mat = d["materials"][p["material"]]
            textured = any(k in mat.get("pbrMetallicRoughness", {}) for k in ("baseColorTexture", "metallicRoughnessTexture")) \
                or "normalTexture" in mat or "emissiveTexture" in mat
            check(not textured or "TEXCOORD_0" in at, where + ": textured material without TEXCOORD_0")
            ia = d["accessors"][p["indices"]]
            check(ia["type"] == "SCALAR" and ia["componentType"] in (UBYTE, USHORT, UINT), where + ": index type")
            check(views[ia["bufferView"]].get("target") == ELEMENT_ARRAY_BUFFER, where + ": index bufferView target")
            I = read(p["indices"])
            check(len(I) % 3 == 0, where + ": index count not a multiple of 3")
            check(max(I) < len(P), where + ": index out of range")
            for t in range(0, len(I), 3):
                a, b, c = (P[I[t + k]] for k in range(3))
                g = cross(sub(b, a), sub(c, a))
                check(length(g) > 1e-12, where + ": degenerate triangle %d" % (t // 3))
                navg = add(add(N[I[t]], N[I[t + 1]]), N[I[t + 2]])
                check(dot(g, navg) > 0, where + ": triangle %d winds against its normals" % (t // 3))
            tris += len(I) // 3
        triangles[mi] = tris

    # nodes, scene, cameras, lights
    nodes = d["nodes"]
    parent = {}
    for i, n in enumerate(nodes):
        for c in n.get("children", []):
            check(0 <= c < len(nodes) and c not in parent and c != i, "node %d child %d" % (i, c))
            parent[c] = i
        if "rotation" in n:
            check(abs(length(n["rotation"]) - 1) < 1e-5, "node %d rotation not unit" % i)
        if "mesh" in n:
            check(0 <= n["mesh"] < len(d["meshes"]), "node %d mesh" % i)
        if "camera" in n:
            check(0 <= n["camera"] < len(d["cameras"]), "node %d camera" % i)
        if "extensions" in n:
            check(EXT_LIGHTS in used, "node %d light without extensionsUsed" % i)
            check(0 <= n["extensions"][EXT_LIGHTS]["light"] < len(d["extensions"][EXT_LIGHTS]["lights"]), "node %d light" % i)
    roots = d["scenes"][d["scene"]]["nodes"]
    check(all(r not in parent for r in roots), "a scene root has a parent")

    instanced_tris = 0
    world_lo, world_hi = [1e30] * 3, [-1e30] * 3
    stack = [(r, mat_identity()) for r in roots]
    reached = set()
    while stack:
        i, pm = stack.pop()
        check(i not in reached, "node %d reached twice (cycle?)" % i)
        reached.add(i)
        n = nodes[i]
        m = mat_mul(pm, mat_trs(n.get("translation", (0, 0, 0)), n.get("rotation", (0, 0, 0, 1)), n.get("scale", (1, 1, 1))))
        if "mesh" in n:
            instanced_tris += triangles[n["mesh"]]
            for p in d["meshes"][n["mesh"]]["primitives"]:
                a = d["accessors"][p["attributes"]["POSITION"]]
                for cx in (a["min"][0], a["max"][0]):
                    for cy in (a["min"][1], a["max"][1]):
                        for cz in (a["min"][2], a["max"][2]):
                            w = mat_point(m, (cx, cy, cz))
                            world_lo = [min(x, y) for x, y in zip(world_lo, w)]
                            world_hi = [max(x, y) for x, y in zip(world_hi, w)]
        stack += [(c, m) for c in n.get("children", [])]
    check(reached == set(range(len(nodes))), "nodes not reachable from the scene")
    for i, c in enumerate(d.get("cameras", [])):
        pp = c["perspective"]
        check(c["type"] == "perspective" and pp["yfov"] > 0 and 0 < pp["znear"] < pp["zfar"], "camera %d" % i)

    # animations
    for ai, anim in enumerate(d.get("animations", [])):
        for ci, ch in enumerate(anim["channels"]):
            where = "animation %d channel %d" % (ai, ci)
            s = anim["samplers"][ch["sampler"]]
            tgt = ch["target"]
            ia, oa = d["accessors"][s["input"]], d["accessors"][s["output"]]
            if tgt["path"] == "pointer":
                check("node" not in tgt and EXT_POINTER in used, where + ": pointer target")
                pointer = tgt["extensions"][EXT_POINTER]["pointer"]
                m = re.fullmatch(r"/materials/(\d+)/extensions/%s/emissiveStrength" % EXT_EMISSIVE, pointer)
                check(m is not None and int(m.group(1)) < len(d.get("materials", [])), where + ": pointer " + pointer)
                check(oa["type"] == "SCALAR" and oa["componentType"] == FLOAT, where + ": output type")
                check(s["interpolation"] == "STEP" and oa["count"] == ia["count"], where + ": output count")
                check(all(v > 0 for v in read(s["output"])), where + ": the light must emit at all times")
                continue
            check(0 <= tgt["node"] < len(nodes) and tgt["path"] in ("translation", "rotation", "scale"), where + ": target")
            check("min" in ia and "max" in ia and ia["type"] == "SCALAR" and ia["componentType"] == FLOAT, where + ": input accessor")
            times = read(s["input"])
            check(times[0] >= 0 and all(b > a for a, b in zip(times, times[1:])), where + ": times not increasing")
            per = 3 if s["interpolation"] == "CUBICSPLINE" else 1
            check(s["interpolation"] in ("LINEAR", "STEP", "CUBICSPLINE"), where + ": interpolation")
            check(oa["count"] == per * len(times), where + ": output count")
            check(oa["type"] == ("VEC4" if tgt["path"] == "rotation" else "VEC3") and oa["componentType"] == FLOAT, where + ": output type")
            if tgt["path"] == "rotation":
                vals = read(s["output"])
                keys = vals[1::3] if per == 3 else vals
                check(all(abs(length(q) - 1) < 1e-5 for q in keys), where + ": rotation keys not unit")
                if s["interpolation"] == "LINEAR":
                    check(all(dot(a, b) > 0 for a, b in zip(keys, keys[1:])), where + ": consecutive quaternions not sign-continuous")

    return {
        "file": os.path.basename(path), "bytes": len(raw), "triangles": sum(triangles.values()),
        "instanced": instanced_tris, "meshes": len(d["meshes"]), "materials": len(d.get("materials", [])),
        "images": len(images), "animations": len(d.get("animations", [])), "nodes": len(nodes),
        "images_decoded": images, "bounds": (world_lo, world_hi),
    }


def print_summary(rows):
    head = ("file", "bytes", "KiB", "tris(mesh)", "tris(inst)", "meshes", "materials", "images", "anims", "nodes")
    table = [head] + [(r["file"], str(r["bytes"]), "%.1f" % (r["bytes"] / 1024), str(r["triangles"]), str(r["instanced"]),
                       str(r["meshes"]), str(r["materials"]), str(r["images"]), str(r["animations"]), str(r["nodes"])) for r in rows]
    widths = [max(len(t[c]) for t in table) for c in range(len(head))]
    for k, t in enumerate(table):
        print("  ".join(s.ljust(w) if c == 0 else s.rjust(w) for c, (s, w) in enumerate(zip(t, widths))))
        if k == 0:
            print("  ".join("-" * w for w in widths))
    for r in rows:
        lo, hi = r["bounds"]
        print("%s world bounds: [%s] .. [%s]" % (r["file"], ", ".join("%.3f" % x for x in lo), ", ".join("%.3f" % x for x in hi)))


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(root, "data", "scenes"), help="output folder (default data/scenes)")
    ap.add_argument("--check", action="store_true", help="only validate the existing files")
    args = ap.parse_args()

    built = {}
    if not args.check:
        os.makedirs(args.out, exist_ok=True)
        for name, make in SCENES:
            g = make()
            data = g.serialize()
            with open(os.path.join(args.out, name), "wb") as f:
                f.write(data)
            built[name] = g
    rows = []
    failed = False
    for name, _ in SCENES:
        path = os.path.join(args.out, name)
        try:
            r = validate(path)
            g = built.get(name)
            if g is not None:
                # round trip: the decoded PNG pixels equal the generated ones
                for (w, h, ch, rows_), (tname, src) in zip(r["images_decoded"], g.textures_rows.items()):
                    if rows_ != src:
                        raise Invalid("image %s does not round-trip" % tname)
            rows.append(r)
        except (Invalid, OSError, KeyError, ValueError, TypeError, IndexError, struct.error, zlib.error) as e:
            print("INVALID %s: %s: %s" % (path, type(e).__name__, e), file=sys.stderr)
            failed = True
    if rows:
        print_summary(rows)
    dyn = built.get("cornell_dynamic.gltf")
    if dyn is not None:
        print("cornell_dynamic camera max yaw: %.2f deg" % dyn.notes["camera_max_yaw_deg"])
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

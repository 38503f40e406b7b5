#!/usr/bin/env python3
"""Renders mutated inputs through the loom CLI and checks the bad-input contract on every run.

Mutations (seeded, so a run is reproducible): values, deletions and truncation of the shipped glTF scenes and
graphs, degenerate node transforms (scales of 0, far translations), edges and outputs between the fields of their
passes, out-of-range --set values, damaged Radiance .hdr environment maps (written here), and `loom view --headless`
scripts (fields switched, parameters set, the camera moved by 1e30 or turned by thousands of degrees, saves and a
video recorded, now and then a malformed line). Byte-level damage too: binary glTF (.glb, built here from the shipped
scenes with the buffer and the PNG images embedded), EXR environment maps (written here) and the PNG and EXR inputs
of `loom image montage` get bit flips, truncation, inserted and deleted bytes, and finite-but-extreme floats (1e30,
3e38, denormals, -0) written into their float data. Each run must

  - exit with 0, or with 2 and one message that starts with "error:" (a crash, a hang past --timeout or exit code 1
    fail the run);
  - write messages that are UTF-8, whatever bytes the input held;
  - leave no half-written file (".partial") in its output folder;
  - on success, dump only finite values: every float or half channel of every EXR.

Usage: mutate_inputs.py --loom build/release/bin/loom --source . [--seed 1] [--runs 12] [--timeout 60]
Prints each failing run with its command; exit code 1 when any failed.
"""
import argparse
import base64
import copy
import json
import math
import os
import random
import shutil
import struct
import subprocess
import sys
import tempfile
import zlib

WEIRD = [-1, 0, 1e30, -1e30, 99999, 2**31, 2**63, 0.5, "", "x", None, [], {}, True, [1e30, -1e30, 0], "NaN", 1e-45,
         -0.0, [0] * 16]


# ---- EXR: every float and half channel finite ----------------------------------------------------------------

def _exr_unzip(data, size):
    raw = bytearray(zlib.decompress(data))
    for i in range(1, len(raw)):  # the predictor: differences of consecutive bytes, offset by 128
        raw[i] = (raw[i - 1] + raw[i] - 128) & 0xFF
    half = (len(raw) + 1) // 2
    out = bytearray(len(raw))
    out[0::2] = raw[:half]
    out[1::2] = raw[half:]
    if len(out) != size:
        raise ValueError("ZIP block of %d bytes, expected %d" % (len(out), size))
    return out


def exr_nonfinite(path):
    """Counts the non-finite values of a scanline EXR (uncompressed or ZIP/ZIPS), as {channel: count}."""
    b = open(path, "rb").read()
    if struct.unpack_from("<I", b, 0)[0] != 20000630:
        raise ValueError("not an EXR")
    pos, channels, window, compression = 8, [], None, 0
    while b[pos] != 0:
        name_end = b.index(b"\0", pos)
        name = b[pos:name_end].decode()
        type_end = b.index(b"\0", name_end + 1)
        size = struct.unpack_from("<i", b, type_end + 1)[0]
        value = b[type_end + 5:type_end + 5 + size]
        if name == "channels":
            p = 0
            while value[p] != 0:
                e = value.index(b"\0", p)
                channels.append((value[p:e].decode(), struct.unpack_from("<i", value, e + 1)[0]))
                p = e + 1 + 16
        elif name == "dataWindow":
            window = struct.unpack_from("<4i", value, 0)
        elif name == "compression":
            compression = value[0]
        pos = type_end + 5 + size
    pos += 1
    if compression not in (0, 2, 3):
        raise ValueError("compression %d not handled" % compression)
    lines_per_block = {0: 1, 2: 1, 3: 16}[compression]
    width, height = window[2] - window[0] + 1, window[3] - window[1] + 1
    blocks = (height + lines_per_block - 1) // lines_per_block
    offsets = struct.unpack_from("<%dQ" % blocks, b, pos)
    channels.sort()
    sizes = {0: 4, 1: 2, 2: 4}  # UINT, HALF, FLOAT
    bad = {}
    for k, off in enumerate(offsets):
        lines = min(lines_per_block, height - k * lines_per_block)
        size = struct.unpack_from("<i", b, off + 4)[0]
        data = b[off + 8:off + 8 + size]
        expected = lines * width * sum(sizes[t] for _, t in channels)
        if size < expected:
            data = _exr_unzip(data, expected)
        p = 0
        for _ in range(lines):
            for name, t in channels:
                n = width * sizes[t]
                if t == 2:
                    values = struct.unpack_from("<%df" % width, data, p)
                    count = sum(1 for v in values if not math.isfinite(v))
                elif t == 1:
                    halves = struct.unpack_from("<%dH" % width, data, p)
                    count = sum(1 for h in halves if (h & 0x7C00) == 0x7C00)
                else:
                    count = 0
                if count:
                    bad[name] = bad.get(name, 0) + count
                p += n
    return bad


# ---- Radiance .hdr written here -------------------------------------------------------------------------------

def write_hdr(path, width, height, rng):
    """A run-length encoded RGBE map with runs and literal stretches."""
    rows = []
    for y in range(height):
        pixels = []
        for x in range(width):
            if x % 9 >= 5 and pixels:
                pixels.append(pixels[-1])
            else:
                pixels.append(bytes([rng.randrange(256), rng.randrange(256), rng.randrange(256),
                                     rng.choice([0, 100, 128, 140, 200])]))
        row = bytearray([2, 2, width >> 8, width & 0xFF])
        for c in range(4):
            values = [p[c] for p in pixels]
            x = 0
            while x < width:
                run = 1
                while x + run < width and run < 127 and values[x + run] == values[x]:
                    run += 1
                if run >= 3:
                    row += bytes([128 + run, values[x]])
                    x += run
                else:
                    n = min(128, width - x)
                    row += bytes([n]) + bytes(values[x:x + n])
                    x += n
        rows.append(bytes(row))
    header = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n" % (height, width)
    data = header + b"".join(rows)
    with open(path, "wb") as f:
        f.write(data)
    return data, len(header)


# ---- binary glTF and EXR written here ---------------------------------------------------------------------------

def make_glb(doc):
    """A .glb of a shipped scene: its JSON and one BIN chunk holding the buffer and, as bufferViews, the data-URI
    images. Returns (bytes, float ranges: [begin, end) of the float accessors' bufferViews, image ranges)."""
    d = copy.deepcopy(doc)
    uri = d["buffers"][0].pop("uri")
    bin_ = bytearray(base64.b64decode(uri[uri.index(",") + 1:]))
    images = []
    for image in d.get("images", []):
        uri = image.get("uri", "")
        if not uri.startswith("data:"):
            continue
        data = base64.b64decode(uri[uri.index(",") + 1:])
        bin_ += b"\0" * (-len(bin_) % 4)
        images.append((len(bin_), len(bin_) + len(data)))
        d["bufferViews"].append({"buffer": 0, "byteOffset": len(bin_), "byteLength": len(data)})
        bin_ += data
        del image["uri"]
        image["bufferView"] = len(d["bufferViews"]) - 1
        image["mimeType"] = uri[5:uri.index(";")]
    bin_ += b"\0" * (-len(bin_) % 4)
    d["buffers"][0]["byteLength"] = len(bin_)
    text = json.dumps(d).encode()
    text += b" " * (-len(text) % 4)
    start = 12 + 8 + len(text) + 8
    data = (b"glTF" + struct.pack("<II", 2, start + len(bin_)) + struct.pack("<I", len(text)) + b"JSON" + text +
            struct.pack("<I", len(bin_)) + b"BIN\0" + bytes(bin_))
    floats = []
    for acc in d["accessors"]:
        if acc.get("componentType") == 5126 and "bufferView" in acc:
            view = d["bufferViews"][acc["bufferView"]]
            floats.append((start + view.get("byteOffset", 0), start + view.get("byteOffset", 0) + view["byteLength"]))
    return data, floats, [(start + a, start + b) for a, b in images]


def write_exr(width, height, rng):
    """An uncompressed scanline EXR of FLOAT channels A, B, G, R (radiances up to 50). Returns (bytes, the float
    range: [begin, end) of the pixel data)."""
    def attr(name, kind, value):
        return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value
    channels = b"".join(c.encode() + b"\0" + struct.pack("<iBBBBii", 2, 0, 0, 0, 0, 1, 1) for c in "ABGR") + b"\0"
    window = struct.pack("<4i", 0, 0, width - 1, height - 1)
    header = (struct.pack("<ii", 20000630, 2) + attr("channels", "chlist", channels) +
              attr("compression", "compression", b"\0") + attr("dataWindow", "box2i", window) +
              attr("displayWindow", "box2i", window) + attr("lineOrder", "lineOrder", b"\0") +
              attr("pixelAspectRatio", "float", struct.pack("<f", 1)) +
              attr("screenWindowCenter", "v2f", struct.pack("<ff", 0, 0)) +
              attr("screenWindowWidth", "float", struct.pack("<f", 1)) + b"\0")
    line_size = 4 * 4 * width
    first = len(header) + 8 * height
    offsets = b"".join(struct.pack("<Q", first + y * (8 + line_size)) for y in range(height))
    lines = b""
    for y in range(height):
        values = [1.0] * width + [rng.uniform(0, 50) for _ in range(3 * width)]
        lines += struct.pack("<ii", y, line_size) + struct.pack("<%df" % (4 * width), *values)
    return header + offsets + lines, (first, first + len(lines))


# ---- mutations ------------------------------------------------------------------------------------------------

EXTREME_FLOATS = [1e30, -1e30, 3e38, -3.4e38, 3.4028234e38, 1.1754944e-38, 1e-45, -1e-45, 1e-40, -0.0, 1e-30]


def mutate_bytes(data, floats, images, rng):
    """One to four byte-level mutations: bit flips, truncation, inserted or deleted bytes, a 32-bit count set to an
    extreme, finite-but-extreme floats into a float range, or damage inside an embedded image."""
    b = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        op = rng.choice(["flip", "truncate", "insert", "delete", "count", "float", "float", "image"])
        if not b:
            b.append(rng.randrange(256))
        elif op == "flip":
            for _ in range(rng.randint(1, 8)):
                b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        elif op == "truncate":
            b = b[:rng.randrange(len(b))]
        elif op == "insert":
            at = rng.randrange(len(b) + 1)
            b[at:at] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
        elif op == "delete":
            at = rng.randrange(len(b))
            del b[at:at + rng.randint(1, 16)]
        elif op == "count" and len(b) >= 4:
            at = rng.randrange(len(b) // 4) * 4
            b[at:at + 4] = struct.pack("<i", rng.choice([0, -1, 2**31 - 1, -2**31, 65536, 255]))
        elif op == "float" and floats:
            begin, end = rng.choice(floats)
            for _ in range(rng.randint(1, 6)):
                at = begin + rng.randrange((end - begin) // 4) * 4
                if at + 4 <= len(b):
                    b[at:at + 4] = struct.pack("<f", rng.choice(EXTREME_FLOATS))
        elif op == "image" and images:
            begin, end = rng.choice(images)
            for _ in range(rng.randint(1, 4)):
                at = rng.randrange(begin, end)
                if at < len(b):
                    b[at] = rng.randrange(256)
    return bytes(b)


def json_paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from json_paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from json_paths(v, prefix + (i,))


def mutate_values(doc, rng):
    d = copy.deepcopy(doc)
    for _ in range(rng.randint(1, 3)):
        paths = [p for p in json_paths(d) if p and p[-1] != "uri"]
        p = rng.choice(paths)
        parent = d
        for k in p[:-1]:
            parent = parent[k]
        if rng.random() < 0.2:
            del parent[p[-1]]
        else:
            parent[p[-1]] = copy.deepcopy(rng.choice(WEIRD))
    return d


def mutate_transforms(scene, rng):
    """Degenerate node transforms: scales of 0 (whole or on one axis), tiny or huge scales, far translations."""
    d = copy.deepcopy(scene)
    for _ in range(rng.randint(1, 2)):
        node = rng.choice(d["nodes"])
        node.pop("matrix", None)
        if rng.random() < 0.7:
            node["scale"] = rng.choice([[0, 0, 0], [1, 0, 1], [0, 1, 1], [1e-30] * 3, [1e20] * 3, [1e-20, 1e20, 1]])
        else:
            node["translation"] = rng.choice([[1e30, 0, 0], [0, 1e20, 0], [0, 0, -1e19]])
    return d


def dump_json(doc, rng):
    text = json.dumps(doc)
    if rng.random() < 0.1:
        text = text[:rng.randint(0, len(text))]
    return text


def pass_fields(loom):
    """{type: {kind: [field, ...]}} from `loom passes`."""
    fields, current = {}, None
    for line in subprocess.run([loom, "passes"], capture_output=True, text=True).stdout.splitlines():
        words = line.split()
        if len(words) >= 2 and words[1] == "-" and not line.startswith(" "):
            current = fields.setdefault(words[0], {})
        elif current is not None and len(words) >= 2 and words[0] in ("input", "output", "history", "internal"):
            current.setdefault(words[0], []).append(words[1])
    return fields


def mutate_graph(graph, fields, rng):
    g = copy.deepcopy(graph)
    passes = g["passes"]
    for _ in range(rng.randint(1, 3)):
        a, b = rng.choice(passes), rng.choice(passes)
        fa, fb = fields.get(a["type"], {}), fields.get(b["type"], {})
        src = rng.choice(fa.get("output", ["x"]) + fa.get("history", []) + ["nope"])
        dst = rng.choice(fb.get("input", ["y"]) + ["nope"])
        op = rng.choice(["edge", "edge", "prev", "output", "remove"])
        if op == "remove" and len(passes) > 1:
            passes.pop(rng.randrange(len(passes)))
        elif op == "output":
            g.setdefault("outputs", []).append(a["name"] + "." + rng.choice(
                fa.get("history", []) + fa.get("internal", []) + fa.get("output", []) + ["nope"]))
        else:
            g.setdefault("edges", []).append([a["name"] + "." + src + ("@prev" if op == "prev" else ""),
                                              b["name"] + "." + dst])
    return g


# ---- runs -----------------------------------------------------------------------------------------------------

def view_script(fields, params, values, out, rng):
    """Lines of a `loom view --script`: well-formed commands with extreme arguments (moves of 1e30, turns of
    thousands of degrees, parameter values from `values`); one script in four also has a malformed line."""
    extreme = ["0", "0.1", "-0.3", "1", "90", "-720", "1e30", "-1e30", "1e-40", "3.4e38"]
    lines, frame = [], 1
    for _ in range(rng.randint(1, 8)):
        frame += rng.choice([0, 1, 1, 2])
        verb = rng.choice(["view", "set", "exposure", "reset", "save", "shot", "move", "turn"])
        if verb == "view":
            arg = rng.choice(fields)
        elif verb == "set":
            arg = "%s=%s" % (rng.choice(params), rng.choice(values))
        elif verb == "exposure":
            arg = rng.choice(["0", "-3", "12", "64", "-64"])
        elif verb in ("save", "shot"):
            arg = os.path.join(out, rng.choice(["a.exr", "b.png", "c"]))
        elif verb == "move":
            arg = " ".join(rng.choice(extreme) for _ in range(3))
        elif verb == "turn":
            arg = " ".join(rng.choice(extreme) for _ in range(2))
        else:
            arg = ""
        lines.append(("%d %s %s" % (frame, verb, arg)).rstrip())
    if rng.random() < 0.25:
        bad = rng.choice(["-1 reset", "x view ToneMap.dst", "99999999999999999999999 reset", "1 veiw ToneMap.dst",
                          "1 move 1 2", "1 turn nan 0", "1 exposure inf", "1 save %s" % os.path.join(out, "no/x.png"),
                          "0 shot %s" % os.path.join(out, "early.png"), "1 view Nope.dst", "1"])
        lines.insert(rng.randrange(len(lines) + 1), bad)
    return "\n".join(lines) + "\n"


def check_run(loom, args, out, timeout, tail=None):
    """Returns (exit code, a failure description or None). `tail`: the output arguments (render's by default)."""
    shutil.rmtree(out, ignore_errors=True)
    if tail is None:
        tail = ["--out", out, "--quiet"]
    else:
        os.makedirs(out)
    try:
        r = subprocess.run([loom] + args + tail, capture_output=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, "no exit within %d s" % timeout
    try:
        err = r.stderr.decode("utf-8")
    except UnicodeDecodeError:
        return r.returncode, "a message that is not UTF-8: %r" % r.stderr[-300:]
    errors = [l for l in err.splitlines() if l.startswith("error:")]
    if r.returncode not in (0, 2):
        return r.returncode, "exit code %d: %s" % (r.returncode, err[-400:])
    if r.returncode == 2 and len(errors) != 1:
        return r.returncode, "exit code 2 with %d error lines: %s" % (len(errors), err[-400:])
    files = os.listdir(out) if os.path.isdir(out) else []
    partial = [f for f in files if f.endswith(".partial")]
    if partial:
        return r.returncode, "half-written files left: %s" % partial[:3]
    if r.returncode == 0:
        for f in sorted(files):
            if f.endswith(".exr"):
                bad = exr_nonfinite(os.path.join(out, f))
                if bad:
                    return r.returncode, "non-finite values in %s: %s" % (f, bad)
    return r.returncode, None


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--loom", required=True)
    ap.add_argument("--source", required=True, help="the source tree (graphs/, data/scenes/)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--runs", type=int, default=12, help="runs per kind of mutation")
    ap.add_argument("--timeout", type=int, default=60)
    ap.add_argument("--keep", help="copy the inputs of failing runs into this folder")
    o = ap.parse_args()
    rng = random.Random(o.seed)
    graphs_dir = os.path.join(o.source, "graphs")
    scenes_dir = os.path.join(o.source, "data", "scenes")
    shipped = sorted(f for f in os.listdir(graphs_dir) if f.startswith("PathTracer") and f.endswith(".json"))
    scenes = sorted(f for f in os.listdir(scenes_dir) if f.endswith(".gltf"))
    fields = pass_fields(o.loom)
    work = tempfile.mkdtemp(prefix="loom_mutate_")
    out = os.path.join(work, "out")
    failures, codes = [], []

    def run(label, args, tail=None):
        code, why = check_run(o.loom, args, out, o.timeout, tail)
        codes.append(code)
        if why:
            failures.append("%s: loom %s\n    %s" % (label, " ".join(args), why))
            if o.keep:
                os.makedirs(o.keep, exist_ok=True)
                for a in args:
                    if a.startswith(work) and os.path.isfile(a):
                        shutil.copy(a, o.keep)

    dynamic = os.path.join(scenes_dir, "cornell_dynamic.gltf")
    small = ["--size", "48x32", "--frames", "3", "--dump", "*", "--jitter", "halton"]
    for i in range(o.runs):
        scene = json.load(open(os.path.join(scenes_dir, rng.choice(scenes))))
        path = os.path.join(work, "scene%d.gltf" % i)
        with open(path, "w") as f:
            f.write(dump_json(mutate_transforms(scene, rng) if rng.random() < 0.3 else mutate_values(scene, rng), rng))
        graph = os.path.join(graphs_dir, rng.choice(shipped + ["GBufferRT.json"]))
        run("scene %d" % i, ["render", "--graph", graph, "--scene", path, "--camera-path",
                             rng.choice(["static", "orbit"])] + small)
    for i in range(o.runs):
        graph = json.load(open(os.path.join(graphs_dir, rng.choice(shipped))))
        mutated = mutate_graph(graph, fields, rng) if rng.random() < 0.5 else mutate_values(graph, rng)
        path = os.path.join(work, "graph%d.json" % i)
        with open(path, "w") as f:
            f.write(dump_json(mutated, rng))
        run("graph %d" % i, ["render", "--graph", path, "--scene", dynamic] + small)
    params = ["SVGF.alpha", "SVGF.momentsAlpha", "SVGF.phiColor", "SVGF.phiNormal", "SVGF.phiDepth",
              "SVGF.iterations", "SVGF.feedbackTap", "TAA.alpha", "TAA.sigma", "ToneMap.exposure",
              "ToneMap.operator", "PathTracer.samplesPerPixel", "PathTracer.maxBounces", "Nope.x"]
    values = ["nan", "inf", "-inf", "-1", "0", "1e40", "abc", "", "1e-45", "2147483648", "-0", "0.999999"]
    for i in range(o.runs):
        sets = []
        for _ in range(rng.randint(1, 3)):
            sets += ["--set", "%s=%s" % (rng.choice(params), rng.choice(values))]
        run("set %d" % i, ["render", "--graph", os.path.join(graphs_dir, "PathTracerSVGFTAA.json"), "--scene",
                           dynamic] + small + sets)
    hdr, header_size = write_hdr(os.path.join(work, "sky.hdr"), 40, 12, rng)
    for i in range(o.runs):
        b = bytearray(hdr)
        kind = rng.choice(["truncate", "bytes", "header", "runs"])
        if kind == "truncate":
            b = b[:rng.randint(0, len(b) - 1)]
        elif kind == "bytes":
            for _ in range(rng.randint(1, 40)):
                b[rng.randrange(header_size, len(b))] = rng.randrange(256)
        elif kind == "header":
            b[rng.randrange(header_size)] = rng.randrange(256)
        else:  # run lengths of 0 or past the row
            for _ in range(rng.randint(1, 4)):
                b[rng.randrange(header_size + 4, len(b))] = rng.choice([0, 128, 255])
        path = os.path.join(work, "sky%d.hdr" % i)
        with open(path, "wb") as f:
            f.write(b)
        run("env map %d (%s)" % (i, kind), ["render", "--graph", os.path.join(graphs_dir, "PathTracerRaw.json"),
                                            "--scene", dynamic, "--env", path, "--size", "32x24", "--dump", "*"])
    # Byte-level damage: binary glTF scenes, EXR environment maps, and the PNG and EXR inputs of a montage.
    glbs = [make_glb(json.load(open(os.path.join(scenes_dir, f)))) for f in scenes]
    for i in range(o.runs):
        data, floats, images = rng.choice(glbs)
        path = os.path.join(work, "scene%d.glb" % i)
        with open(path, "wb") as f:
            f.write(mutate_bytes(data, floats, images, rng))
        run("glb %d" % i, ["render", "--graph", os.path.join(graphs_dir, rng.choice(shipped)), "--scene", path] +
            small)
    exr, exr_floats = write_exr(16, 8, rng)
    for i in range(o.runs):
        path = os.path.join(work, "sky%d.exr" % i)
        with open(path, "wb") as f:
            f.write(mutate_bytes(exr, [exr_floats], [], rng))
        run("env map exr %d" % i, ["render", "--graph", os.path.join(graphs_dir, "PathTracerRaw.json"), "--scene",
                                   dynamic, "--env", path, "--size", "32x24", "--dump", "*"])
    png = base64.b64decode(next(im["uri"] for im in json.load(open(os.path.join(scenes_dir, "materials.gltf")))
                                ["images"]).split(",", 1)[1])
    for i in range(o.runs):
        kind = rng.choice(["png", "exr"])
        path = os.path.join(work, "image%d.%s" % (i, kind))
        with open(path, "wb") as f:
            f.write(mutate_bytes(png, [], [(8, len(png))], rng) if kind == "png"
                    else mutate_bytes(exr, [exr_floats], [], rng))
        good = os.path.join(work, "good%d.%s" % (i, kind))
        with open(good, "wb") as f:
            f.write(png if kind == "png" else exr)
        run("montage %d (%s)" % (i, kind), ["image", "montage", good, path],
            ["--out", os.path.join(out, "montage.png")])
    shown = {"PathTracerSVGFTAA.json": ["SVGF.variance", "SVGF.moments", "TAA.colorHistory", "GBuffer.meshId",
                                     "GBuffer.mvec", "ToneMap.dst", "PathTracer.color", "GBuffer.vbuffer"],
             "GBufferRaster.json": ["GBuffer.mvec", "GBuffer.linearZ", "GBuffer.meshId", "GBuffer.normW"],
             "TestPattern.json": ["Blur.dst", "Counter.dst", "Display.dst", "Blur.tmp"]}
    view_params = params[:3] + ["TAA.alpha", "Blur.radius", "GBuffer.cullMode"]
    view_values = ["0", "1", "0.5", "3", "none", "1e40", "nan"]
    view_codes = []
    for i in range(o.runs):
        graph = rng.choice(sorted(shown))
        path = os.path.join(work, "script%d.txt" % i)
        with open(path, "w") as f:
            f.write(view_script(shown[graph], view_params, view_values, out, rng))
        record = os.path.join(out, "v.y4m") if rng.random() < 0.5 else os.path.join(out, "frames")
        # The still box: its camera is not animated, so the scripts' moves and turns take it.
        run("view script %d" % i, ["view", "--headless", "--graph", os.path.join(graphs_dir, graph), "--scene",
                                   os.path.join(scenes_dir, "cornell_box.gltf"), "--size", "40x24", "--frames", "4",
                                   "--script", path, "--jitter", "halton"], ["--record", record])
        view_codes.append(codes[-1])
    print("view scripts: %d shown, %d rejected" % (view_codes.count(0), view_codes.count(2)))
    shutil.rmtree(work, ignore_errors=True)
    for f in failures:
        print("FAILED " + f)
    print("%d runs (%d rendered, %d rejected as bad input), %d failed (seed %d)" %
          (len(codes), codes.count(0), codes.count(2), len(failures), o.seed))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())

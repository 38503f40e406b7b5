#!/usr/bin/env python3
"""Regenerates passes/PathTracer/BrdfTables.h and compares it with the committed file: the same layout and every
number within 2e-5: the generator's float arithmetic rounds differently under other compiler flags (entries moved by
up to 4.5e-6 between the release and the debug build), while a change of the BRDF moves them by far more."""
import re
import subprocess
import sys

gen, committed, out = sys.argv[1:4]
subprocess.run([gen, out], check=True)
number = re.compile(r"-?\d+\.\d+e[-+]\d+f")


def parse(path):
    text = open(path).read()
    return number.sub("N", text), [float(x[:-1]) for x in number.findall(text)]


layout_c, values_c = parse(committed)
layout_g, values_g = parse(out)
if layout_c != layout_g or len(values_c) != len(values_g):
    sys.exit("BrdfTables.h is out of date (layout): run build/release/bin/loom_gen_brdf_tables "
             "passes/PathTracer/BrdfTables.h")
worst = max(abs(a - b) for a, b in zip(values_c, values_g))
if worst > 2e-5:
    sys.exit(f"BrdfTables.h is out of date (largest difference {worst:.2e}): run "
             "build/release/bin/loom_gen_brdf_tables passes/PathTracer/BrdfTables.h")
print(f"{len(values_c)} values agree within {worst:.1e}")

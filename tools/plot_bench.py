#!/usr/bin/python3
"""Plots a `loom bench` results.json: error against time per frame.

    /usr/bin/python3 tools/plot_bench.py results.json plot.png [--title TEXT]

Two panels (RelMSE and FLIP, both against median ms per frame, log-log): the
brute-force path tracer at 1, 2, 4, ... spp as a line, each benchmarked graph
(or sweep point) as a labelled point. Needs Debian's python3-matplotlib; `loom
bench --plot` runs this script.
"""
import argparse
import json
import sys

try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:
    sys.stderr.write("plot_bench.py: matplotlib is missing (apt-get install python3-matplotlib)\n")
    sys.exit(2)


def label(run):
    return run["graph"] + (" " + run["params"] if run["params"] else "")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", help="results.json written by loom bench")
    parser.add_argument("output", help="PNG to write")
    parser.add_argument("--title", help="plot title (default: scene, size and camera)")
    args = parser.parse_args()

    with open(args.results) as f:
        data = json.load(f)
    title = args.title or "{} {}x{}, camera {}, {} frames ({} warm-up), reference {} spp".format(
        data["scene"], data["width"], data["height"], data["camera_path"], data["frames"], data["warmup"],
        data["reference"]["spp"])

    metrics = [("relmse", "RelMSE"), ("flip", "FLIP")]
    fig, axes = plt.subplots(1, len(metrics), figsize=(12, 6))
    curve = data["brute_force"]
    for ax, (key, name) in zip(axes, metrics):
        if curve:
            xs = [r["summary"]["total_ms"] for r in curve]
            ys = [r["summary"][key] for r in curve]
            ax.plot(xs, ys, "-o", color="0.35", label="brute force (path tracer alone)", zorder=1)
            for r, x, y in zip(curve, xs, ys):
                ax.annotate("{} spp".format(r["spp"]), (x, y), textcoords="offset points", xytext=(4, 4),
                            fontsize=7, color="0.35")
        markers = "sD^v<>ph*"
        for i, r in enumerate(data["variants"]):
            s = r["summary"]
            speedup = r["speedup_" + key]["text"]
            ax.scatter([s["total_ms"]], [s[key]], marker=markers[i % len(markers)], s=60, zorder=2,
                       label="{} ({} equal-error)".format(label(r), speedup))
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("median ms per frame")
        ax.set_ylabel("mean {} per frame (after warm-up)".format(name))
        ax.set_title(name)
        ax.grid(True, which="both", alpha=0.3)
        # Below the axes, so no point hides behind it.
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=1, frameon=False)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(args.output, dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())

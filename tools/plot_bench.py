#!/usr/bin/python3
"""Plots a `loom bench` results.json: error against time per frame, and error per frame.

    /usr/bin/python3 tools/plot_bench.py results.json plot.png [--frames-output plot_frames.png] [--title TEXT]

plot.png, two panels (RelMSE and FLIP, both against median ms per frame,
log-log): the brute-force path tracer at 1, 2, 4, ... spp as a line, each
benchmarked graph (or sweep point) as a labelled point.

plot_frames.png (with --frames-output): RelMSE per frame of every run, warm-up
frames included (shaded), the camera cut and lighting steps marked, with each
run's frames to recover after the cut in its label. Needs Debian's
python3-matplotlib; `loom bench --plot` runs this script.
"""
import argparse
import json
import sys

try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator
except ImportError:
    sys.stderr.write("plot_bench.py: matplotlib is missing (apt-get install python3-matplotlib)\n")
    sys.exit(2)


def label(run):
    return run["graph"] + (" " + run["params"] if run["params"] else "")


def plot_frames(data, title, output):
    """RelMSE per frame of every run, warm-up shaded, events marked (the lag figures)."""
    fig, ax = plt.subplots(figsize=(12, 6))
    warmup = data["warmup"]
    if warmup > 0:
        ax.axvspan(-0.5, warmup - 0.5, color="0.92", zorder=0, label="warm-up ({} frames)".format(warmup))
    ax.axvline(0, color="0.2", linestyle="--", linewidth=1, zorder=1, label="camera cut")
    for i, frame in enumerate(data.get("event_frames", [])):
        ax.axvline(frame, color="tab:red", linestyle=":", linewidth=1.2, zorder=1,
                   label="lighting step" if i == 0 else None)
    runs = data["variants"] + data["brute_force"]
    for r in runs:
        xs = [f["frame"] for f in r["frames"]]
        ys = [max(f["relmse"], 1e-12) for f in r["frames"]]
        cut = next((e for e in r.get("lag", {}).get("events", []) if e["kind"] == "cut"), None)
        lag = ""
        if cut is not None:
            n = cut["frames_to_recover"]
            lag = ", cut lag {}".format(n if n is not None else ("not settled" if not cut["settled"] else "n/a"))
        style = dict(color="0.55", linewidth=0.8, linestyle="-") if r in data["brute_force"] else dict(linewidth=1.5)
        ax.plot(xs, ys, label="{}{}".format(label(r), lag), zorder=2, **style)
    ax.set_yscale("log")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("frame")
    ax.set_ylabel("RelMSE")
    ax.set_title("RelMSE per frame (every run starts from empty history at its first frame)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, frameon=False)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(output, dpi=110)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", help="results.json written by loom bench")
    parser.add_argument("output", help="PNG to write")
    parser.add_argument("--frames-output", help="also write RelMSE per frame to this PNG")
    parser.add_argument("--title", help="plot title (default: scene, size and camera)")
    args = parser.parse_args()

    with open(args.results) as f:
        data = json.load(f)
    reference = data["reference"]
    # Given reference frames (--reference-sequence) have no sample count, and a scene-less run no camera.
    ref_text = ("reference {} spp".format(reference["spp"]) if reference.get("spp") is not None
                else "reference {}".format(reference.get("sequence") or "given"))
    shot = ("{} {}x{}, camera {}".format(data["scene"], data["width"], data["height"], data["camera_path"])
            if data.get("scene") else "{}x{}".format(data["width"], data["height"]))
    title = args.title or "{}, {} frames ({} warm-up), {}".format(shot, data["frames"], data["warmup"], ref_text)

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
    if args.frames_output:
        plot_frames(data, title, args.frames_output)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""What the tracer process's priority costs the frame and the tracer: one serial renderer and one
overlapped renderer per niceness (``RenderConfig.tracer_nice``), frames interleaved in one process.

    python benchmarks/bench_tracer_nice.py [--sizes 320x180,640x360] [--nices=-15,-10,-5,0,19]
        [--frames 24] [--passes 10] [--json FILE] [--chart FILE.png]

Every renderer draws the ``serenity bench`` camera path and moving sun (``--passes`` times over); at
each frame of the path every renderer draws once, in an order rotated from frame to frame, so a
drift of the machine's speed weighs on all alike. Per variant, over the frames after each pass's
first two: the median frame (wall ms), the median "cpu ray tracing" stage and "wait for ray
tracing", the tracer's CPU-ms; and the two ratios issue 12 asks about: the overlapped frame ÷ the
serial frame, and the overlapped tracer stage ÷ the serial (inline) one. A negative niceness needs
CAP_SYS_NICE (root); ``actual_nice`` records what the OS granted. Measures only; the default stays
what the committed results support.
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from serenity.io.results import machine_info, write_results  # noqa: E402

RT, WAIT = "cpu ray tracing", "wait for ray tracing"


def run_size(scene_name: str, w: int, h: int, nices: list[int], frames: int, passes: int, quality: str) -> dict:
    from serenity.bench import camera_path, sun_path
    from serenity.config import RenderConfig
    from serenity.frame import Renderer
    from serenity.scene import load

    base = load(scene_name)
    names = ["serial"] + [f"nice {n}" for n in nices]
    configs = [RenderConfig.preset(quality, overlap=False)] + [
        RenderConfig.preset(quality, overlap=True, tracer_nice=n) for n in nices]
    scenes = {k: copy.deepcopy(base) for k in names}
    renderers = {k: Renderer(scenes[k], w, h, config=c) for k, c in zip(names, configs, strict=True)}
    rec = {k: {"frame": [], "rt": [], "wait": [], "rt_cpu": []} for k in names}
    bc, bs = base.camera, np.asarray(base.sun.direction, np.float64).copy()
    try:
        with tqdm(total=passes * frames, desc=f"tracer nice {w}x{h}", unit="frame") as bar:
            for _ in range(passes):
                for i in range(frames):
                    t = i / max(1, frames - 1)
                    order = names[i % len(names):] + names[:i % len(names)]
                    for k in order:
                        sc = scenes[k]
                        sc.camera = camera_path(bc, t)
                        sc.sun.direction = sun_path(bs, t)
                        f = renderers[k].render(read_back=False)
                        if i >= 2:  # each pass's first frames rebuild what the jump back to t = 0 changed
                            rec[k]["frame"].append(f.wall_ms)
                            rec[k]["rt"].append(f.timings.get(RT, 0.0))
                            rec[k]["wait"].append(f.timings.get(WAIT, 0.0))
                            rec[k]["rt_cpu"].append(f.tracer_cpu_ms)
                    bar.update()
        actual = {k: r.tracer_niceness for k, r in renderers.items()}  # what the OS granted
    finally:
        for r in renderers.values():
            r.close()
    med = {k: {m: float(np.median(v)) for m, v in r.items()} for k, r in rec.items()}
    serial = med["serial"]
    out = {"serial": {"frame_ms": serial["frame"], "cpu_ray_tracing_ms": serial["rt"],
                      "tracer_cpu_ms": serial["rt_cpu"],
                      "tracer_cores_held": serial["rt_cpu"] / serial["rt"] if serial["rt"] else None},
           "overlapped": {}}
    for n in nices:
        m = med[f"nice {n}"]
        out["overlapped"][str(n)] = {
            # what the OS granted: a negative niceness needs CAP_SYS_NICE, without which the child runs at 0
            "actual_nice": actual.get(f"nice {n}"),
            "frame_ms": m["frame"], "cpu_ray_tracing_ms": m["rt"], "wait_for_ray_tracing_ms": m["wait"],
            # CPU-ms the tracer process spent on the rays (all its threads): the work, whatever the wall
            "tracer_cpu_ms": m["rt_cpu"], "tracer_cores_held": m["rt_cpu"] / m["rt"] if m["rt"] else None,
            "frame_ratio_vs_serial": m["frame"] / serial["frame"],
            "tracer_ratio_vs_serial": m["rt"] / serial["rt"] if serial["rt"] else None,
            "frame_ms_p10_p90": [float(np.percentile(rec[f"nice {n}"]["frame"], q)) for q in (10, 90)]}
    return out


def chart(result: dict, path: str) -> None:
    from serenity.optional import pyplot

    plt = pyplot("the tracer-niceness chart")
    sizes = list(result["sizes"])
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for size in sizes:
        r = result["sizes"][size]
        nices = [int(n) for n in r["overlapped"]]
        o = [r["overlapped"][str(n)] for n in nices]
        axes[0].plot(nices, [v["frame_ratio_vs_serial"] for v in o], "o-", label=size)
        line, = axes[1].plot(nices, [v["tracer_ratio_vs_serial"] for v in o], "o-", label=f"{size}: wall")
        axes[1].plot(nices, [v["tracer_cpu_ms"] / r["serial"]["tracer_cpu_ms"] for v in o], "s--",
                     color=line.get_color(), label=f"{size}: CPU-ms")
    axes[0].axhline(1.0, color="grey", lw=0.8, ls="--")
    axes[1].axhline(1.5, color="grey", lw=0.8, ls="--")
    axes[0].set_title("overlapped frame / serial frame (bar: ≤ 1)", fontsize=10)
    axes[1].set_title("overlapped tracer / inline: wall (bar: ≤ 1.5) and CPU-ms", fontsize=10)
    axes[1].set_ylim(bottom=0.9)
    for ax in axes:
        ax.set_xlabel("tracer process niceness")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"{result['scene']}, {result['quality']}: medians of {result['frames_per_variant']} frames "
                 "per variant, interleaved", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="courtyard")
    ap.add_argument("--sizes", default="320x180,640x360")
    ap.add_argument("--nices", default="-15,-10,-5,0,19")
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--passes", type=int, default=10)
    ap.add_argument("--quality", default="medium")
    ap.add_argument("--json")
    ap.add_argument("--chart")
    args = ap.parse_args(argv)
    nices = [int(n) for n in args.nices.split(",")]
    cli = argv if argv is not None else sys.argv[1:]
    result = {"benchmark": "tracer_nice", "command": "python benchmarks/bench_tracer_nice.py " + " ".join(cli),
              "scene": args.scene, "quality": args.quality, "nices": nices,
              "frames_per_variant": args.passes * (args.frames - 2),
              "machine": machine_info(), "sizes": {}}
    for size in args.sizes.split(","):
        w, h = (int(x) for x in size.lower().split("x"))
        r = result["sizes"][size] = run_size(args.scene, w, h, nices, args.frames, args.passes, args.quality)
        se = r["serial"]
        print(f"{size}: serial frame {se['frame_ms']:.1f} ms, tracer inline {se['cpu_ray_tracing_ms']:.2f} ms, "
              f"CPU {se['tracer_cpu_ms']:.2f} ms ({se['tracer_cores_held']:.2f} cores held)")
        for n, v in r["overlapped"].items():
            print(f"  nice {n:>2}: frame {v['frame_ms']:.1f} ms ({v['frame_ratio_vs_serial']:.3f}x serial), "
                  f"tracer {v['cpu_ray_tracing_ms']:.2f} ms ({v['tracer_ratio_vs_serial']:.2f}x inline), "
                  f"wait {v['wait_for_ray_tracing_ms']:.2f} ms, tracer CPU {v['tracer_cpu_ms']:.2f} ms "
                  f"({v['tracer_cores_held']:.2f} cores held)")
    result["load_average_after"] = list(os.getloadavg())
    if args.json:
        write_results(args.json, result)
    if args.chart:
        chart(result, args.chart)
        print(f"wrote {args.chart}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

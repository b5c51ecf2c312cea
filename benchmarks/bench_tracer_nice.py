"""What the tracer process's scheduling costs the frame and the tracer: one serial renderer and one
overlapped renderer per variant, frames interleaved in one process.

    python benchmarks/bench_tracer_nice.py [--sizes 320x180,640x360] [--variants=default,19,0,19/session/idle]
        [--frames 24] [--passes 10] [--json FILE] [--chart FILE.png]

A variant is ``default`` (RenderConfig's own settings) or ``NICE[/session][/idle]``: the tracer
process's niceness (``ScheduleConfig.tracer_nice``), in a session of its own (``tracer_session``: its
own autogroup where Linux has them), and its rays handed over where the main thread is about to
wait for the volume worker instead of right after the G-buffer (``tracer_start = "idle"``; without
``/idle`` "g-buffer"). ``own_group`` records whether the tracer got a scheduling group of its own,
which decides where ``default``'s "auto" start hands the rays over.

Every renderer draws the ``serenity bench`` camera path and moving sun (``--passes`` times over); at
each frame of the path every renderer draws once, in an order rotated from frame to frame, so a
drift of the machine's speed weighs on all alike. Per variant, over the frames after each pass's
first two: the median frame (wall ms), the median "cpu ray tracing" stage and "wait for ray
tracing", the tracer's CPU-ms; and the two ratios the overlap is judged by: the overlapped frame ÷ the
serial frame, and the overlapped tracer stage ÷ the serial (inline) one. A negative niceness needs
CAP_SYS_NICE (root); ``actual_nice`` records what the OS granted, ``scheduling_group`` the tracer's
autogroup. The chart puts each variant at (tracer ÷ inline, frame ÷ serial), one panel per size,
with the two bars as lines. ``--load N`` runs N busy-looping processes beside the renderers, each in
a session of its own (as another program on the machine would be), to see each variant on a machine
that is not idle.
"""

from __future__ import annotations

import argparse
import copy
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from serenity.io.results import machine_info, write_results  # noqa: E402

RT, WAIT = "cpu ray tracing", "wait for ray tracing"


def parse_variant(spec: str) -> dict:
    """``NICE[/session][/idle]`` → the ScheduleConfig fields it sets; ``default`` → none (ScheduleConfig's
    own: nice 19, a session of its own, the "auto" start)."""
    if spec.strip() == "default":
        return {}
    nice, *flags = spec.strip().split("/")
    if set(flags) - {"session", "idle"}:
        raise SystemExit(f"a variant is NICE[/session][/idle], got {spec!r}")
    return {"tracer_nice": int(nice), "tracer_session": "session" in flags,
            "tracer_start": "idle" if "idle" in flags else "g-buffer"}


def run_size(scene_name: str, w: int, h: int, variants: list[str], frames: int, passes: int, quality: str) -> dict:
    from serenity.bench import camera_path, sun_path
    from serenity.config import RenderConfig, ScheduleConfig
    from serenity.frame import Renderer
    from serenity.scene import load

    base = load(scene_name)
    names = ["serial", *variants]
    configs = [RenderConfig.preset(quality, schedule=ScheduleConfig(overlap=False))] + [
        RenderConfig.preset(quality, schedule=ScheduleConfig(overlap=True, **parse_variant(v))) for v in variants]
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
        groups = {k: r._tracer_proc.scheduling_group if r._tracer_proc else None for k, r in renderers.items()}
        own = {k: r._tracer_proc.own_group if r._tracer_proc else None for k, r in renderers.items()}
    finally:
        for r in renderers.values():
            r.close()
    med = {k: {m: float(np.median(v)) for m, v in r.items()} for k, r in rec.items()}
    serial = med["serial"]
    out = {"serial": {"frame_ms": serial["frame"], "cpu_ray_tracing_ms": serial["rt"],
                      "tracer_cpu_ms": serial["rt_cpu"],
                      "tracer_cores_held": serial["rt_cpu"] / serial["rt"] if serial["rt"] else None},
           "overlapped": {}}
    for v in variants:
        m = med[v]
        out["overlapped"][v] = {
            **parse_variant(v),
            # what the OS granted: a negative niceness needs CAP_SYS_NICE, without which the child runs at 0
            "actual_nice": actual.get(v), "scheduling_group": groups.get(v), "own_group": own.get(v),
            "frame_ms": m["frame"], "cpu_ray_tracing_ms": m["rt"], "wait_for_ray_tracing_ms": m["wait"],
            # CPU-ms the tracer process spent on the rays (all its threads): the work, whatever the wall
            "tracer_cpu_ms": m["rt_cpu"], "tracer_cores_held": m["rt_cpu"] / m["rt"] if m["rt"] else None,
            "frame_ratio_vs_serial": m["frame"] / serial["frame"],
            "tracer_ratio_vs_serial": m["rt"] / serial["rt"] if serial["rt"] else None,
            "frame_ms_p10_p90": [float(np.percentile(rec[v]["frame"], q)) for q in (10, 90)]}
    return out


def chart(result: dict, path: str) -> None:
    from serenity.optional import pyplot

    plt = pyplot("the tracer-scheduling chart")
    sizes = list(result["sizes"])
    variants = list(result["variants"])
    markers = "osD^v<>ph*"
    fig, axes = plt.subplots(1, len(sizes), figsize=(5.5 * len(sizes), 4.6), squeeze=False)
    for ax, size in zip(axes[0], sizes, strict=True):
        o = result["sizes"][size]["overlapped"]
        ax.axvline(1.5, color="grey", lw=0.8, ls="--")
        ax.axhline(1.0, color="grey", lw=0.8, ls="--")
        for k, v in enumerate(variants):
            ax.plot(o[v]["tracer_ratio_vs_serial"], o[v]["frame_ratio_vs_serial"], markers[k % len(markers)],
                    color=f"C{k}", ms=8, label=v)
        xs = [o[v]["tracer_ratio_vs_serial"] for v in variants]
        ys = [o[v]["frame_ratio_vs_serial"] for v in variants]
        ax.set_xlim(0.9, max(xs + [1.6]) * 1.08)
        lo, hi = min(ys + [0.98]), max(ys + [1.01])
        y0 = lo - 0.1 * (hi - lo)
        ax.set_ylim(y0, hi + 0.1 * (hi - lo))
        ax.fill_between([0.9, 1.5], y0, 1.0, color="tab:green", alpha=0.08, lw=0)  # both bars met
        ax.set_title(f"{size}: both bars met in the lower left", fontsize=10)
        ax.set_xlabel("tracer stage, overlapped ÷ inline (bar ≤ 1.5)")
        ax.set_ylabel("frame, overlapped ÷ serial (bar ≤ 1)")
        ax.grid(alpha=0.3)
    axes[0][-1].legend(fontsize=8, title="NICE[/session][/idle]", title_fontsize=8, loc="best")
    load = result.get("background_load")
    fig.suptitle(f"{result['scene']}, {result['quality']}: medians of {result['frames_per_variant']} frames "
                 "per variant, interleaved" + (f", busy-looping processes beside: {load}" if load else ""),
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def measure_size(args, result: dict, size: str, variants: list[str]) -> None:
    w, h = (int(x) for x in size.lower().split("x"))
    r = result["sizes"][size] = run_size(args.scene, w, h, variants, args.frames, args.passes, args.quality)
    se = r["serial"]
    print(f"{size}: serial frame {se['frame_ms']:.1f} ms, tracer inline {se['cpu_ray_tracing_ms']:.2f} ms, "
          f"CPU {se['tracer_cpu_ms']:.2f} ms ({se['tracer_cores_held']:.2f} cores held)")
    for n, v in r["overlapped"].items():
        print(f"  {n:>18}: frame {v['frame_ms']:.1f} ms ({v['frame_ratio_vs_serial']:.3f}x serial), "
              f"tracer {v['cpu_ray_tracing_ms']:.2f} ms ({v['tracer_ratio_vs_serial']:.2f}x inline), "
              f"wait {v['wait_for_ray_tracing_ms']:.2f} ms, tracer CPU {v['tracer_cpu_ms']:.2f} ms "
              f"({v['tracer_cores_held']:.2f} cores held)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="courtyard")
    ap.add_argument("--sizes", default="320x180,640x360")
    ap.add_argument("--variants", default="default,19,19/idle,0,-5,0/idle,19/session",
                    help="default or NICE[/session][/idle], comma-separated")
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--passes", type=int, default=10)
    ap.add_argument("--quality", default="lpv-fast")
    ap.add_argument("--load", type=int, default=0, help="busy-looping processes to run beside (other programs)")
    ap.add_argument("--json")
    ap.add_argument("--chart")
    args = ap.parse_args(argv)
    variants = args.variants.split(",")
    for v in variants:
        parse_variant(v)
    cli = argv if argv is not None else sys.argv[1:]
    result = {"benchmark": "tracer_nice", "command": "python benchmarks/bench_tracer_nice.py " + " ".join(cli),
              "scene": args.scene, "quality": args.quality, "variants": variants,
              "background_load": args.load,  # whether autogroups are on: machine.sched_autogroup
              "frames_per_variant": args.passes * (args.frames - 2),
              "machine": machine_info(), "sizes": {}}
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"], start_new_session=True)
                for _ in range(args.load)]
    try:
        for size in args.sizes.split(","):
            measure_size(args, result, size, variants)
    finally:
        for p in spinners:
            p.kill()
            p.wait()
    result["load_average_after"] = list(os.getloadavg())
    if args.json:
        write_results(args.json, result)
    if args.chart:
        chart(result, args.chart)
        print(f"wrote {args.chart}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Warp on CUDA against Warp on the CPU, on one machine with an NVIDIA GPU (OpenGL runs on that GPU
in both cases; only the Warp kernels change device).

1. Agreement: the courtyard and the Cornell box at 320×180 (``lpv-fast``), the same two frames
   rendered with Warp on the CPU and on ``cuda:0``; FLIP and relMSE of the CUDA image against the
   CPU one (the CPU path is the tested one), and the share of pixels more than 1 % apart.
2. The frame benchmark of ``serenity bench`` (camera path, moving sun, overlapped and serial
   schedules) on ``cuda:0`` and on the CPU, at 640×360 and 320×180, with the timeline chart of one
   overlapped CUDA frame at 640×360.

    python benchmarks/bench_cuda.py [--json benchmarks/results/cuda.json] [--frames 24]
                                    [--chart benchmarks/results/cuda.png]

Without a CUDA device it stops with a one-line message.
"""

from __future__ import annotations

import argparse
import copy
import os
import platform
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from serenity.bench import bench  # noqa: E402
from serenity.config import RenderConfig  # noqa: E402
from serenity.device import available_devices  # noqa: E402
from serenity.eval import metrics  # noqa: E402
from serenity.frame import Renderer  # noqa: E402
from serenity.io.results import write_results  # noqa: E402
from serenity.raster.context import renderer_name  # noqa: E402
from serenity.scene import load  # noqa: E402

SIZES = ((640, 360), (320, 180))


def render_pair(scene_name: str, width: int, height: int, frames: int = 2, devices=("cpu", "cuda:0")) -> dict:
    """The same ``frames`` frames on the CPU and on cuda:0; metrics of the CUDA image vs the CPU one."""
    scene = load(scene_name)
    images, ms = {}, {}
    for device in devices:
        r = Renderer(copy.deepcopy(scene), width, height, device=device, config=RenderConfig.preset("lpv-fast"))
        for _ in range(frames):
            f = r.render(read_back={"hdr"})
        images[device], ms[device] = f.hdr[..., :3].astype(np.float64), f.wall_ms
        r.close()
    cpu, cuda = (images[d] for d in devices)
    rel = np.abs(cuda - cpu) / np.maximum(np.abs(cpu), 1e-3)
    out = {"scene": scene_name, "size": [width, height], "frames": frames,
           "rel_mse": metrics.rel_mse(cuda, cpu), "pixels_over_1pct": float(np.mean(rel.max(axis=-1) > 0.01)),
           "max_rel_diff": float(rel.max()), "finite": bool(np.isfinite(cuda).all()),
           "last_frame_ms": ms}
    try:
        out["flip"] = metrics.flip(cuda, cpu)
    except Exception as e:  # flip-evaluator not installed on the GPU machine
        out["flip"] = None
        out["flip_note"] = str(e).splitlines()[0]
    print(f"{scene_name} {width}x{height}: CUDA vs CPU relMSE {out['rel_mse']:.2e}, FLIP {out['flip']}, "
          f"{100 * out['pixels_over_1pct']:.2f} % of pixels > 1 % apart")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", default=os.path.join(ROOT, "benchmarks", "results", "cuda.json"))
    ap.add_argument("--chart", default=os.path.join(ROOT, "benchmarks", "results", "cuda.png"))
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--devices", default="cuda:0,cpu", help="devices to benchmark (default %(default)s)")
    args = ap.parse_args(argv)
    devices = available_devices()
    if "cuda:0" not in devices:
        print(f"bench_cuda: no CUDA device here (devices: {', '.join(devices)})", file=sys.stderr)
        return 2
    import warp as wp

    t0 = time.perf_counter()
    results = {"machine": {"gpu": wp.get_device("cuda:0").name, "gl_renderer": None, "cpus": os.cpu_count(),
                           "platform": platform.platform(), "python": platform.python_version(),
                           "warp": wp.config.version}, "agreement": [], "bench": {}}
    for scene_name in ("courtyard", "cornell"):
        results["agreement"].append(render_pair(scene_name, 320, 180))
    results["machine"]["gl_renderer"] = renderer_name()
    for device in args.devices.split(","):
        for w, h in SIZES:
            chart = args.chart if (device.startswith("cuda") and (w, h) == SIZES[0]) else None
            r = bench("courtyard", w, h, args.frames, device, json_path=None, chart_path=chart)
            results["bench"].setdefault(device, {})[f"{w}x{h}"] = r
    results["seconds"] = time.perf_counter() - t0
    write_results(args.json, results)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Per-stage CPU cost of the frame, robust to a busy machine: llvmpipe renders on the calling
thread (LP_NUM_THREADS=0), the stage clock is the process's CPU time, serial schedule, the bench's
camera path and moving sun. Prints the median CPU-ms per stage over frames 2..N.

    python tools/profile_frame.py [WxH] [frames] [--quality Q] [--static]

CPU-ms are not wall ms (on 2 cores llvmpipe and the Warp launches split the work over both); use
it to see where the work is, and ``serenity bench`` for the frame's wall time.
"""

from __future__ import annotations

import argparse
import copy
import os
import time

os.environ.setdefault("LP_NUM_THREADS", "0")

import numpy as np  # noqa: E402

import serenity.frame as frame_module  # noqa: E402
import serenity.frame.renderer as frame_renderer  # noqa: E402
from serenity.bench import camera_path, sun_path  # noqa: E402
from serenity.config import QUALITY_PRESETS, RenderConfig, ScheduleConfig  # noqa: E402
from serenity.scene import load  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("size", nargs="?", default="640x360")
    ap.add_argument("frames", nargs="?", type=int, default=6)
    ap.add_argument("--quality", choices=QUALITY_PRESETS, default="lpv-fast")
    ap.add_argument("--scene", default="courtyard")
    ap.add_argument("--static", action="store_true", help="keep the camera and the sun still")
    args = ap.parse_args()
    w, h = (int(x) for x in args.size.split("x"))
    frame_renderer.time.perf_counter = time.process_time  # the stages' clock: CPU seconds
    scene = copy.deepcopy(load(args.scene))
    base_cam, base_sun = scene.camera, scene.sun.direction.copy()
    config = RenderConfig.preset(args.quality, schedule=ScheduleConfig(overlap=False))
    renderer = frame_module.Renderer(scene, w, h, config=config)
    records = []
    for i in range(args.frames):
        t = i / max(1, args.frames - 1)
        if not args.static:
            scene.camera = camera_path(base_cam, t)
            scene.sun.direction = sun_path(base_sun, t)
        records.append(renderer.render(read_back={"hdr"}).timings)
    renderer.close()
    recs = records[1:] or records
    names = [k for k in frame_module.STAGES if any(k in r for r in recs)]
    for k in names:
        print(f"{k:28s} {np.median([r.get(k, 0.0) for r in recs]):8.2f}")
    print(f"{'frame (median of sums)':28s} {np.median([sum(r.values()) for r in recs]):8.2f}  CPU-ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

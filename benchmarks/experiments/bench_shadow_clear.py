"""What clearing the shadow atlas's tiles costs: ``glClearTexSubImage`` against a scissored clear.

    python benchmarks/experiments/bench_shadow_clear.py [--sizes 320x180,640x360] [--frames 160] [--json FILE]

llvmpipe clears a whole framebuffer by tagging its tiles, but a part of one (``fbo.clear`` with a
viewport: one tile of the 2×2 cascade atlas) by drawing it; ``glClearTexSubImage`` writes the texels
directly (``serenity.raster.context.clear_depth_rect``). Two measurements:

- the clear alone: the median over 25 clears of one cascade tile (``finish()`` before and after) each
  way, at the two tile sizes ``lpv-fast`` uses (512² at 320×180, 1024² at 640×360);
- in the frame: one ``lpv-fast`` renderer on the serial schedule (so that no worker thread shares the
  cores with the stage) along ``serenity bench``'s camera path and moving sun (two tiles redrawn a
  frame), the clear switched between the two ways frame by frame; the median ``shadow maps (CSM)``
  stage and frame of each way, after 8 warm-up frames.

The images are the same either way (the test ``test_clear_depth_rect_clears_only_its_tile``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from serenity.io.results import machine_info, write_results  # noqa: E402


def clear_alone(ctx, context, native, tile: int, reps: int = 25) -> dict:
    depth = ctx.depth_texture((2 * tile, 2 * tile))
    fbo = ctx.framebuffer(depth_attachment=depth)
    before = ctx.fbo
    out = {}
    for name, way in (("clear_tex_sub_image", native), ("scissored_clear", None)):
        context._native_clear = way
        ts = []
        for _ in range(reps + 5):
            fbo.use()
            context.finish(ctx)
            t = time.perf_counter()
            context.clear_depth_rect(ctx, fbo, depth, (0, 0, tile, tile))
            context.finish(ctx)
            ts.append((time.perf_counter() - t) * 1e3)
        out[name] = float(np.median(ts[5:]))
    context._native_clear = native
    before.use()  # a framebuffer released while bound leaves GL_INVALID_OPERATION for the next call
    fbo.release()
    depth.release()
    return out


def in_frame(width: int, height: int, frames: int) -> dict:
    from serenity.bench import camera_path, sun_path
    from serenity.config import RenderConfig, ScheduleConfig
    from serenity.frame import Renderer
    from serenity.raster import context
    from serenity.scene import load

    scene = load("courtyard")
    cam0, sun0 = scene.camera, np.asarray(scene.sun.direction, np.float64).copy()
    r = Renderer(scene, width, height, config=RenderConfig.preset("lpv-fast", schedule=ScheduleConfig(overlap=False)))
    native = context._native_clear
    stage = {True: [], False: []}
    wall = {True: [], False: []}
    tiles = []  # tiles the CSM redrew per frame
    try:
        for i in range(frames):
            t = (i % 48) / 47
            scene.camera, scene.sun.direction = camera_path(cam0, t), sun_path(sun0, t)
            way = i % 2 == 0
            context._native_clear = native if way else None
            f = r.render(read_back=False)
            if i >= 8:
                stage[way].append(f.timings["shadow maps (CSM)"])
                wall[way].append(f.wall_ms)
                tiles.append(r.shadow_pass.redrawn)
        alone = clear_alone(r.ctx, context, native, r.shadow_size)
    finally:
        context._native_clear = native
        r.close()
    return {"tile": r.shadow_size, "clear_alone_ms": alone,
            "csm_stage_ms": {"clear_tex_sub_image": float(np.median(stage[True])),
                             "scissored_clear": float(np.median(stage[False]))},
            "frame_ms": {"clear_tex_sub_image": float(np.median(wall[True])),
                         "scissored_clear": float(np.median(wall[False]))},
            "frames_each": len(stage[True]), "tiles_redrawn_per_frame": float(np.mean(tiles))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="320x180,640x360")
    ap.add_argument("--frames", type=int, default=160)
    ap.add_argument("--json", default=str(ROOT / "benchmarks/experiments/results/shadow_clear.json"))
    args = ap.parse_args(argv)
    from serenity.raster import context

    context.get_context()
    if context._native_clear is None:
        raise SystemExit("glClearTexSubImage is not available on this GL context: nothing to compare")
    out = {"benchmark": "shadow_clear", "command": " ".join(["python", *sys.argv]), "machine": machine_info(),
           "sizes": {}}
    for size in args.sizes.split(","):
        w, h = (int(v) for v in size.lower().split("x"))
        res = out["sizes"][size] = in_frame(w, h, args.frames)
        a, s = res["clear_alone_ms"], res["csm_stage_ms"]
        print(f"{size}: {res['tile']}² tile clear {a['scissored_clear']:.3f} -> {a['clear_tex_sub_image']:.3f} ms; "
              f"CSM stage {s['scissored_clear']:.2f} -> {s['clear_tex_sub_image']:.2f} ms; frame "
              f"{res['frame_ms']['scissored_clear']:.1f} -> {res['frame_ms']['clear_tex_sub_image']:.1f} ms; "
              f"{res['tiles_redrawn_per_frame']:.2f} tiles redrawn a frame")
    write_results(args.json, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

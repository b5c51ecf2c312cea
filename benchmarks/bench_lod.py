"""Levels of detail on a production interior: triangles drawn, error against the path-traced
reference and the G-buffer's cost at each bound on a level's error, and what building the levels
costs on an empty cache.

    python benchmarks/bench_lod.py [--scene FILE] [--sizes 320x180,640x360] [--error-sizes 320x180]
        [--bounds 0,0.25,0.5,1,2] [--frames 8] [--json benchmarks/results/lod.json]

Per size: one renderer of the default preset; for each bound (``RenderConfig.lod_pixel_error``;
0 draws every mesh whole) the G-buffer's triangles at the scene's camera, FLIP and relMSE of the
converged frame (at the ``--error-sizes``) against the scene's reference
(``serenity.eval.reference.reference_for_error``, as the frontier renders it), and the G-buffer
stage's and the frame's median ms over ``--frames`` frames, the bounds' frames interleaved so that
a drifting machine load falls on all alike. Last, building the scene's levels with the disk cache
off (``scene_levels(cache=False)``), in seconds.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from serenity.config import RenderConfig  # noqa: E402
from serenity.eval.metrics import compare  # noqa: E402
from serenity.eval.reference import reference_for_error  # noqa: E402
from serenity.frame import Renderer  # noqa: E402
from serenity.io.results import write_results  # noqa: E402
from serenity.raster.scene_gl import LOD_PIXEL_ERROR  # noqa: E402
from serenity.scene.loaders import load  # noqa: E402
from serenity.scene.lod import scene_levels  # noqa: E402

BREAKFAST = ROOT / "scenes" / "breakfast_room" / "breakfast_room.toml"


def _set_bound(renderer, bound: float) -> None:
    """What ``RenderConfig.lod_pixel_error`` sets, on a built renderer (the passes read it per draw)."""
    renderer.gbuffer_pass.lod_pixel_error = renderer.shadow_pass.lod_pixel_error = bound
    renderer.shadow_pass.invalidate()


def run_size(scene, width: int, height: int, bounds: list[float], frames: int, with_error: bool) -> dict:
    cfg = RenderConfig.preset()
    ref = (reference_for_error(scene, width, height, flip=0.08, rel_mse=0.2, spp=256, max_spp=4096, seed=0,
                               progress=False).image if with_error else None)
    cam = scene.camera
    vp = cam.projection_matrix(width / height) @ cam.view_matrix()
    out = {"size": f"{width}x{height}", "bounds": {}}
    with Renderer(scene, width, height, config=cfg) as r:
        for b in bounds:
            _set_bound(r, b)
            for _ in range(6):  # the probes and the temporal passes settle
                r.render(read_back=False)
            frame = r.render(read_back=("hdr",))
            m = compare(frame.hdr, ref, exposure=cfg.exposure) if ref is not None else {"flip": None, "rel_mse": None}
            levels = r.scene_gl.levels(vp, width, height, b)
            drawn = sum(x.count for x in r.gbuffer_pass.ranges.visible(vp, levels=levels)) // 3
            out["bounds"][str(b)] = {"bound": b, "triangles": int(drawn), "flip": m["flip"], "rel_mse": m["rel_mse"],
                                     "gbuffer_ms": [], "frame_ms": []}
        for _ in tqdm(range(frames), desc=f"{width}x{height} frames", leave=False):
            for b in bounds:
                _set_bound(r, b)
                f = r.render(read_back=False)
                rec = out["bounds"][str(b)]
                rec["gbuffer_ms"].append(f.timings["g-buffer"])
                rec["frame_ms"].append(f.wall_ms)
    for rec in out["bounds"].values():
        rec["gbuffer_ms_median"] = float(np.median(rec["gbuffer_ms"]))
        rec["frame_ms_median"] = float(np.median(rec["frame_ms"]))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default=str(BREAKFAST))
    ap.add_argument("--sizes", default="320x180,640x360")
    ap.add_argument("--bounds", default="0,0.25,0.5,1,2")
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--error-sizes", default="320x180",
                    help="sizes whose error against the reference is measured (a 4096-spp reference each)")
    ap.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "lod.json"))
    args = ap.parse_args()
    scene = load(args.scene)
    bounds = [float(b) for b in args.bounds.split(",")]
    t0 = time.perf_counter()
    levels = scene_levels(scene.meshes, [True] * len(scene.meshes), cache=False)
    build_s = time.perf_counter() - t0
    sizes = []
    for s in args.sizes.split(","):
        w, h = (int(x) for x in s.lower().split("x"))
        sizes.append(run_size(scene, w, h, bounds, args.frames, s in args.error_sizes.split(",")))
    write_results(args.json, {
        "command": "python benchmarks/bench_lod.py " + " ".join(sys.argv[1:]),
        "scene": Path(args.scene).name if Path(args.scene).exists() else args.scene,
        "triangles": int(scene.triangle_count),
        "meshes_with_levels": int(sum(lv is not None for lv in levels)),
        "build_seconds": build_s,
        "default_bound": LOD_PIXEL_ERROR,
        "sizes": sizes,
    })


if __name__ == "__main__":
    main()

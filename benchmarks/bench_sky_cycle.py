"""What re-lighting the sky volume a few layers per frame costs in accuracy and buys in time.

With ``SkyConfig.method = "transfer"`` a rebaked sky can re-light every probe at once
(``transfer_layers`` = 0, the ``high`` preset) or ``transfer_layers`` y-layers per frame in a
continuous cycle, uploading only those layers (1 in ``medium`` and ``low``: the paper's one layer per
frame). This runs the frame benchmark's path (camera orbiting, the sun moving ~0.9° per frame, so
the sky map is rebaked every frame: the worst case for a cycle) with one renderer per setting,
interleaved frame by frame so that a shared machine's load falls on all alike, and reports per
setting the median ms of the sky stage ("sky volume update" + "sky upload") and how far each
frame's HDR image is from the all-at-once renderer's image of the same frame (relMSE, FLIP; the
all-at-once volume is current every frame, so this is the error the cycle's stale layers add).

    python benchmarks/bench_sky_cycle.py [--json benchmarks/results/sky_cycle.json]
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import os
import sys
import time

import numpy as np
from tqdm import tqdm

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from serenity.bench import camera_path, sun_path  # noqa: E402
from serenity.config import RenderConfig  # noqa: E402
from serenity.eval import metrics  # noqa: E402
from serenity.frame import SKY_UPDATE_STAGES, Renderer  # noqa: E402
from serenity.io.results import write_results  # noqa: E402
from serenity.scene import load  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="courtyard")
    ap.add_argument("--size", default="320x180")
    ap.add_argument("--quality", default="medium")
    ap.add_argument("--layers", default="0,1,2,3", help="transfer_layers settings; 0 (all at once) is the baseline")
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--json", default=os.path.join(ROOT, "benchmarks", "results", "sky_cycle.json"))
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.lower().split("x"))
    settings = [int(v) for v in args.layers.split(",")]
    if settings[0] != 0:
        settings = [0, *settings]
    base = load(args.scene)
    base_cam, base_sun = base.camera, base.sun.direction.copy()
    preset = RenderConfig.preset(args.quality)
    scenes, renderers = [], []
    for n in settings:
        s = copy.deepcopy(base)
        cfg = dataclasses.replace(preset, sky=dataclasses.replace(preset.sky, transfer_layers=n))
        scenes.append(s)
        renderers.append(Renderer(s, w, h, config=cfg))
    sky_ms = {n: [] for n in settings}
    errors = {n: [] for n in settings[1:]}
    t_start = time.perf_counter()
    for i in tqdm(range(args.frames), desc=f"sky cycle {args.scene} {args.size}", unit="frame"):
        t = i / max(1, args.frames - 1)
        images = {}
        for n, s, r in zip(settings, scenes, renderers, strict=True):
            s.camera = camera_path(base_cam, t)
            s.sun.direction = sun_path(base_sun, t)
            f = r.render(read_back={"hdr"})
            images[n] = f.hdr
            sky_ms[n].append(sum(f.timings.get(k, 0.0) for k in SKY_UPDATE_STAGES))
        for n in settings[1:]:
            errors[n].append({"frame": i, "rel_mse": metrics.rel_mse(images[n], images[0]),
                              "flip": metrics.flip(images[n], images[0])})
    for r in renderers:
        r.close()
    y = renderers[0].sky_volume.resolution[1]
    out = {"benchmark": "sky_cycle", "scene": args.scene, "size": [w, h], "quality": args.quality,
           "frames": args.frames, "sky_layers": int(y), "sun_deg_per_frame": 20.0 / max(1, args.frames - 1),
           "seconds": time.perf_counter() - t_start,
           "settings": {}}
    for n in settings:
        # the first frame builds the whole volume in every setting: left out of the median
        row = {"transfer_layers": n, "sky_stage_ms_median": float(np.median(sky_ms[n][1:])),
               "sky_stage_ms": sky_ms[n]}
        if n:
            e = errors[n][1:]
            row.update({"max_layer_age_frames": -(-y // n),
                        "rel_mse_vs_all_at_once_mean": float(np.mean([x["rel_mse"] for x in e])),
                        "rel_mse_vs_all_at_once_max": float(np.max([x["rel_mse"] for x in e])),
                        "flip_vs_all_at_once_mean": float(np.mean([x["flip"] for x in e])),
                        "flip_vs_all_at_once_max": float(np.max([x["flip"] for x in e])),
                        "per_frame": errors[n]})
        out["settings"][str(n)] = row
        print(f"transfer_layers={n}: sky stage {row['sky_stage_ms_median']:.2f} ms"
              + (f", vs all at once: relMSE mean {row['rel_mse_vs_all_at_once_mean']:.2e} max "
                 f"{row['rel_mse_vs_all_at_once_max']:.2e}, FLIP mean {row['flip_vs_all_at_once_mean']:.4f} "
                 f"max {row['flip_vs_all_at_once_max']:.4f}" if n else ""))
    write_results(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

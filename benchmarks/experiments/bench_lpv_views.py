"""Which LPV grid resolution to default to, judged over several views rather than one: the ``lpv-fast``
preset with each of ``--resolutions`` cells per cascade axis (everything else as the preset has it),
the courtyard from 4 camera positions and the Cornell box from 3, at 160×90 against 1024-spp
references (rendered once and cached; the LPV lives in world space, so a small image judges it).

    python benchmarks/experiments/bench_lpv_views.py [--json experiments/results/lpv_views.json]
                                         [--chart ...png] [--resolutions 12] [--lpv FIELD=VALUE ...]

Per scene, view and resolution: FLIP and relMSE (without the worst 0.1 % of pixels) of one frame; per
scene and resolution: their means over the views, and the median milliseconds of the LPV update
(the sun's RSM, the G-buffer VPLs, injection, propagation, upload: what a moving camera or sun pays
each frame) over ``--frames`` forced re-updates in the first view. The chart plots each of the three
against the resolution, one line per scene. ``--lpv FIELD=VALUE`` (repeatable; VALUE parsed as JSON)
sets an ``LPVConfig`` field for every row as well, e.g. ``--lpv view_distance=192`` to judge the
cascades fitted to the scene instead of the view (the JSON records the overrides).
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)

from serenity.config import RenderConfig  # noqa: E402
from serenity.eval import metrics  # noqa: E402
from serenity.eval.reference import render_reference  # noqa: E402
from serenity.frame import LPV_UPDATE_STAGES, Renderer  # noqa: E402
from serenity.io.results import write_results  # noqa: E402
from serenity.scene import load  # noqa: E402
from serenity.scene.model import Camera  # noqa: E402

SIZE = (160, 90)
REF_SPP = 1024
RESOLUTIONS = (6, 8, 10, 12, 14, 16)
VIEWS = {
    # None = the scene's own camera; else (position, target)
    "courtyard": (None, ((10.0, 1.7, 10.0), (-6.0, 3.0, -8.0)), ((-8.0, 1.7, -9.0), (6.0, 2.5, 8.0)),
                  ((0.0, 8.0, 14.0), (0.0, 0.0, -4.0))),
    "cornell": (None, ((0.45, 0.15, -0.6), (0.2, 0.3, 0.4)), ((0.1, 0.45, -0.5), (0.4, 0.1, 0.5))),
}


def view_scene(name: str, view):
    scene = load(name)
    if view is not None:
        c = scene.camera
        scene.camera = Camera(position=view[0], target=view[1], fov_y_deg=c.fov_y_deg, near=c.near, far=c.far)
    return scene


def config(resolution: int, lpv: dict | None = None) -> RenderConfig:
    m = RenderConfig.preset("lpv-fast")
    return dataclasses.replace(m, lpv=dataclasses.replace(m.lpv, resolution=resolution, **(lpv or {})))


def update_ms(scene, resolution: int, frames: int, lpv: dict | None = None) -> float:
    r = Renderer(copy.deepcopy(scene), *SIZE, config=config(resolution, lpv))
    try:
        r.render(read_back=False)
        out = []
        for _ in range(frames):
            r.invalidate_lpv()
            f = r.render(read_back=False)
            out.append(sum(f.timings.get(s, 0.0) for s in LPV_UPDATE_STAGES))
        return float(np.median(out))
    finally:
        r.close()


def run(resolutions, frames: int, progress: bool = True, lpv: dict | None = None) -> dict:
    from tqdm import tqdm

    out = {}
    total = sum(len(v) for v in VIEWS.values()) * len(resolutions) + len(VIEWS) * len(resolutions)
    with tqdm(total=total, disable=not progress, desc="lpv views") as bar:
        for name, views in VIEWS.items():
            per_view = []
            for vi, view in enumerate(views):
                scene = view_scene(name, view)
                bar.set_description(f"{name} view {vi}: reference")
                ref = render_reference(scene, *SIZE, spp=REF_SPP, progress=False)[..., :3]
                camera = None if view is None else [list(view[0]), list(view[1])]
                row = {"view": vi, "camera": camera, "by_resolution": {}}
                for res in resolutions:
                    bar.set_description(f"{name} view {vi}: {res}^3")
                    r = Renderer(copy.deepcopy(scene), *SIZE, config=config(res, lpv))
                    try:
                        f = r.render(read_back=("hdr",))
                        img = f.hdr[..., :3]
                        m = metrics.compare(img, ref, exposure=f.exposure)
                    finally:
                        r.close()
                    row["by_resolution"][str(res)] = {"flip": m["flip"],
                                                      "rel_mse_trimmed": metrics.rel_mse(img, ref, trim=1e-3)}
                    bar.update(1)
                per_view.append(row)
            scene = view_scene(name, views[0])
            summary = {}
            for res in resolutions:
                bar.set_description(f"{name}: update ms at {res}^3")
                vals = [v["by_resolution"][str(res)] for v in per_view]
                summary[str(res)] = {"flip_mean": float(np.mean([v["flip"] for v in vals])),
                                     "rel_mse_trimmed_mean": float(np.mean([v["rel_mse_trimmed"] for v in vals])),
                                     "update_ms": update_ms(scene, res, frames, lpv)}
                bar.update(1)
            out[name] = {"views": per_view, "summary": summary}
    return out


def chart(results: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = (("flip_mean", "mean FLIP over the views", "linear"),
              ("rel_mse_trimmed_mean", "mean relMSE (0.1 % trimmed)", "log"),
              ("update_ms", "LPV update per frame (ms, first view)", "linear"))
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for ax, (key, label, scale) in zip(axes, panels, strict=True):
        for name, res in results.items():
            pts = sorted((int(k), v[key]) for k, v in res["summary"].items())
            ax.plot([k for k, _ in pts], [v for _, v in pts], "o-", label=name)
        ax.set_xlabel("LPV cells per cascade axis")
        ax.set_ylabel(label)
        ax.set_yscale(scale)
        ax.set_xticks(sorted({int(k) for r in results.values() for k in r["summary"]}))
        ax.grid(alpha=0.3)
        ax.legend()
    fig.suptitle(f"LPV grid resolution (lpv-fast preset, {SIZE[0]}x{SIZE[1]}, {REF_SPP}-spp references)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"wrote {path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", default=os.path.join(ROOT, "benchmarks", "experiments", "results", "lpv_views.json"))
    ap.add_argument("--chart", default=os.path.join(ROOT, "benchmarks", "experiments", "results", "lpv_views.png"))
    ap.add_argument("--resolutions", default=",".join(map(str, RESOLUTIONS)))
    ap.add_argument("--frames", type=int, default=9)
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--chart-only", action="store_true", help="redraw the chart from --json")
    ap.add_argument("--lpv", action="append", default=[], metavar="FIELD=VALUE",
                    help="an LPVConfig field for every row (VALUE as JSON)")
    args = ap.parse_args()
    import json

    if args.chart_only:
        with open(args.json) as f:
            chart(json.load(f)["scenes"], args.chart)
        return
    resolutions = [int(x) for x in args.resolutions.split(",")]
    lpv = {}
    for pair in args.lpv:
        key, _, raw = pair.partition("=")
        lpv[key] = json.loads(raw)
    t0 = time.perf_counter()
    results = run(resolutions, args.frames, progress=not args.no_progress, lpv=lpv)
    for name, res in results.items():
        for k, v in res["summary"].items():
            print(f"{name:9s} {k:>2s}^3  FLIP {v['flip_mean']:.4f}  relMSE* {v['rel_mse_trimmed_mean']:.4f}  "
                  f"update {v['update_ms']:6.1f} ms")
    write_results(args.json, {"benchmark": "lpv_views", "size": list(SIZE), "reference_spp": REF_SPP,
                              "preset": "lpv-fast", "lpv_overrides": lpv, "resolutions": resolutions,
                              "frames": args.frames,
                              "update_stages": list(LPV_UPDATE_STAGES), "scenes": results,
                              "seconds": time.perf_counter() - t0})
    chart(results, args.chart)


if __name__ == "__main__":
    main()

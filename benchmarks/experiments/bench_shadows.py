"""Speed vs accuracy of the sun's shadows (hard / PCF / PCSS) and of SSAO (paper §6, §3).

    python benchmarks/experiments/bench_shadows.py [--json FILE] [--chart-dir DIR] [--size WxH]

Shadows: the ``penumbra`` scene (a 6 m pole's shadow tip under the 0.53° sun). Ours: the direct
light of each ground pixel divided by its unshadowed value (``frame.aovs["direct"]``) = visibility.
Exact: the fraction of the sun's disc visible from the same world point, by tracing 1024 stratified
rays into the disc with the kd-tree (``KdTree.occluded``). Error: mean |ours − exact| over the
penumbra band (pixels whose exact or estimated visibility is strictly between 0.02 and 0.98, the
only place the filters differ) and over all ground pixels.

SSAO: the courtyard. Exact: ray-traced ambient occlusion of the same radius — 1 − the cosine-
weighted fraction of 256 hemisphere rays that hit geometry within the radius — at the G-buffer's
positions and normals. Error: mean |SSAO − exact| over covered pixels.

Times are the medians over frames 2..N of the stages each setting changes: "shadow maps (CSM)" +
"direct lighting" for shadows, "ssao" for SSAO (ray tracing disabled, so nothing overlaps).
Writes JSON and two speed-vs-error charts.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys

import numpy as np

from serenity.config import RayTracingConfig, RenderConfig, ShadowConfig, SSAOConfig
from serenity.eval.exact import exact_ao, exact_sun_visibility
from serenity.frame import Renderer
from serenity.io.results import write_results
from serenity.kernels.kdtree import KdTree
from serenity.scene import load


def _median_ms(renderer, stages, frames):
    ts, frame = [], None
    for _ in range(frames):
        frame = renderer.render()
        ts.append(sum(frame.timings.get(s, 0.0) for s in stages))
    return float(np.median(ts[1:] if len(ts) > 1 else ts)), frame


def bench_shadows(size, frames):
    scene = load("penumbra")
    v, _, _, f, _ = scene.merged()
    tree = KdTree.build(v, f)
    settings = [("hard", {}, "hard")]
    settings += [("pcf", {"filter_samples": s}, f"PCF {s}") for s in (8, 16, 32, 64)]
    settings += [("pcss", {"blocker_samples": b, "filter_samples": s}, f"PCSS {b}/{s}")
                 for b, s in ((4, 8), (8, 16), (16, 32), (32, 64), (64, 128))]
    exact, points = None, []
    for mode, kw, label in settings:
        cfg = RenderConfig(shadow=ShadowConfig(filter=mode, **kw), ssao=SSAOConfig(enabled=False),
                           rt=RayTracingConfig(enabled=False))
        r = Renderer(scene, *size, config=cfg)
        ms, frame = _median_ms(r, ("shadow maps (CSM)", "direct lighting"), frames)
        pos, nrm = frame.aovs["position"], frame.aovs["normal"]
        ground = np.isfinite(frame.aovs["depth"][..., 0]) & (nrm[..., 1] > 0.99) & (pos[..., 1] < 1e-3)
        if exact is None:
            exact = np.full(ground.shape, np.nan)
            exact[ground] = exact_sun_visibility(tree, pos[ground], nrm[ground], scene.sun.direction,
                                                 scene.sun.angular_diameter_deg)
        ndl = float(scene.sun.direction[1])
        unshadowed = 0.5 / np.pi * scene.sun.irradiance[0] * ndl
        ours = np.clip(frame.aovs["direct"][..., 0] / unshadowed, 0, 1)
        band = ground & (((exact > 0.02) & (exact < 0.98)) | ((ours > 0.02) & (ours < 0.98)))
        err_band = float(np.mean(np.abs(ours[band] - exact[band])))
        err_all = float(np.mean(np.abs(ours[ground] - exact[ground])))
        points.append({"technique": mode, "label": label, "ms": ms, "error": err_band, "error_all": err_all,
                       "paper": label == "PCSS 16/32", **kw})
        print(f"  {label:<12} {ms:7.2f} ms   penumbra |err| {err_band:.4f}   all ground {err_all:.5f}")
    return points


def bench_ssao(size, frames):
    scene = load("courtyard")
    v, _, _, f, _ = scene.merged()
    tree = KdTree.build(v, f)
    exact, points = None, []
    settings = [(d, s) for d in (4, 8, 12, 16, 24) for s in (2, 4, 8)]
    for d, s in settings:
        cfg = RenderConfig(ssao=SSAOConfig(directions=d, steps=s), rt=RayTracingConfig(enabled=False))
        r = Renderer(scene, *size, config=cfg)
        ms, frame = _median_ms(r, ("ssao",), frames)
        covered = np.isfinite(frame.aovs["depth"][..., 0])
        if exact is None:
            exact = np.full(covered.shape, np.nan)
            exact[covered] = exact_ao(tree, frame.aovs["position"][covered], frame.aovs["normal"][covered],
                                      cfg.ssao.radius)
        ao = frame.aovs["ao"][..., 0]
        err = float(np.mean(np.abs(ao[covered] - exact[covered])))
        points.append({"technique": "ssao", "label": f"{d}x{s}", "ms": ms, "error": err,
                       "paper": (d, s) == (12, 4), "directions": d, "steps": s})
        print(f"  SSAO {d:>2} dirs x {s} steps  {ms:7.2f} ms   mean |AO err| {err:.4f}")
    return points


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", default="serenity_out/shadows.json")
    ap.add_argument("--chart-dir", default="serenity_out")
    ap.add_argument("--size", default="480x270")
    ap.add_argument("--frames", type=int, default=4)
    args = ap.parse_args(argv)
    size = tuple(int(x) for x in args.size.lower().split("x"))
    print("shadows (penumbra scene):")
    sh = bench_shadows(size, args.frames)
    print("SSAO (courtyard):")
    ao = bench_ssao(size, args.frames)
    out = {"machine": {"platform": platform.platform(), "cpus": os.cpu_count()}, "size": size,
           "shadows": sh, "ssao": ao}
    write_results(args.json, out)
    from serenity.eval.charts import save_speed_accuracy_chart

    os.makedirs(args.chart_dir, exist_ok=True)
    for name, pts, ylabel in (("shadows", sh, "mean |visibility error| in the penumbra band"),
                              ("ssao", ao, "mean |AO − ray-traced AO|")):
        path = os.path.join(args.chart_dir, f"{name}_speed_accuracy.png")
        save_speed_accuracy_chart(pts, path, error_name=ylabel,
                                  title=f"{name}: ms vs error ({size[0]}x{size[1]}, CPU/llvmpipe)")
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

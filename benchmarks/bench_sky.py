"""Sky: sky map bake, atmosphere accuracy vs steps, SH and sky-volume accuracy, volume cost (paper §5, §7).

    python benchmarks/bench_sky.py [--json FILE] [--chart FILE.png] [--device cpu] [--reps N] [--quick]

Everything runs on all CPU threads (``serenity.kernels.launch``); kernels are compiled and warmed up
outside the timed regions; figures are medians over ``--reps``.

Keys:
- ``skymap_bake_ms``: 256² paraboloid sky map at the default view steps.
- ``skymap_mean_rel_error`` / ``skymap_worst_rel_error``: per texel (every 16th texel inside the
  disc), fast model vs the float64 reference (256 view × 128 sun steps), mean over the sun
  elevations 90/45/10/2°; ``skymap_by_elevation`` each; ``skymap_steps_sweep`` steps vs error vs ms
  (the chart's left panel).
- ``sh_irradiance_mean_rel_error``: L2 SH irradiance (no window) of an unoccluded probe vs the
  brute-force cosine integral of the same sky map + ground, 1000 normals, mean over the elevations.
- ``quad_irradiance_mean_rel_error``: courtyard probes among the occlusion quads vs a brute-force
  16 384-ray integral of the same quads, sky and ground (24 probes × 26 normals × RGB), default
  rays per probe; ``rays_sweep`` rays per probe vs that error vs full-volume ms (right panel).
- ``volume_full_ms``: the 32×16×23 volume (paper's), default rays, courtyard quads, all threads;
  ``volume_layer_ms``: one layer of it (the per-frame cost); ``goal_ratio``: volume_full_ms / 1000
  (the goal: ≤ 1 s); ``time_of_day_lag_frames``: layers until the volume reflects a sun step.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time

import numpy as np

from serenity.config import SkyConfig
from serenity.device import cpu_threads, resolve_device
from serenity.io.results import write_results
from serenity.kernels import atmosphere as A
from serenity.kernels import sh as S
from serenity.kernels.occlusion import occluded_np
from serenity.kernels.sampling import fibonacci_sphere
from serenity.kernels.skyvolume import PAPER_RESOLUTION, SkyVolume
from serenity.scene.model import direction_from_angles
from serenity.scene.procedural import build_scene

ELEVATIONS = (90.0, 45.0, 10.0, 2.0)


def _median_ms(fn, reps):
    fn()
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        fn()
        ts.append((time.perf_counter() - t) * 1e3)
    return float(np.median(ts))


def skymap_accuracy(device, steps_list, reps):
    step = 16
    dirs = A.sky_map_directions(256)[step // 2::step, step // 2::step].reshape(-1, 3)
    dirs = dirs[A.sky_map_solid_angles(256)[step // 2::step, step // 2::step].reshape(-1) > 0]
    refs = {el: A.sky_radiance_reference(dirs, direction_from_angles(el, 135.0), view_steps=256, sun_steps=128)
            for el in ELEVATIONS}
    sweep = []
    for steps in steps_list:
        errs = {}
        for el in ELEVATIONS:
            ours = A.sky_radiance(dirs, direction_from_angles(el, 135.0), device=device, steps=steps)
            rel = np.abs(ours - refs[el]) / refs[el]
            errs[el] = (float(rel.mean()), float(rel.max()))
        ms = _median_ms(lambda s=steps: A.bake_sky_map(direction_from_angles(45.0, 135.0), device=device, steps=s),
                        reps)
        sweep.append({"steps": steps, "bake_ms": ms, "mean_rel_error": float(np.mean([e[0] for e in errs.values()])),
                      "worst_rel_error": float(np.max([e[1] for e in errs.values()])),
                      "by_elevation": {str(k): {"mean": v[0], "worst": v[1]} for k, v in errs.items()}})
    return sweep


def sh_accuracy(device):
    out = {}
    normals = fibonacci_sphere(1000)
    below = fibonacci_sphere(100000)
    below = below[below[:, 1] < 0]
    for el in ELEVATIONS:
        m = A.bake_sky_map(direction_from_angles(el, 135.0), device=device).reshape(-1, 3).astype(np.float64)
        d = A.sky_map_directions(256).reshape(-1, 3)
        w = A.sky_map_solid_angles(256).reshape(-1)
        ground = 0.2 / math.pi * A.horizontal_irradiance(m.reshape(256, 256, 3))
        brute = (np.maximum(normals @ d.T, 0) * w) @ m + ground[None] * math.pi * (1 - normals[:, 1:2]) / 2
        lsh = (S.sh_basis(d) * w[:, None]).T @ m
        lsh += (S.sh_basis(below).sum(0) * (2 * math.pi / len(below)))[:, None] * ground
        rel = np.abs(S.eval_irradiance(S.irradiance_coefficients(lsh), normals) - brute) / brute
        out[str(el)] = {"mean": float(rel.mean()), "worst": float(rel.max())}
    return out


def quad_accuracy(vol, probes):
    d = fibonacci_sphere(16384)
    normals = fibonacci_sphere(26)
    sky = vol.sky_map()
    rad = np.where((d[:, 1] >= 0)[:, None], A.sample_sky_map_np(sky, d), vol.ground_radiance[None])
    errs = []
    for p in probes:
        vis = ~occluded_np(p, d, vol.quads)
        brute = (np.maximum(normals @ d.T, 0) * vis) @ rad * (4 * math.pi / len(d))
        errs.append(np.abs(vol.irradiance(np.repeat(p[None], len(normals), 0), normals) - brute) / brute)
    rel = np.concatenate(errs)
    return float(rel.mean()), float(rel.max())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default=None)
    ap.add_argument("--chart", default=None)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="fewer sweep points")
    args = ap.parse_args(argv)
    device = resolve_device(args.device)
    scene = build_scene("courtyard")

    steps_list = (8, 16, 24, 48) if args.quick else (4, 8, 12, 16, 24, 32, 48, 64)
    sweep = skymap_accuracy(device, steps_list, args.reps)
    default = next((s for s in sweep if s["steps"] == A.DEFAULT_STEPS), None)
    bake_ms = _median_ms(lambda: A.bake_sky_map(scene.sun.direction, device=device), args.reps)

    sh = sh_accuracy(device)

    # the paper's per-ray layers (what the volume timings and the rays sweep measure) ...
    cfg = SkyConfig(resolution=PAPER_RESOLUTION, normal_offset=0.0, method="layers")
    vol = SkyVolume(scene, cfg, device=device)
    vol.rebuild()
    pos = vol.probe_positions()
    inside = (np.abs(pos[:, 0]) < 13) & (np.abs(pos[:, 2]) < 13) & (pos[:, 1] > 0.3) & (pos[:, 1] < 9)
    probes = pos[np.random.default_rng(5).choice(np.nonzero(inside)[0], 24, replace=False)]
    sky_map_wp = vol.sky.sky_map_wp
    full_ms = _median_ms(lambda: vol.method.integrate(sky_map_wp, 0, vol.resolution[1]), args.reps)
    layer_ms = _median_ms(lambda: vol.method.integrate(sky_map_wp, 0, 1), args.reps * 3)
    quad_mean, quad_worst = quad_accuracy(vol, probes)

    rays_sweep = []
    for rays in ((32, 128, 512) if args.quick else (16, 32, 64, 128, 256, 512, 1024)):
        v = SkyVolume(scene, SkyConfig(resolution=PAPER_RESOLUTION, normal_offset=0.0, rays_per_probe=rays,
                                       method="layers"), device=device)
        v.rebuild()
        ms = _median_ms(lambda v=v: v.method.integrate(v.sky.sky_map_wp, 0, v.resolution[1]), max(1, args.reps // 2))
        m, w = quad_accuracy(v, probes)
        rays_sweep.append({"rays_per_probe": rays, "full_ms": ms, "mean_rel_error": m, "worst_rel_error": w})

    # ... and the default visibility transfer: its one-off build, the re-lighting of every probe
    # after a sky change, and its accuracy at the same probes
    tv = SkyVolume(scene, SkyConfig(resolution=PAPER_RESOLUTION, normal_offset=0.0), device=device)
    t0 = time.perf_counter()
    tv.rebuild()
    transfer_build_ms = (time.perf_counter() - t0) * 1e3

    def relight():  # after a sky change: the sky's projection, then every probe
        tv.method.projected = None
        tv.method.apply()

    transfer_apply_ms = _median_ms(relight, args.reps)
    transfer_mean, transfer_worst = quad_accuracy(tv, probes)

    # time-of-day lag: layers until a sun step is fully reflected
    lag = SkyVolume(scene, SkyConfig(rays_per_probe=8, resolution=PAPER_RESOLUTION, method="layers"), device=device)
    lag.rebuild()
    el = math.degrees(math.asin(scene.sun.direction[1]))
    new_sun = direction_from_angles(el - 10.0, scene.sun.azimuth_deg)
    frames = 0
    while lag.update(1, sun_direction=new_sun):
        frames += 1

    result = {
        "machine": {"platform": platform.platform(), "python": sys.version.split()[0], "cpu_threads": cpu_threads(),
                    "processor": platform.processor() or platform.machine()},
        "device": device,
        "scene": "courtyard",
        "settings": {"sky_map_size": 256, "sky_steps": A.DEFAULT_STEPS, "volume_resolution": PAPER_RESOLUTION,
                     "rays_per_probe": cfg.rays_per_probe, "quads": len(vol.quads), "window": cfg.window,
                     "ground_albedo": cfg.ground_albedo, "reference_steps": {"view": 256, "sun": 128}},
        "skymap_bake_ms": bake_ms,
        "skymap_mean_rel_error": default["mean_rel_error"] if default else None,
        "skymap_worst_rel_error": default["worst_rel_error"] if default else None,
        "skymap_by_elevation": default["by_elevation"] if default else None,
        "skymap_steps_sweep": sweep,
        "sh_irradiance_mean_rel_error": float(np.mean([v["mean"] for v in sh.values()])),
        "sh_irradiance_by_elevation": sh,
        "quad_irradiance_mean_rel_error": quad_mean,
        "quad_irradiance_worst_rel_error": quad_worst,
        "rays_sweep": rays_sweep,
        "volume_full_ms": full_ms,
        "volume_layer_ms": layer_ms,
        "goal_ratio": full_ms / 1000.0,
        "time_of_day_lag_frames": frames,
        "transfer": {"bands": tv.config.transfer_bands, "build_ms": transfer_build_ms,
                     "relight_all_probes_ms": transfer_apply_ms, "quad_irradiance_mean_rel_error": transfer_mean,
                     "quad_irradiance_worst_rel_error": transfer_worst},
    }
    if args.json:
        write_results(args.json, result)
    print(json.dumps(result, indent=2))
    chart = args.chart or (os.path.splitext(args.json)[0] + ".png" if args.json else None)
    if chart:
        write_chart(result, chart)


def write_chart(result, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    sw = result["skymap_steps_sweep"]
    ms = [s["bake_ms"] for s in sw]
    a.loglog(ms, [s["mean_rel_error"] for s in sw], "o-", label="mean")
    a.loglog(ms, [s["worst_rel_error"] for s in sw], "s--", label="worst")
    for s in sw:
        a.annotate(f"{s['steps']}", (s["bake_ms"], s["mean_rel_error"]), textcoords="offset points", xytext=(4, 4),
                   fontsize=8)
    a.set_xlabel("256² sky map bake, ms (all CPU threads)")
    a.set_ylabel("relative error vs reference")
    a.set_title("Sky map: view-march steps (labels)")
    a.legend()
    a.grid(True, which="both", alpha=0.3)
    rs = result["rays_sweep"]
    b.loglog([r["full_ms"] for r in rs], [r["mean_rel_error"] for r in rs], "o-")
    for r in rs:
        b.annotate(f"{r['rays_per_probe']}", (r["full_ms"], r["mean_rel_error"]), textcoords="offset points",
                   xytext=(4, 4), fontsize=8)
    b.axvline(1000.0, color="gray", ls=":", label="goal: 1 s")
    b.set_xlabel("full 32×16×23 volume, ms (all CPU threads)")
    b.set_ylabel("mean relative irradiance error")
    b.set_title("Sky volume vs brute force: rays per probe (labels)")
    b.legend()
    b.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()

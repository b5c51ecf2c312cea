"""Light propagation volumes: cost on all CPU threads, and error against Mitsuba (paper §8).

    python benchmarks/bench_lpv.py [--json FILE] [--device cpu] [--reps N] [--no-reference] [--quick]

Cost (synthetic workload sized like a frame of the courtyard): a 60×20×60 m scene; 49 152 VPLs
(≈ a 256² sun RSM's covered texels) + 57 600 sky VPLs (a 1280×720 G-buffer at stride 4) and as
many surfels, on random floor/wall planes, camera at head height. Figures are medians over
``--reps`` runs after a warm-up (kernels compiled outside the timed region; the CPU is synchronous).

Error (skipped with ``--no-reference``; Mitsuba references are cached, so re-runs cost only our
frames): the Cornell box's indirect light over a grid of resolution × iterations
(``cornell_indirect``) and the light leaking through the thin-wall scene's wall
(``thin_wall_leak``).

Keys: ``lpv_update_ms`` — inject (VPLs + surfels) + propagate of 3 cascades of 32³ with the default
iterations (8, the coarsest extended to cross the scene: 30 here) = what a frame costs when the
lights changed, at the paper's grid size; ``lpv_update_ms_32_no_cross_scene`` the same with 8
iterations everywhere; ``lpv_update_ms_default`` the default config (12³); ``stages_ms`` the 32³
split; ``per_cascade_ms`` inject/propagate (8 iterations)/lookup of one 32³ cascade alone;
``lookup_ms`` irradiance/glossy lookups at 320×180 points (the Warp twin of the shader);
``sweep`` grid resolution × iterations vs ms; ``cornell_indirect_relmse`` (and ``_trimmed``,
``_flip``) of the default config; ``cornell`` the whole Cornell sweep; ``thin_wall`` the leak table.
Charts and images next to ``--json``: ``<name>.png`` (ms sweep), ``<name>_cornell.png`` (error vs
ms), ``<name>_cornell_images.png`` and ``<name>_thin_wall_images.png`` (what the numbers look like).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np

from serenity.config import LPVConfig
from serenity.device import cpu_threads, resolve_device
from serenity.frame import LPV_UPDATE_STAGES
from serenity.io.results import write_results
from serenity.kernels.lpv import LightPropagationVolume

BOUNDS = np.array([[-30.0, 0.0, -30.0], [30.0, 20.0, 30.0]])
CAMERA = (np.array([0.0, 1.7, -12.0]), np.array([0.0, -0.1, 1.0]))


def _surfaces(rng, n):
    """n points on random axis-aligned planes of the scene (floor, walls), with their normals."""
    p = rng.uniform(BOUNDS[0], BOUNDS[1], (n, 3))
    axis = rng.integers(0, 3, n)
    nrm = np.zeros((n, 3))
    nrm[np.arange(n), axis] = rng.choice([-1.0, 1.0], n)
    floor = rng.random(n) < 0.4
    p[floor, 1] = 0.0
    nrm[floor] = (0.0, 1.0, 0.0)
    return p.astype(np.float32), nrm.astype(np.float32)


def workload(seed=0):
    rng = np.random.default_rng(seed)
    sets = []
    for n, flux in ((49_152, 0.05), (57_600, 0.02)):
        p, nrm = _surfaces(rng, n)
        sets.append((p, nrm, rng.uniform(0.2, 1.0, (n, 3)).astype(np.float32) * flux))
    p, nrm = _surfaces(rng, 57_600)
    surfels = [(p, nrm, np.full(len(p), 0.04, np.float32))]
    return sets, surfels


def time_update(cfg, device, sets, surfels, reps):
    """Median ms of clear + inject + inject_geometry + propagate, and the median stage split."""
    v = LightPropagationVolume(cfg, device=device)
    v.fit(CAMERA, BOUNDS)
    rows = []
    for k in range(reps + 1):
        t0 = time.perf_counter()
        v.clear()
        t1 = time.perf_counter()
        for s in sets:
            v.inject(*s)
        t2 = time.perf_counter()
        for s in surfels:
            v.inject_geometry(*s)
        t3 = time.perf_counter()
        v.propagate()
        t4 = time.perf_counter()
        if k:  # the first run compiles and warms up
            rows.append((t4 - t0, t1 - t0, t2 - t1, t3 - t2, t4 - t3))
    med = np.median(np.array(rows), axis=0) * 1e3
    split = dict(zip(("total", "clear", "inject", "inject_geometry", "propagate"), (float(x) for x in med),
                     strict=True))
    return v, split


def time_lookups(v, reps, n=320 * 180, seed=1):
    rng = np.random.default_rng(seed)
    p, nrm = _surfaces(rng, n)
    r = rng.normal(size=(n, 3)).astype(np.float32)
    out = {}
    for name, fn in (("irradiance", lambda: v.irradiance(p, nrm)), ("glossy", lambda: v.glossy(p, r, 32.0))):
        fn()
        ts = []
        for _ in range(reps):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
        out[name] = float(np.median(ts) * 1e3)
    return out


CORNELL_SIZE = (160, 90)
CORNELL_SPP = 4096
"""Reference samples per pixel (two halves of different seeds). The Cornell box is lit through a
13 × 10 cm hole, so its indirect light comes from one small patch: even at 4096 spp the reference's
own noise is relMSE ≈ 0.04 (printed and stored as ``reference_noise_rel_mse``), a floor under every
relMSE figure of the sweep."""
CORNELL_GRID = ((8, 16), (12, 12), (16, 4), (16, 8), (16, 16), (16, 32), (24, 8), (24, 24), (32, 8), (32, 16),
                (32, 32))
"""(resolution, iterations) pairs of the Cornell sweep (3 cascades; the scene-fitted placement decides
how many are active)."""


def cornell_reference(width, height, spp):
    """The Cornell box's indirect light (Mitsuba full − direct-only), two halves of spp/2 averaged;
    returns (scene, reference, noise) with noise the relMSE the average owes to its own variance."""
    from serenity.eval.metrics import REL_MSE_EPS
    from serenity.eval.reference import render_reference
    from serenity.scene import load

    scene = load("cornell")
    half = max(1, spp // 2)
    a = render_reference(scene, width, height, spp=half, component="indirect", seed=0)
    b = render_reference(scene, width, height, spp=half, component="indirect", seed=1)
    ref = (a + b) / 2
    noise = float(np.mean((a - b) ** 2 / 4 / (ref * ref + REL_MSE_EPS)))
    return scene, ref, noise


def cornell_indirect(grid=CORNELL_GRID, size=CORNELL_SIZE, spp=CORNELL_SPP, reps=3, default=None):
    """Cornell box, indirect light only: ours = frame(LPV on) − frame(LPV off) (the LPV pass is purely
    additive), the reference = Mitsuba full − direct. For each (resolution, iterations) and the default
    config: relMSE (all pixels, and without the worst 0.1 %), FLIP at an exposure putting the
    reference's mean luminance at 0.18, the frame's "lpv update" and "lpv lighting" ms (medians of
    ``reps`` forced re-updates). Row "LPV off" (ours = 0) is the error to beat."""
    from serenity.config import RenderConfig
    from serenity.eval.metrics import compare, rel_mse
    from serenity.frame import Renderer

    width, height = size
    scene, ref, noise = cornell_reference(width, height, spp)
    print(f"cornell indirect reference {width}x{height}, {spp} spp: mean {ref.reshape(-1, 3).mean(0).round(3)}, "
          f"own noise relMSE {noise:.4f}", flush=True)
    exposure = 0.18 / max(float(ref.mean()), 1e-9)
    base = Renderer(scene, width, height, config=RenderConfig(lpv=LPVConfig(enabled=False))).render().hdr

    def row(label, ours, extra):
        m = compare(ours, ref, exposure=exposure)
        r = {"config": label, **extra, "rel_mse": m["rel_mse"], "rel_mse_trimmed": rel_mse(ours, ref, trim=1e-3),
             "flip": m["flip"], "mean_ours": ours.reshape(-1, 3).mean(0).tolist()}
        print(f"  {label:<24} {extra.get('update_ms', 0):7.1f} ms  relMSE {r['rel_mse']:8.3f} "
              f"(trimmed {r['rel_mse_trimmed']:7.3f})  FLIP {r['flip']:.3f}", flush=True)
        return r

    rows = [row("LPV off", np.zeros_like(ref), {"resolution": 0, "iterations": 0, "update_ms": 0.0})]
    images = {"reference (Mitsuba full - direct)": ref}
    configs = [(f"{res}^3 x {it} it", LPVConfig(resolution=res, iterations=it)) for res, it in grid]
    configs.append(("default", default or LPVConfig()))
    for label, cfg in configs:
        r = Renderer(scene, width, height, config=RenderConfig(lpv=cfg))
        ours = r.render().hdr - base
        upd, lit = [], []
        for _ in range(reps):
            r.invalidate_lpv()
            f = r.render()
            upd.append(sum(f.timings.get(k, 0.0) for k in LPV_UPDATE_STAGES))
            lit.append(f.timings.get("lpv lighting", 0.0))
        extra = {"resolution": cfg.resolution, "iterations": cfg.iterations,
                 "cascades_active": len(r.lpv.grids), "cell_m": [g.cell_size for g in r.lpv.grids],
                 "iterations_run": r.lpv.iterations_run,
                 "update_ms": float(np.median(upd)), "lighting_ms": float(np.median(lit))}
        rows.append(row(label, ours, extra))
        if label in ("default", f"{CORNELL_GRID[0][0]}^3 x {CORNELL_GRID[0][1]} it", "32^3 x 8 it"):
            images[label] = ours
    return {"size": list(size), "reference_spp": spp, "reference_noise_rel_mse": noise, "flip_exposure": exposure,
            "rows": rows, "images": images}


def cornell_chart(result, path):
    """Error vs ms of the Cornell sweep: one line per resolution through its iteration counts."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in result["rows"] if r["config"] not in ("LPV off", "default")]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, key, name in ((axes[0], "rel_mse_trimmed", "relMSE (worst 0.1% px left out)"), (axes[1], "flip", "FLIP")):
        for res in sorted({r["resolution"] for r in rows}):
            pts = sorted((r["update_ms"], r[key], r["iterations"]) for r in rows if r["resolution"] == res)
            ax.plot([p[0] for p in pts], [p[1] for p in pts], marker="o", label=f"{res}³")
            for x, y, it in pts:
                ax.annotate(f"{it}", (x, y), textcoords="offset points", xytext=(3, 3), fontsize=7)
        off = next(r for r in result["rows"] if r["config"] == "LPV off")
        ax.axhline(off[key], color="grey", linestyle="--", linewidth=1, label="LPV off")
        d = next((r for r in result["rows"] if r["config"] == "default"), None)
        if d:
            ax.plot([d["update_ms"]], [d[key]], marker="*", markersize=14, color="k", linestyle="none",
                    label="default")
        ax.set_xlabel("LPV update ms (frame stage; labels = iterations)")
        ax.set_ylabel(name)
        ax.set_yscale("log")
        ax.legend(fontsize=8)
    w, h = result["size"]
    fig.suptitle(f"Cornell box, indirect light only vs Mitsuba (full − direct), {w}x{h}, "
                 f"{cpu_threads()} CPU threads")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


THIN_WALL_SIZE = (160, 90)
THIN_WALL_SPP = 1024
THIN_WALL_CONFIGS = {
    "plain": {"geometry_volume": False, "leak_guard": False},
    "geometry volume": {"geometry_volume": True, "leak_guard": False},
    "leak guard": {"geometry_volume": False, "leak_guard": True},
    "geometry volume + leak guard": {"geometry_volume": True, "leak_guard": True},
}


def thin_wall_leak(size=THIN_WALL_SIZE, spp=THIN_WALL_SPP, configs=THIN_WALL_CONFIGS):
    """Light leaking through the ``thin-wall`` scene's 5 cm wall (a fifth of a finest cell): the camera
    sees the wall's shaded north face; the sun lights its south face. On the north-face pixels, the
    LPV's contribution (frame(LPV) − frame(no LPV)) against Mitsuba's indirect light there (full −
    direct: only light bounced off the ground in front, nothing comes through the wall). ``excess`` =
    ours − reference, over the reference; the same on the ground in front of the wall (legitimate
    bounce light the mitigations must not kill)."""
    from serenity.config import RenderConfig
    from serenity.eval.reference import render_reference
    from serenity.frame import Renderer
    from serenity.scene import load

    width, height = size
    scene = load("thin-wall")
    half = max(1, spp // 2)
    ref = (render_reference(scene, width, height, spp=half, component="indirect", seed=0)
           + render_reference(scene, width, height, spp=half, component="indirect", seed=1)) / 2
    base = Renderer(scene, width, height, config=RenderConfig(lpv=LPVConfig(enabled=False))).render()
    nrm, pos = base.aovs["normal"], base.aovs["position"]
    dark = (nrm[..., 2] < -0.9) & (np.abs(pos[..., 2]) < 0.1)
    ground = (nrm[..., 1] > 0.9) & (pos[..., 2] < -0.5) & (pos[..., 2] > -4.0) & (np.abs(pos[..., 0]) < 5.0)
    lum = np.array([0.2126, 0.7152, 0.0722], np.float32)
    rows = []
    images = {"reference (Mitsuba full - direct)": ref}
    print(f"thin wall: {int(dark.sum())} north-face px, {int(ground.sum())} ground px; reference {spp} spp",
          flush=True)
    for label, kw in configs.items():
        ours = Renderer(scene, width, height, config=RenderConfig(lpv=LPVConfig(**kw))).render().hdr
        ours = ours - base.hdr
        images[label] = ours
        row = {"config": label, **kw}
        for region, m in (("north_face", dark), ("ground", ground)):
            o, r = float((ours[m] @ lum).mean()), float((ref[m] @ lum).mean())
            row[region] = {"ours": o, "reference": r, "excess": (o - r) / max(r, 1e-9)}
        rows.append(row)
        print(f"  {label:<30} north face ours {row['north_face']['ours']:.3f} vs ref "
              f"{row['north_face']['reference']:.3f} (excess {row['north_face']['excess']:+.2f}); ground "
              f"{row['ground']['ours']:.3f} vs {row['ground']['reference']:.3f}", flush=True)
    exposure = 0.18 / max(float((ref[ground | dark] @ lum).mean()), 1e-9)
    return {"size": list(size), "reference_spp": spp, "luminance": "Rec.709 Y of linear radiance (W m^-2 sr^-1)",
            "rows": rows, "images": images, "flip_exposure": exposure}


def image_strip(images: dict, exposure: float, path: str) -> None:
    """The labelled images side by side (exposure, Reinhard, sRGB: the renderer's tone map), as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from serenity.eval.metrics import tonemap

    n = len(images)
    h, w = next(iter(images.values())).shape[:2]
    fig, axes = plt.subplots(1, n, figsize=(2.6 * n, 2.6 * h / w + 0.5))
    for ax, (label, img) in zip(np.atleast_1d(axes), images.items(), strict=True):
        ax.imshow(tonemap(np.maximum(img, 0.0), exposure))
        ax.set_title(label, fontsize=8)
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def chart(sweep, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for res in sorted({s["resolution"] for s in sweep}):
        pts = [(s["iterations"], s["update_ms"]) for s in sweep if s["resolution"] == res]
        ax.plot(*zip(*pts, strict=True), marker="o", label=f"{res}³ × 3 cascades")
    ax.axhline(30.0, color="grey", linestyle="--", linewidth=1, label="goal 30 ms")
    ax.set_xlabel("propagation iterations")
    ax.set_ylabel("LPV update (inject + propagate), ms")
    ax.set_title(f"LPV update on {cpu_threads()} CPU threads")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", help="write the figures here (charts and images next to it)")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--no-reference", action="store_true", help="cost only (no Mitsuba, no frames)")
    ap.add_argument("--quick", action="store_true", help="small sweeps (smoke test)")
    args = ap.parse_args(argv)
    device = resolve_device(args.device)
    sets, surfels = workload()
    paper = LPVConfig(resolution=32)
    v, split = time_update(paper, device, sets, surfels, args.reps)
    _, split_default = time_update(LPVConfig(), device, sets, surfels, args.reps)
    one_v, one = time_update(LPVConfig(resolution=32, cascades=1, view_distance=8.0, cross_scene=False), device,
                             sets, surfels, args.reps)
    _, split_plain = time_update(LPVConfig(resolution=32, cross_scene=False), device, sets, surfels, args.reps)
    per_cascade = {"inject_ms": one["inject"] + one["inject_geometry"], "propagate_ms": one["propagate"],
                   "lookup_irradiance_ms": time_lookups(one_v, args.reps)["irradiance"]}
    result = {
        "machine": {"platform": platform.platform(), "python": sys.version.split()[0], "cpu_threads": cpu_threads(),
                    "processor": platform.processor()},
        "device": device,
        "scene": "synthetic 60x20x60 m, 49152 RSM + 57600 sky VPLs, 57600 surfels",
        "settings": {k: getattr(paper, k) for k in ("resolution", "cascades", "iterations", "cross_scene", "handover",
                                                    "early_stop", "geometry_volume", "leak_guard", "glossy_steps")},
        "cascades_fitted": [{"level": g.level, "cell_m": g.cell_size} for g in v.fitted],
        "iterations_run": v.iterations_run,
        "lpv_update_ms": split["total"],
        "lpv_update_ms_default": split_default["total"],
        "lpv_update_ms_32_no_cross_scene": split_plain["total"],
        "stages_ms": split,
        "per_cascade_ms": per_cascade,
        "lookup_ms": time_lookups(v, args.reps),
    }
    sweep = []
    for res in ((16, 32) if args.quick else (8, 16, 24, 32)):
        for iters in ((4, 8) if args.quick else (2, 4, 8, 12, 16)):
            cfg = LPVConfig(resolution=res, iterations=iters, early_stop=0.0, cross_scene=False)
            _, st = time_update(cfg, device, sets, surfels, max(3, args.reps // 2))
            sweep.append({"resolution": res, "iterations": iters, "update_ms": st["total"],
                          "propagate_ms": st["propagate"]})
    result["sweep"] = sweep
    print(f"lpv_update_ms (3 x 32^3) {split['total']:.1f}, default (3 x 16^3) {split_default['total']:.1f}",
          flush=True)
    cornell = thin = None
    if not args.no_reference:
        grid = ((8, 16), (16, 8)) if args.quick else CORNELL_GRID
        cornell = cornell_indirect(grid=grid, reps=1 if args.quick else 3)
        d = next(r for r in cornell["rows"] if r["config"] == "default")
        result.update({"cornell_indirect_relmse": d["rel_mse"], "cornell_indirect_relmse_trimmed": d["rel_mse_trimmed"],
                       "cornell_indirect_flip": d["flip"]})
        thin = thin_wall_leak()
        result["cornell"] = {k: v for k, v in cornell.items() if k != "images"}
        result["thin_wall"] = {k: v for k, v in thin.items() if k != "images"}
    else:
        result["cornell_indirect_relmse"] = None  # not measured in this run (--no-reference)
    print(json.dumps(result, indent=2))
    if args.json:
        write_results(args.json, result)
        stem = os.path.splitext(args.json)[0]
        chart(sweep, stem + ".png")
        if cornell is not None:
            cornell_chart(cornell, stem + "_cornell.png")
            image_strip(cornell["images"], cornell["flip_exposure"], stem + "_cornell_images.png")
            image_strip(thin["images"], thin["flip_exposure"], stem + "_thin_wall_images.png")
        print(f"wrote {args.json} and its charts")


if __name__ == "__main__":
    main()

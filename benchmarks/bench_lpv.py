"""Light propagation volume cost on all CPU threads (paper §8; issue #6).

    python benchmarks/bench_lpv.py [--json FILE] [--chart FILE.png] [--device cpu] [--reps N]

Workload (synthetic, sized like a frame of the courtyard): a 60×20×60 m scene; 49 152 VPLs
(≈ a 256² sun RSM's covered texels) + 57 600 sky VPLs (a 1280×720 G-buffer at stride 4) and as
many surfels, on random floor/wall planes, camera at head height. Figures are medians over
``--reps`` runs after a warm-up (kernels compiled outside the timed region; the CPU is synchronous).

Keys: ``lpv_update_ms`` — inject (VPLs + surfels) + propagate of the default config (3 cascades,
32³, 8 iterations, early stop 0.01, geometry volume) = what a frame costs when the lights changed;
``stages_ms`` its split; ``per_cascade_ms`` inject/propagate/lookup of one 32³ cascade alone;
``lookup_ms`` irradiance/glossy lookups at 320×180 points (the Warp reference of the shader);
``sweep`` grid resolution × iterations vs ms (the chart). ``cornell_indirect_relmse`` is null: see
the TODO below.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np

from serenity.device import cpu_threads, resolve_device
from serenity.kernels.lpv import LightPropagationVolume, LPVConfig

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


def cornell_indirect_relmse():
    """TODO(#6, #3): relative MSE of the LPV's indirect light in the Cornell box against Mitsuba's
    (full − direct-only). Needs the LPV wired into the deferred pass (frame.py, owned by the lead)
    and the reference harness in serenity/eval/; until both exist this returns None — never a
    made-up number."""
    return None


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
    ap.add_argument("--json", help="write the figures here")
    ap.add_argument("--chart", help="PNG of grid resolution × iterations vs ms (default: next to --json)")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--quick", action="store_true", help="small sweep (CI smoke)")
    args = ap.parse_args(argv)
    device = resolve_device(args.device)
    sets, surfels = workload()
    default = LPVConfig()
    v, split = time_update(default, device, sets, surfels, args.reps)
    per_cascade = {}
    one_v, one = time_update(LPVConfig(cascades=1, view_distance=8.0), device, sets, surfels, args.reps)
    per_cascade = {"inject_ms": one["inject"] + one["inject_geometry"], "propagate_ms": one["propagate"],
                   "lookup_irradiance_ms": time_lookups(one_v, args.reps)["irradiance"]}
    result = {
        "machine": {"platform": platform.platform(), "python": sys.version.split()[0], "cpu_threads": cpu_threads(),
                    "processor": platform.processor()},
        "device": device,
        "scene": "synthetic 60x20x60 m, 49152 RSM + 57600 sky VPLs, 57600 surfels",
        "settings": {k: getattr(default, k) for k in ("resolution", "cascades", "iterations", "early_stop",
                                                      "geometry_volume", "leak_guard", "glossy_steps")},
        "cascades_fitted": [{"level": g.level, "cell_m": g.cell_size} for g in v.fitted],
        "iterations_run": v.iterations_run,
        "lpv_update_ms": split["total"],
        "stages_ms": split,
        "per_cascade_ms": per_cascade,
        "lookup_ms": time_lookups(v, args.reps),
        "cornell_indirect_relmse": cornell_indirect_relmse(),
    }
    sweep = []
    for res in ((16, 32) if args.quick else (16, 24, 32, 48)):
        for iters in ((4, 8) if args.quick else (2, 4, 8, 12, 16)):
            cfg = LPVConfig(resolution=res, iterations=iters, early_stop=0.0)
            _, s = time_update(cfg, device, sets, surfels, max(3, args.reps // 2))
            sweep.append({"resolution": res, "iterations": iters, "update_ms": s["total"],
                          "propagate_ms": s["propagate"]})
    result["sweep"] = sweep
    text = json.dumps(result, indent=2)
    print(text)
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, "w") as f:
            f.write(text + "\n")
    path = args.chart or (os.path.splitext(args.json)[0] + ".png" if args.json else None)
    if path:
        chart(sweep, path)


if __name__ == "__main__":
    main()

"""LPV in a closed room and outdoors: each propagation/placement change measured against Mitsuba.

    python benchmarks/bench_lpv_room.py [--json FILE] [--quick]

For each LPV setting (``VARIANTS``: the paper's transfer with view-fitted cells, each closed-room
change alone — ``clamp_faces``, ``lookup_occlusion``, ``scene_cells`` — all three, all three with
``lookup_planes`` but without the self-illumination damping ("undamped"), near-field and
coverage-blocking alternatives, and the default, which adds the damping):

- ``cornell_indirect``: the Cornell box's indirect light alone at 160×90 (ours = frame with the LPV −
  frame without it; the reference = Mitsuba full − direct, 4096 spp, cached — the same as
  ``bench_lpv.py``'s Cornell sweep): relMSE, relMSE without the worst 0.1 % of pixels, FLIP at the
  exposure that puts the reference's mean at 0.18, and per region (``serenity.eval.regions``) the
  luminance ratio ours/reference — ``down-facing`` is the ceiling; plus ``top1pct_share``, the share
  of the relMSE sum in the worst 1 % of pixels (where the error sits);
- ``courtyard``: the full frame at 320×180 against the full reference (256 spp, cached, as
  ``bench_baseline.py``): FLIP, relMSE and the region luminance ratios;
- ``open_ground``: the ``plane`` scene (flat lit ground, black sky: exact indirect 0) at 320×180, the
  plane's luminance ours/reference (the bar: within 5 %);
- ``plane_self_illumination``: E_self/M of a lit plane (the kernel test's set-up: one 16³ cascade
  of 1 m cells, 8 iterations, plane heights 3.01/3.3/3.6/3.9 m, with its surfels in the geometry
  volume as in a frame); exact 0;
- ``thin_wall``: the worst E_dark/E_lit of the stability suite's thin wall (exact 0);
- ``synthetic_cost``: CPU-ms of one update on ``bench_lpv.py``'s synthetic workload, before / face
  clamp / default, interleaved (``--cost-only`` re-measures just this into an existing JSON);
- ``lpv_update_ms``: the frame's LPV update (Σ ``frame.LPV_UPDATE_STAGES``) in the courtyard at 320×180,
  median of 3 forced re-updates (wall time on a shared machine: compare within a run);
  ``lpv_inject_propagate_cpu_ms``: the stages this change touches ("lpv inject" + "lpv propagate"),
  as process CPU time (the clock ``tools/profile_frame.py`` uses; robust to a busy machine, summed
  over the worker threads), median of 3 more; ``lpv_lighting_cpu_ms`` the "lpv lighting" GL pass
  the same way (llvmpipe renders on the calling thread: ``LP_NUM_THREADS=0``, set by this script).

The LPV row "off" is the error to beat. ``--quick`` skips the courtyard; ``--only LABEL`` measures only the
settings whose label contains LABEL and merges them into the existing JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

os.environ.setdefault("LP_NUM_THREADS", "0")  # llvmpipe on the calling thread: GL passes in process CPU time

import numpy as np  # noqa: E402

from serenity.config import LPVConfig, RenderConfig  # noqa: E402
from serenity.eval.metrics import compare, rel_mse  # noqa: E402
from serenity.eval.reference import render_reference  # noqa: E402
from serenity.eval.regions import region_report  # noqa: E402
from serenity.frame import LPV_UPDATE_STAGES, Renderer  # noqa: E402
from serenity.io.results import write_results  # noqa: E402
from serenity.kernels.lpv import LightPropagationVolume  # noqa: E402
from serenity.scene import load  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
WALL = time.perf_counter
BEFORE = {"clamp_faces": False, "lookup_occlusion": False, "scene_cells": 0.0, "lookup_planes": False,
          "self_damping": 0.0}
#: undamped: every closed-room change but the self-illumination damping
UNDAMPED = {"self_damping": 0.0}
VARIANTS = {
    "before (paper transfer, view-fitted cells)": BEFORE,
    "face clamp": {**BEFORE, "clamp_faces": True},
    "lookup occlusion": {**BEFORE, "lookup_occlusion": True},
    "scene-fitted coarsest cascade (6 cells)": {**BEFORE, "scene_cells": 6.0},
    "all three": {**UNDAMPED, "lookup_planes": False},
    "all three + lookup planes (undamped)": UNDAMPED,
    "undamped, scene-fitted 8 cells": {**UNDAMPED, "scene_cells": 8.0},
    "undamped + lookups without the injected lobes": {**UNDAMPED, "accumulate_injected": False},
    "undamped + injection offset 1 cell": {**UNDAMPED, "injection_offset": 1.0},
    "undamped + injection offset 0.75 cell": {**UNDAMPED, "injection_offset": 0.75},
    "undamped + coverage blocking": {**UNDAMPED, "coverage_blocking": True},
    "+ self-illumination damping (1.5 cells, power 2)": {"self_damping": 1.5, "self_damping_power": 2.0},
    "+ self-illumination damping (2 cells, power 2)": {"self_damping": 2.0, "self_damping_power": 2.0},
    "**default (+ self-illumination damping, 2.5 cells, power 2)**": {},
    "default + coverage blocking": {"coverage_blocking": True},
    "default + coverage blocking, coarsest cascade 24 iterations": {"coverage_blocking": True,
                                                                    "iterations": (8, 24, 24)},
}

COST_VARIANTS = {k: VARIANTS[k] for k in ("before (paper transfer, view-fitted cells)", "face clamp",
                                          "all three + lookup planes (undamped)",
                                          "**default (+ self-illumination damping, 2.5 cells, power 2)**")}


def _reference(scene, w, h, spp, component):
    a = render_reference(scene, w, h, spp=spp // 2, component=component, seed=0)
    b = render_reference(scene, w, h, spp=spp // 2, component=component, seed=1)
    return (a + b) / 2


def _regions(img, ref, frame, scene, exposure, fmap):
    rep = region_report(img, ref, frame.aovs["normal"], frame.aovs["depth"], frame.aovs["material"],
                        [m.name for m in scene.materials], exposure=exposure, fmap=fmap)
    return {k: v["luminance_ratio"] for k, v in rep["regions"].items()}


def _top_share(ours, ref, frac=0.01):
    e = np.mean((ours - ref) ** 2 / (ref * ref + 1e-2), axis=-1).ravel()
    k = max(1, int(frac * e.size))
    return float(np.sort(e)[::-1][:k].sum() / max(e.sum(), 1e-30))


def cornell_indirect(variants):
    scene = load("cornell")
    w, h = 160, 90
    ref = _reference(scene, w, h, 4096, "indirect")
    exposure = 0.18 / max(float(ref.mean()), 1e-9)
    base = Renderer(scene, w, h, config=RenderConfig(lpv=LPVConfig(enabled=False))).render()
    m = compare(np.zeros_like(ref), ref, exposure=exposure)
    rows = [{"config": "off", "rel_mse": m["rel_mse"], "rel_mse_trimmed": rel_mse(np.zeros_like(ref), ref, trim=1e-3),
             "flip": m["flip"]}]
    for label, kw in variants.items():
        r = Renderer(scene, w, h, config=RenderConfig(lpv=LPVConfig(**kw)))
        f = r.render()
        ours = f.hdr - base.hdr
        m = compare(ours, ref, exposure=exposure)
        rows.append({"config": label, "lpv": kw, "rel_mse": m["rel_mse"],
                     "rel_mse_trimmed": rel_mse(ours, ref, trim=1e-3), "flip": m["flip"],
                     "top1pct_share": _top_share(ours, ref),
                     "cell_m": [g.cell_size for g in r.lpv.grids], "iterations_run": r.lpv.iterations_run,
                     "luminance_ratio": _regions(ours, ref, f, scene, exposure, m["flip_map"])})
        print(f"cornell indirect  {label:<48} relMSE {m['rel_mse']:7.3f} (trimmed {rows[-1]['rel_mse_trimmed']:6.3f})"
              f"  FLIP {m['flip']:.3f}  ceiling {rows[-1]['luminance_ratio']['down-facing']}", flush=True)
    return {"size": [w, h], "reference_spp": 4096, "flip_exposure": exposure, "rows": rows}


def courtyard(variants):
    scene = load("courtyard")
    w, h = 320, 180
    ref = _reference(scene, w, h, 256, "full")
    rows = []
    for label, kw in variants.items():
        r = Renderer(scene, w, h, config=RenderConfig(lpv=LPVConfig(**kw)))
        f = r.render()
        m = compare(f.hdr, ref, exposure=f.exposure)
        upd, cpu, light = [], [], []
        for _ in range(3):
            r.invalidate_lpv()
            upd.append(sum(r.render().timings.get(k, 0.0) for k in LPV_UPDATE_STAGES))
        time.perf_counter = time.process_time  # the stages' clock: CPU seconds (tools/profile_frame.py)
        try:
            for _ in range(3):
                r.invalidate_lpv()
                t = r.render().timings
                cpu.append(sum(t.get(k, 0.0) for k in ("lpv inject", "lpv propagate")))
                light.append(t.get("lpv lighting", 0.0))
        finally:
            time.perf_counter = WALL
        rows.append({"config": label, "lpv": kw, "rel_mse": m["rel_mse"],
                     "rel_mse_trimmed": rel_mse(f.hdr, ref, trim=1e-3), "flip": m["flip"],
                     "lpv_update_ms": float(np.median(upd)), "lpv_inject_propagate_cpu_ms": float(np.median(cpu)),
                     "lpv_lighting_cpu_ms": float(np.median(light)),
                     "cell_m": [g.cell_size for g in r.lpv.grids],
                     "luminance_ratio": _regions(f.hdr, ref, f, scene, f.exposure, m["flip_map"])})
        lr = rows[-1]["luminance_ratio"]
        print(f"courtyard         {label:<48} relMSE {m['rel_mse']:.4f}  FLIP {m['flip']:.4f}  down-facing "
              f"{lr['down-facing']:.3f}  vertical {lr['vertical']:.3f}  up {lr['up-facing']:.3f}  "
              f"update {rows[-1]['lpv_update_ms']:.1f} ms, inject + propagate "
              f"{rows[-1]['lpv_inject_propagate_cpu_ms']:.1f} CPU-ms, lighting {rows[-1]['lpv_lighting_cpu_ms']:.1f} "
              f"CPU-ms", flush=True)
    return {"size": [w, h], "reference_spp": 256, "rows": rows}


def open_ground(variants):
    """The ``plane`` scene (one diffuse plane, sun at 60°, black sky: the exact indirect light is 0),
    320×180 against Mitsuba (256 spp, cached): luminance ratio ours/reference on the plane — what the
    plane's light on itself adds — for LPV off and each setting."""
    scene = load("plane")
    w, h = 320, 180
    ref = _reference(scene, w, h, 256, "full")
    out = {}
    for label, kw in {"off": None, **variants}.items():
        lpv = LPVConfig(enabled=False) if kw is None else LPVConfig(**kw)
        f = Renderer(scene, w, h, config=RenderConfig(lpv=lpv)).render()
        m = compare(f.hdr, ref, exposure=f.exposure)
        out[label] = {"luminance_ratio": _regions(f.hdr, ref, f, scene, f.exposure, m["flip_map"])["up-facing"],
                      "flip": m["flip"], "rel_mse": m["rel_mse"]}
        print(f"open ground       {label:<48} plane luminance ours/ref {out[label]['luminance_ratio']:.3f}", flush=True)
    return out


def _unit_settings(kw: dict) -> dict:
    """A variant's settings for the one-cascade test LPVs (plane, thin wall), which fix their own
    iteration count: per-cascade ``iterations`` do not apply there (and would clash with it)."""
    return {k: v for k, v in kw.items() if k != "iterations"}


def plane_self_illumination(variants):
    """``serenity.eval.stability.lpv_self_illumination`` (a lit plane, its surfels in the geometry
    volume, 1 m cells, 8 iterations) at four heights within a cell, per variant."""
    from serenity.eval.stability import lpv_self_illumination

    out = {}
    for label, kw in variants.items():
        kw = _unit_settings(kw)
        out[label] = ratios = [lpv_self_illumination(y0, device="cpu", surfels=True, **kw)
                               for y0 in (3.01, 3.3, 3.6, 3.9)]
        print(f"plane E_self/M    {label:<48} {np.round(ratios, 3).tolist()}", flush=True)
    return out


def thin_wall(variants):
    """``serenity.eval.stability.lpv_thin_wall`` (a 5 cm two-sided wall lit on one side, 1 m cells, the
    wall at 5 positions across a cell) per setting: the worst E_dark/E_lit (exact 0) — the figure of
    ``tests/stability/test_lpv.py`` and bench_stability's LPV thin-wall case."""
    from serenity.eval.stability import lpv_thin_wall

    out = {}
    for label, kw in variants.items():
        kw = _unit_settings(kw)
        r = [lpv_thin_wall(f, True, True, **kw) for f in (0.1, 0.3, 0.5, 0.7, 0.9)]
        out[label] = [d / lit for d, lit in r]
        print(f"thin wall E_d/E_l {label:<48} worst {max(out[label]):.4f}", flush=True)
    return out


def synthetic_cost(variants, reps=7):
    """CPU-ms (process time, summed over the worker threads) of one LPV update — clear, inject,
    inject_geometry, propagate — on ``bench_lpv.py``'s synthetic courtyard-sized workload (107 k VPLs,
    58 k surfels, the default 3 cascades), median of ``reps`` after a warm-up, per setting; the settings
    interleaved round by round so a load change hits them alike."""
    from bench_lpv import BOUNDS, CAMERA, workload

    sets, surfels = workload()
    vols = {}
    for label, kw in variants.items():
        v = LightPropagationVolume(LPVConfig(**kw), device="cpu")
        v.fit(CAMERA, BOUNDS)
        vols[label] = v
    rows = {label: {"total": [], "propagate": []} for label in variants}
    for k in range(reps + 1):
        for label, v in vols.items():
            t0 = time.process_time()
            v.clear()
            for st in sets:
                v.inject(*st)
            for st in surfels:
                v.inject_geometry(*st)
            t1 = time.process_time()
            v.propagate()
            t2 = time.process_time()
            if k:
                rows[label]["total"].append((t2 - t0) * 1e3)
                rows[label]["propagate"].append((t2 - t1) * 1e3)
    out = {label: {"update_cpu_ms": float(np.median(r["total"])), "propagate_cpu_ms": float(np.median(r["propagate"])),
                   "iterations_run": vols[label].iterations_run} for label, r in rows.items()}
    for label, r in out.items():
        print(f"synthetic update  {label:<48} {r['update_cpu_ms']:7.1f} CPU-ms "
              f"(propagate {r['propagate_cpu_ms']:.1f}), "
              f"iterations {r['iterations_run']}", flush=True)
    return out


def _merge(out: dict, key: str, new) -> None:
    """Merge one section's results for some settings into ``out[key]`` (rows replaced by label)."""
    old = out.setdefault(key, {})
    if "rows" in new:
        rows = {r["config"]: r for r in old.get("rows", [])}
        rows.update({r["config"]: r for r in new["rows"]})
        out[key] = {**old, **{k: v for k, v in new.items() if k != "rows"}, "rows": list(rows.values())}
    else:
        old.update(new)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", default=os.path.join(HERE, "results", "lpv_room.json"))
    ap.add_argument("--quick", action="store_true", help="skip the courtyard")
    ap.add_argument("--cost-only", action="store_true",
                    help="only the synthetic CPU-ms, merged into an existing --json")
    ap.add_argument("--only", action="append", default=[], metavar="LABEL",
                    help="measure only this setting of VARIANTS (repeatable; a substring of its label) and merge "
                         "its rows into an existing --json (the Cornell 'off' row is re-measured too)")
    args = ap.parse_args(argv)
    if args.only:
        picked = {k: v for k, v in VARIANTS.items() if any(o in k for o in args.only)}
        if not picked:
            ap.error(f"no setting matches {args.only}")
        with open(args.json) as fh:
            out = json.load(fh)
        _merge(out, "plane_self_illumination", plane_self_illumination(picked))
        _merge(out, "thin_wall", thin_wall(picked))
        _merge(out, "cornell_indirect", cornell_indirect(picked))
        _merge(out, "open_ground", open_ground(picked))
        if not args.quick:
            _merge(out, "courtyard", courtyard(picked))
        write_results(args.json, out)
        return 0
    if args.cost_only:
        with open(args.json) as fh:
            out = json.load(fh)
        out["synthetic_cost"] = synthetic_cost(COST_VARIANTS)
        write_results(args.json, out)
        return 0
    keys = ("clamp_faces", "lookup_occlusion", "lookup_planes", "coverage_blocking", "scene_cells",
            "accumulate_injected", "injection_offset")
    out = {"benchmark": "lpv_room", "default_lpv": {k: getattr(LPVConfig(), k) for k in keys},
           "plane_self_illumination": plane_self_illumination(VARIANTS), "thin_wall": thin_wall(VARIANTS),
           "cornell_indirect": cornell_indirect(VARIANTS), "open_ground": open_ground(VARIANTS)}
    if not args.quick:
        out["courtyard"] = courtyard(VARIANTS)
    out["synthetic_cost"] = synthetic_cost(COST_VARIANTS)
    write_results(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

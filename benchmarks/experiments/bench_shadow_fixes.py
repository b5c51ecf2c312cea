"""What the two sun-shadow fixes buy and cost, each switched on in turn.

    python benchmarks/experiments/bench_shadow_fixes.py [--frames N] [--json FILE]

The courtyard and the Cornell box at 320×180, default ``RenderConfig`` but for the two switches,
against the same full references as ``bench_baseline.py`` (two cached halves, 256 / 1024 spp):

- ``RayTracingConfig.sun_shadows``: "osm" (the paper's overlapped shadow maps light what reflections and
  refractions show) vs "traced" (one shadow ray per traced hit in the CPU tracer);
- ``ShadowConfig.contact_steps``: 0 (off) vs the default screen-space contact shadow;

and two diagnostics of the glass: refractions off (the glass's transmitted term shows its own
rasterised surface: if the glass is right then, the refraction term is what was wrong) and 4096²
overlapped maps with a hard, unbiased lookup (whether the maps' resolution and bias are the cause;
acne elsewhere does not matter for this question).

Per setting: relMSE (also 0.1 % trimmed), FLIP, the luminance ratio ours/reference of the glass,
mirror and down-facing regions (``serenity.eval.regions``), the Cornell box's worst pixel
(row 152, column 97: ours and the reference), and the median over frames
2..N of the stages the switches touch ("cpu ray tracing" runs in the tracer process, beside the GL
work) and of the frame's total. The renderers of one scene take their frames in turn, so the load
of the machine falls on all settings alike. "tracer": the CPU tracer's time for one frame's rays
with and without the shadow rays (one thread, interleaved), what the traced rt shadows cost it.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from serenity.config import RayTracingConfig, RenderConfig, ScheduleConfig, ShadowConfig
from serenity.eval.metrics import compare, rel_mse
from serenity.eval.reference import render_reference
from serenity.eval.regions import region_report
from serenity.frame import Renderer
from serenity.io.results import write_results
from serenity.scene import load

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = {"courtyard": 256, "cornell": 1024}  # reference spp, as bench_baseline.py
NO_CONTACT = ShadowConfig(contact_steps=0)
SETTINGS = {
    # diagnostics: which term of the glass was wrong (refraction off: the glass's transmitted term
    # shows its own rasterised surface) and whether finer, unbiased overlapped maps get it right
    "OSM, refractions off, no contact shadow": RenderConfig(rt=RayTracingConfig(sun_shadows="osm", refractions=False),
                                                            shadow=NO_CONTACT),
    "OSM 4096², hard, no bias, no contact shadow": RenderConfig(
        rt=RayTracingConfig(sun_shadows="osm", osm_size=4096),
        shadow=ShadowConfig(contact_steps=0, filter="hard", bias=0.0, normal_offset=0.0)),
    "OSM, no contact shadow (before)": RenderConfig(rt=RayTracingConfig(sun_shadows="osm"), shadow=NO_CONTACT),
    "traced rt shadows, no contact shadow": RenderConfig(shadow=NO_CONTACT),
    "traced rt shadows + contact shadow (default)": RenderConfig(),
}
STAGES = ("direct lighting", "cpu ray tracing", "shadow maps (OSM)", "rt direct lighting", "composite")
WORST = (152, 97)
"""The Cornell box's worst pixel (row, column) at 320×180."""


def tracer_cost(scene, w, h, repeats) -> dict | None:
    """The CPU tracer's own time for one frame's rays (the default frame's ray-casting buffer), with
    and without the sun's shadow rays, in this process on one thread, interleaved ``2 * repeats``
    times; None when the scene has no ray-traced pixel."""
    r = Renderer(scene, w, h, config=RenderConfig(schedule=ScheduleConfig(overlap=False)))
    try:
        r.render()
        if r.tracer is None:
            return None
        rcb = r.raycast_pass.read()
        batches = [b for b in r._ray_batches(rcb) if b is not None]
        times = {False: [], True: []}
        for _ in range(2 * repeats):
            for with_sun in (False, True):
                t0 = time.perf_counter()
                for b in batches:
                    r.tracer.trace(*b[:4], transmissions=b[4], sun_direction=b[5] if with_sun else None, threads=1)
                times[with_sun].append((time.perf_counter() - t0) * 1e3)
        return {"rays": int(sum(len(b[0]) for b in batches)), "threads": 1,
                "ms_without_sun": float(np.median(times[False])), "ms_with_sun": float(np.median(times[True]))}
    finally:
        r.close()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=6)
    ap.add_argument("--json", default=os.path.join(HERE, "results", "shadow_fixes.json"))
    args = ap.parse_args(argv)
    w, h = 320, 180
    out = {"benchmark": "shadow_fixes", "size": [w, h], "frames": args.frames,
           "note": "timings on a shared 2-core machine: compare settings within one run", "scenes": {}}
    for name, spp in SCENES.items():
        scene = load(name)
        ref = (render_reference(scene, w, h, spp=spp // 2, component="full", seed=0)
               + render_reference(scene, w, h, spp=spp // 2, component="full", seed=1)) / 2
        renderers = {label: Renderer(scene, w, h, config=cfg) for label, cfg in SETTINGS.items()}
        timings = {label: [] for label in SETTINGS}
        frames = {}
        try:
            for _ in range(args.frames):
                for label, r in renderers.items():
                    frames[label] = r.render()
                    timings[label].append(frames[label].timings | {"total": frames[label].total_ms})
        finally:
            for r in renderers.values():
                r.close()
        rows = {}
        for label, f in frames.items():
            m = compare(f.hdr, ref, exposure=f.exposure)
            reg = region_report(f.hdr, ref, f.aovs["normal"], f.aovs["depth"], f.aovs["material"],
                                [mat.name for mat in scene.materials], exposure=f.exposure, fmap=m["flip_map"])
            lum = {k: v["luminance_ratio"] for k, v in reg["materials"].items() if k in ("glass", "mirror")}
            lum["down-facing"] = reg["regions"]["down-facing"]["luminance_ratio"]
            later = timings[label][1:] or timings[label]
            ms = {s: float(np.median([t.get(s, 0.0) for t in later])) for s in (*STAGES, "total")}
            row = {"rel_mse": m["rel_mse"], "rel_mse_trimmed": rel_mse(f.hdr, ref, trim=1e-3), "flip": m["flip"],
                   "luminance_ratio": lum, "ms": ms}
            if name == "cornell":
                row["worst_pixel"] = {"row_column": list(WORST), "ours": f.hdr[WORST].tolist(),
                                      "reference": ref[WORST].tolist()}
            rows[label] = row
            print(f"{name:<10} {label:<45} relMSE {m['rel_mse']:.4f} FLIP {m['flip']:.4f} "
                  + " ".join(f"{k} {v:.3f}" for k, v in lum.items() if v is not None)
                  + f"  direct lighting {ms['direct lighting']:.2f} ms, cpu ray tracing {ms['cpu ray tracing']:.2f} ms,"
                  f" OSM {ms['shadow maps (OSM)']:.2f} ms, total {ms['total']:.1f} ms", flush=True)
        out["scenes"][name] = {"reference_spp": spp, "settings": rows}
        tracer = tracer_cost(scene, w, h, args.frames)
        if tracer:
            out["scenes"][name]["tracer"] = tracer
            print(f"{name:<10} tracer, {tracer['rays']} rays: {tracer['ms_without_sun']:.2f} ms without shadow rays, "
                  f"{tracer['ms_with_sun']:.2f} ms with", flush=True)
    write_results(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Edges and textures: FXAA post pass vs jittered temporal accumulation on a static
camera, and the G-buffer's in-shader anisotropic texture filtering (``RenderConfig.texture_taps``),
against the cached Mitsuba references of ``bench_baseline.py``.

    python benchmarks/bench_aa.py [--size 320x180] [--json FILE]

Per scene and method: FLIP and relMSE over all pixels and over the edge pixels (``edges`` region of
``serenity.eval.regions``: depth discontinuities of the unjittered frame), the FXAA pass's ms (its
stage timing, llvmpipe) and, for accumulation, the wall ms of all its frames (a viewer pays them over
successive frames, one ordinary frame each). ``texture_taps`` (courtyard: its ground is the textured
material): FLIP / relMSE over all pixels and over the ground's pixels, and the G-buffer stage's median ms
over 8 frames, the settings' frames interleaved.
Default ``RenderConfig`` otherwise.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import numpy as np

from serenity.config import RenderConfig
from serenity.eval.metrics import compare
from serenity.eval.reference import render_reference
from serenity.eval.regions import region_report
from serenity.frame import Renderer
from serenity.io.results import write_results
from serenity.scene import load

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = {"courtyard": 256, "cornell": 1024}  # reference spp, as bench_baseline.py (same cache entries)
SAMPLES = (4, 8, 16)
TAPS = (1, 2, 4, 8)


def score(frame, ref):
    m = compare(frame.hdr, ref, exposure=frame.exposure)
    rep = region_report(frame.hdr, ref, frame.aovs["normal"], frame.aovs["depth"], exposure=frame.exposure,
                        fmap=m["flip_map"])
    e = rep["regions"]["edges"]
    return {"flip": m["flip"], "rel_mse": m["rel_mse"], "edge_flip": e["flip"], "edge_rel_mse": e["rel_mse"],
            "edge_pixels": e["pixels"]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", default="320x180")
    ap.add_argument("--json", default=os.path.join(HERE, "results", "aa.json"))
    args = ap.parse_args(argv)
    width, height = (int(x) for x in args.size.split("x"))
    rows = []
    for name, spp in SCENES.items():
        scene = load(name)
        ref = (render_reference(scene, width, height, spp=spp // 2, component="full", seed=0, progress=False)
               + render_reference(scene, width, height, spp=spp // 2, component="full", seed=1,
                                  progress=False)) / 2
        for aa in ("none", "fxaa"):
            r = Renderer(scene, width, height, config=RenderConfig(antialiasing=aa))
            frames = [r.render() for _ in range(4)]
            ms = float(np.median([f.timings.get("anti-aliasing", 0.0) for f in frames[1:]]))
            total = float(np.median([f.total_ms for f in frames[1:]]))
            rows.append({"scene": name, "method": aa, "aa_ms": ms, "frame_ms": total, **score(frames[-1], ref)})
            if aa == "none":
                for n in SAMPLES:
                    t = time.perf_counter()
                    f = r.render_accumulated(n)
                    rows.append({"scene": name, "method": f"accumulate {n}", "aa_ms": 0.0, "frame_ms": total,
                                 "all_frames_ms": (time.perf_counter() - t) * 1e3, **score(f, ref)})
        for row in rows:
            if row["scene"] == name:
                print(f"{name:<10} {row['method']:<14} FLIP {row['flip']:.4f} relMSE {row['rel_mse']:.4f}  edges "
                      f"({row['edge_pixels']} px) FLIP {row['edge_flip']:.4f} relMSE {row['edge_rel_mse']:.4f}  "
                      f"AA pass {row['aa_ms']:.1f} ms", flush=True)
    taps_rows = []
    scene = load("courtyard")
    # G-buffer cost: one renderer per setting, frames interleaved round-robin so that the load of this
    # shared machine falls on every setting alike
    renderers = {taps: Renderer(scene, width, height, config=RenderConfig(texture_taps=taps)) for taps in TAPS}
    gb_ms = {taps: [] for taps in TAPS}
    for k in range(9):
        for taps, r in renderers.items():
            f = r.render(read_back=("hdr",))
            if k:
                gb_ms[taps].append(f.timings["g-buffer"])
    del renderers
    ref = (render_reference(scene, width, height, spp=128, component="full", seed=0, progress=False)
           + render_reference(scene, width, height, spp=128, component="full", seed=1, progress=False)) / 2
    names = [m.name for m in scene.materials]
    for taps in TAPS:
        r = Renderer(scene, width, height, config=RenderConfig(texture_taps=taps))
        frames = [r.render() for _ in range(2)]
        f = frames[-1]
        m = compare(f.hdr, ref, exposure=f.exposure)
        g = region_report(f.hdr, ref, f.aovs["normal"], f.aovs["depth"], f.aovs["material"], names,
                          exposure=f.exposure, fmap=m["flip_map"])["materials"]["ground"]
        taps_rows.append({"texture_taps": taps, "flip": m["flip"], "rel_mse": m["rel_mse"], "ground_flip": g["flip"],
                          "ground_rel_mse": g["rel_mse"],
                          "gbuffer_ms": float(np.median(gb_ms[taps]))})
        t = taps_rows[-1]
        print(f"courtyard texture_taps {taps}: FLIP {t['flip']:.4f} relMSE {t['rel_mse']:.4f}  ground FLIP "
              f"{t['ground_flip']:.4f} relMSE {t['ground_rel_mse']:.4f}  g-buffer {t['gbuffer_ms']:.1f} ms", flush=True)
    out = {"benchmark": "aa", "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                                          "python": sys.version.split()[0]},
           "size": [width, height], "reference_spp": SCENES, "results": rows, "texture_taps": taps_rows}
    write_results(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

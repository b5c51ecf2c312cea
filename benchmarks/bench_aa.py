"""Edges and textures: FXAA, TAA and jittered temporal accumulation on a static camera, FXAA and TAA
with a moving camera, and the G-buffer's in-shader anisotropic texture filtering
(``RenderConfig.texture_taps``), against Mitsuba references (the static camera's those of
``bench_baseline.py``, cached).

    python benchmarks/bench_aa.py [--size 320x180] [--json FILE] [--cases still,moving,taps] [--scenes ...]

Per scene and method: FLIP and relMSE over all pixels and over the edge pixels (``edges`` region of
``serenity.eval.regions``: depth discontinuities of the unjittered frame), the FXAA pass's ms (its
stage timing, llvmpipe) and, for accumulation, the wall ms of all its frames (a viewer pays them over
successive frames, one ordinary frame each); TAA after 8 and 16 frames of the still view. The moving
camera (``moving``): ``MOVING_FRAMES`` frames along a slow truck and dolly (``moving_pose``, about a
pixel a frame), each method rendering the whole path and scored at the last ``MOVING_SCORED`` poses
against a reference at each pose (``reference_with_floor``: its noise floor recorded), on the edges of
the unjittered frame; the anti-aliasing stage's median ms over the path. ``texture_taps`` (courtyard:
its ground is the textured material): FLIP / relMSE over all pixels and over the ground's pixels, and
the G-buffer stage's median ms over 8 frames, the settings' frames interleaved.
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
from serenity.eval.reference import reference_with_floor, render_reference
from serenity.eval.regions import region_report
from serenity.frame import Renderer
from serenity.io.results import write_results
from serenity.raster.taa import TAAConfig
from serenity.scene import load
from serenity.scene.model import Camera

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = {"courtyard": 256, "cornell": 1024}  # reference spp, as bench_baseline.py (same cache entries)
SAMPLES = (4, 8, 16)
TAPS = (1, 2, 4, 8)
MOVING_FRAMES = 24
MOVING_SCORED = 4       # the last poses of the path, each against a reference at that pose
MOVING_SPP = {"courtyard": 256, "cornell": 1024}  # their references' spp (the Cornell box's path tracing is noisier)
TRUCK = 0.006           # per frame, of the camera's distance to its target (about a pixel a frame at 320x180)
DOLLY = 0.003
TAA_STILL = (8, 16)     # frames of a still view resolved by TAA


def moving_pose(base: Camera, k: int) -> Camera:
    """Frame ``k`` of the moving-camera case: ``base`` trucked right by k·TRUCK and dollied in by k·DOLLY
    of its distance to its target, the view direction kept."""
    d = np.asarray(base.target, np.float64) - np.asarray(base.position, np.float64)
    dist = float(np.linalg.norm(d))
    right = np.cross(d / dist, base.up)
    move = k * dist * (TRUCK * right / np.linalg.norm(right) + DOLLY * d / dist)
    return Camera(position=base.position + move, target=base.target + move, up=base.up, fov_y_deg=base.fov_y_deg,
                  near=base.near, far=base.far)


def moving_references(name: str, width: int, height: int) -> list:
    """The references (``reference_with_floor``, cached) of the moving case's scored poses."""
    scene = load(name)
    base = scene.camera
    out = []
    for k in range(MOVING_FRAMES - MOVING_SCORED, MOVING_FRAMES):
        scene.camera = moving_pose(base, k)
        out.append(reference_with_floor(scene, width, height, spp=MOVING_SPP[name], progress=False))
    scene.camera = base
    return out


def score(frame, ref, aovs=None):
    """FLIP and relMSE of ``frame`` against ``ref``, over all pixels and the edges of ``aovs`` (default
    the frame's own; a jittered frame is scored on the unjittered frame's edges)."""
    aovs = frame.aovs if aovs is None else aovs
    m = compare(frame.hdr, ref, exposure=frame.exposure)
    rep = region_report(frame.hdr, ref, aovs["normal"], aovs["depth"], exposure=frame.exposure,
                        fmap=m["flip_map"])
    e = rep["regions"]["edges"]
    return {"flip": m["flip"], "rel_mse": m["rel_mse"], "edge_flip": e["flip"], "edge_rel_mse": e["rel_mse"],
            "edge_pixels": e["pixels"]}


#: the moving case's methods: (name, RenderConfig.antialiasing, TAAConfig or None)
MOVING_METHODS = (("none", "none", None), ("fxaa", "fxaa", None), ("taa", "taa", None),
                  ("taa, karis weights", "taa", TAAConfig(weights="karis")),
                  ("taa, no clip", "taa", TAAConfig(clip=False)))


def moving_case(name: str, width: int, height: int) -> tuple[list, list]:
    """Every method of ``MOVING_METHODS`` along the moving camera's path (``moving_pose``), scored at
    the last ``MOVING_SCORED`` poses against their references (on the edges of the unjittered frame
    of each pose). Returns (rows, the references' noise floors)."""
    refs = moving_references(name, width, height)
    scene = load(name)
    base = scene.camera
    first = MOVING_FRAMES - MOVING_SCORED
    plain_aovs = {}
    rows = []
    for method, aa, taa_config in MOVING_METHODS:
        r = Renderer(scene, width, height, config=RenderConfig(antialiasing=aa))
        if taa_config is not None:
            r.taa_pass.config = taa_config
        scores, ms = [], []
        for k in range(MOVING_FRAMES):
            scene.camera = moving_pose(base, k)
            f = r.render(read_back=("hdr", "aovs") if k >= first else False)
            if k:
                ms.append(f.timings.get("anti-aliasing", 0.0))
            if k >= first:
                if method == "none":
                    plain_aovs[k] = f.aovs
                scores.append(score(f, refs[k - first].image, plain_aovs[k]))
        r.close()
        scene.camera = base
        row = {"scene": name, "method": method, "aa_ms": float(np.median(ms)),
               **{key: float(np.mean([sc[key] for sc in scores])) for key in scores[0]},
               "per_pose": scores}
        rows.append(row)
        print(f"{name:<10} moving {method:<20} FLIP {row['flip']:.4f} relMSE {row['rel_mse']:.4f}  edges "
              f"({row['edge_pixels']:.0f} px) FLIP {row['edge_flip']:.4f} relMSE {row['edge_rel_mse']:.4f}  "
              f"AA pass {row['aa_ms']:.1f} ms", flush=True)
    floors = [{"pose": first + i, **ref.floor, "spp": ref.spp} for i, ref in enumerate(refs)]
    return rows, floors


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", default="320x180")
    ap.add_argument("--json", default=os.path.join(HERE, "results", "aa.json"))
    ap.add_argument("--cases", default="still,moving,taps", help="which cases to run (comma-separated)")
    ap.add_argument("--scenes", default=",".join(SCENES), help="the still and moving cases' scenes (comma-separated)")
    args = ap.parse_args(argv)
    cases = set(args.cases.split(","))
    scenes = {name: SCENES[name] for name in args.scenes.split(",")}
    width, height = (int(x) for x in args.size.split("x"))
    rows = []
    for name, spp in scenes.items() if "still" in cases else ():
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
                plain = frames[-1]
                for n in SAMPLES:
                    t = time.perf_counter()
                    f = r.render_accumulated(n)
                    rows.append({"scene": name, "method": f"accumulate {n}", "aa_ms": 0.0, "frame_ms": total,
                                 "all_frames_ms": (time.perf_counter() - t) * 1e3, **score(f, ref)})
        r = Renderer(scene, width, height, config=RenderConfig(antialiasing="taa"))
        frames = [r.render(read_back=("hdr",)) for _ in range(max(TAA_STILL))]
        for n in TAA_STILL:
            rows.append({"scene": name, "method": f"taa {n}", "aa_ms": float(np.median(
                [f.timings.get("anti-aliasing", 0.0) for f in frames[1:]])),
                "frame_ms": float(np.median([f.total_ms for f in frames[1:]])),
                **score(frames[n - 1], ref, plain.aovs)})
        r.close()
        for row in rows:
            if row["scene"] == name:
                print(f"{name:<10} {row['method']:<14} FLIP {row['flip']:.4f} relMSE {row['rel_mse']:.4f}  edges "
                      f"({row['edge_pixels']} px) FLIP {row['edge_flip']:.4f} relMSE {row['edge_rel_mse']:.4f}  "
                      f"AA pass {row['aa_ms']:.1f} ms", flush=True)
    moving, floors = [], {}
    for name in scenes if "moving" in cases else ():
        case_rows, floors[name] = moving_case(name, width, height)
        moving += case_rows
    taps_rows = []
    if "taps" in cases:
        scene = load("courtyard")
        # G-buffer cost: one renderer per setting, frames interleaved round-robin so that the load of this
        # shared machine falls on every setting alike
        renderers = {taps: Renderer(scene, width, height, config=RenderConfig(texture_taps=taps, antialiasing="none"))
                     for taps in TAPS}
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
            r = Renderer(scene, width, height, config=RenderConfig(texture_taps=taps, antialiasing="none"))
            frames = [r.render() for _ in range(2)]
            f = frames[-1]
            m = compare(f.hdr, ref, exposure=f.exposure)
            g = region_report(f.hdr, ref, f.aovs["normal"], f.aovs["depth"], f.aovs["material"], names,
                              exposure=f.exposure, fmap=m["flip_map"])["materials"]["ground"]
            taps_rows.append({"texture_taps": taps, "flip": m["flip"], "rel_mse": m["rel_mse"],
                              "ground_flip": g["flip"], "ground_rel_mse": g["rel_mse"],
                              "gbuffer_ms": float(np.median(gb_ms[taps]))})
            t = taps_rows[-1]
            print(f"courtyard texture_taps {taps}: FLIP {t['flip']:.4f} relMSE {t['rel_mse']:.4f}  ground FLIP "
                  f"{t['ground_flip']:.4f} relMSE {t['ground_rel_mse']:.4f}  g-buffer {t['gbuffer_ms']:.1f} ms",
                  flush=True)
    out = {"benchmark": "aa", "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                                          "python": sys.version.split()[0]},
           "size": [width, height], "reference_spp": SCENES, "results": rows, "texture_taps": taps_rows,
           "moving": {"frames": MOVING_FRAMES, "scored": MOVING_SCORED, "truck": TRUCK, "dolly": DOLLY,
                      "reference_spp": MOVING_SPP, "reference_floor": floors, "results": moving}}
    write_results(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""A/B of one stage of the frame between two variants of the renderer, in one process, frames interleaved.

    python benchmarks/bench_pass_ab.py --stage "lpv lighting" --a-glsl lpv.glsl@HEAD~1 [--json FILE]
    python benchmarks/bench_pass_ab.py --stage "shadow maps (CSM)" --moving \\
        --a-config shadow.texels_per_pixel=0 --reference [--json FILE]

Variant A is the renderer with the given GLSL files as they were at a git revision (``--a-glsl
FILE@REV``, repeatable; the file's ``#include``s as they are now) and/or config fields overridden
(``--a-config FIELD=VALUE``, a sub-config's field as ``shadow.size=512``; VALUE is parsed as JSON,
else taken as a string); variant B is the same with ``--b-glsl`` / ``--b-config`` (by default the
code as it is). Both renderers draw the same scene at the same size; each frame of one is followed
by a frame of the other, so a shared machine's drifting load falls on both alike. Still frames by
default (the camera and sun of the scene); ``--moving``: the ``serenity bench`` camera path and sun,
so that the work a moving frame redoes (shadow tiles, the volumes) is timed. Per variant: the
stage's median, 10th percentile and minimum over the frames after two warm-up frames, the whole
frame's median and every stage's; whether the two variants' still frames (the scene's camera and sun, a fresh renderer
each, second frame) are bit-identical; with ``--reference``, their FLIP and relMSE (all pixels and
0.1 % trimmed) against the frontier's cached 1024-spp reference.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from serenity.io.results import write_results  # noqa: E402

GLSL_DIR = "serenity/raster/glsl"


def glsl_at(spec: str) -> tuple[str, str]:
    """(file name, its text at the revision) for ``FILE@REV``."""
    name, _, rev = spec.partition("@")
    if not rev:
        raise SystemExit(f"--*-glsl wants FILE@REV, got {spec!r}")
    text = subprocess.run(["git", "show", f"{rev}:{GLSL_DIR}/{name}"], cwd=ROOT, check=True, capture_output=True,
                          text=True).stdout
    return name, text


def parse_config(pairs: list[str]) -> dict:
    """{"field": value} or {"sub": {"field": value}} from FIELD=VALUE strings."""
    out: dict = {}
    for p in pairs:
        key, _, raw = p.partition("=")
        try:
            value = json.loads(raw)
        except json.JSONDecodeError:
            value = raw
        if "." in key:
            sub, field = key.split(".", 1)
            out.setdefault(sub, {})[field] = value
        else:
            out[key] = value
    return out


def make_config(preset: str, overrides: dict):
    from serenity.config import RenderConfig

    # in one step: a pair of overrides may only be valid together (sky.method=gather, lpv.diffuse=false)
    return RenderConfig.from_dict(overrides, where="--a-config/--b-config", base=RenderConfig.preset(preset))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stage", required=True, help="a frame.STAGES name, e.g. 'direct lighting'")
    ap.add_argument("--scene", default="courtyard")
    ap.add_argument("--size", default="320x180")
    ap.add_argument("--preset", default="lpv-fast")
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--moving", action="store_true")
    ap.add_argument("--reference", action="store_true")
    for v in "ab":
        ap.add_argument(f"--{v}-glsl", action="append", default=[])
        ap.add_argument(f"--{v}-config", action="append", default=[])
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    w, h = (int(x) for x in args.size.lower().split("x"))

    from serenity.bench import camera_path, sun_path
    from serenity.frame import Renderer
    from serenity.raster import context
    from serenity.scene import load

    variants = {v: {"glsl": dict(glsl_at(s) for s in getattr(args, f"{v}_glsl")),
                    "config": parse_config(getattr(args, f"{v}_config"))} for v in "ab"}
    original = context.shader_source
    active: dict[str, str] = {}

    def shader_source(name, _seen=frozenset()):  # the variant's files while its renderer compiles
        if name not in active:
            return original(name, _seen)
        if name in _seen:
            return ""
        return context.expand_includes(active[name], _seen | {name})

    context.shader_source = shader_source  # context.load_program (and the original's includes) look it up here
    base = load(args.scene)
    runs = {}
    for v in "ab":
        scene = copy.deepcopy(base)
        active.clear()
        active.update(variants[v]["glsl"])
        r = Renderer(scene, w, h, config=make_config(args.preset, variants[v]["config"]))
        for _ in range(2):  # every program variant compiles in the first frames, with this variant's files
            r.render(read_back=False)
        runs[v] = {"renderer": r, "scene": scene, "stage_ms": [], "frame_ms": [], "timings": []}
    active.clear()
    bc, bs = base.camera, base.sun.direction.copy()
    for i in range(args.frames):
        for v in ("ab" if i % 2 == 0 else "ba"):
            run = runs[v]
            if args.moving:
                t = i / max(1, args.frames - 1)
                run["scene"].camera = camera_path(bc, t)
                run["scene"].sun.direction = sun_path(bs, t)
            f = run["renderer"].render(read_back=False)
            run["stage_ms"].append(f.timings.get(args.stage, 0.0))
            run["frame_ms"].append(f.wall_ms)
            run["timings"].append(f.timings)
    images = {}
    for v in "ab":  # the still scene's converged frame (a fresh renderer: no amortised volume lags behind)
        active.clear()
        active.update(variants[v]["glsl"])
        r = Renderer(copy.deepcopy(base), w, h, config=make_config(args.preset, variants[v]["config"]))
        r.render(read_back=False)
        images[v] = r.render(read_back=("hdr",)).hdr
        r.close()
    active.clear()
    out = {"benchmark": "pass_ab", "command": "python benchmarks/bench_pass_ab.py " + " ".join(argv or sys.argv[1:]),
           "scene": args.scene, "size": [w, h], "preset": args.preset, "stage": args.stage, "moving": args.moving,
           "frames": args.frames, "load_average": list(os.getloadavg()),
           "images_identical": bool(np.array_equal(images["a"], images["b"])),
           "max_abs_difference": float(np.abs(images["a"] - images["b"]).max()), "variants": {}}
    ref = None
    if args.reference:
        from serenity.eval.metrics import compare, rel_mse
        from serenity.eval.reference import render_reference

        ref = render_reference(base, w, h, spp=1024, component="full", seed=0, progress=True)
    for v in "ab":
        run = runs[v]
        s = run["stage_ms"][2:]
        rec = {"glsl": {k: "at " + spec.partition("@")[2] for k, spec in
                        zip(variants[v]["glsl"], getattr(args, f"{v}_glsl"), strict=True)},
               "config": variants[v]["config"], "shadow_size": run["renderer"].shadow_size,
               "stage_ms_median": float(np.median(s)), "stage_ms_p10": float(np.percentile(s, 10)),
               "stage_ms_min": float(np.min(s)), "frame_ms_median": float(np.median(run["frame_ms"][2:])),
               # every stage's median too: a change to one pass moves the others' contention
               "stages_ms_median": {k: float(np.median([t.get(k, 0.0) for t in run["timings"][2:]]))
                                    for k in dict.fromkeys(k for t in run["timings"][2:] for k in t)}}
        if ref is not None:
            m = compare(images[v], ref, exposure=run["renderer"].config.exposure)
            rec.update(flip=float(m["flip"]), rel_mse=float(m["rel_mse"]),
                       rel_mse_trimmed=float(rel_mse(images[v], ref, trim=1e-3)))
        out["variants"][v] = rec
        run["renderer"].close()
        print(f"{v.upper()}: {args.stage} median {rec['stage_ms_median']:.2f} ms, p10 {rec['stage_ms_p10']:.2f}, "
              f"min {rec['stage_ms_min']:.2f}; frame {rec['frame_ms_median']:.1f} ms"
              + (f"; FLIP {rec['flip']:.4f}, relMSE {rec['rel_mse']:.4f} ({rec['rel_mse_trimmed']:.4f} trimmed)"
                 if ref is not None else ""))
    print(f"images identical: {out['images_identical']} (max |A - B| {out['max_abs_difference']:.3g})")
    if args.json:
        write_results(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

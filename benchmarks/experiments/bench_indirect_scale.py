"""What the quarter-resolution indirect light of the ``lpv-fast`` preset costs in accuracy and buys in
time: ``lpv-fast`` as it is (``IndirectConfig.scale`` = 4: sky light, LPV light and SSAO at 1/4 resolution,
bilaterally upsampled) against the same preset at 1/2 resolution, for the courtyard and the Cornell
box at 320×180 and 640×360, against the frontier's 1024-spp references.

    python benchmarks/experiments/bench_indirect_scale.py [--json benchmarks/experiments/results/indirect_scale.json]

Per case: FLIP and relMSE (all pixels, and without the worst 0.1 %) of one still frame, and the
median ms of the passes that run at the indirect resolution (sky lighting, LPV lighting, SSAO, the
low-res guide; "indirect_passes_ms") and of the deferred pass that upsamples them (its own
full-resolution cost included), over ``--frames`` still frames, the two settings' renderers interleaved frame by
frame so that a shared machine's load falls on both alike.
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
from serenity.frame import Renderer  # noqa: E402
from serenity.io.results import write_results  # noqa: E402
from serenity.scene import load  # noqa: E402

LOW_RES_STAGES = ("sky lighting", "lpv lighting", "ssao", "low-res guide")
STAGES = (*LOW_RES_STAGES, "direct lighting")
"""The passes at the indirect resolution, then the full-resolution deferred pass (direct light and the upsampling)."""


def run(frames: int) -> list[dict]:
    medium = RenderConfig.preset("lpv-fast")
    settings = {"1/4 (lpv-fast)": medium,
                "1/2": dataclasses.replace(medium, indirect=dataclasses.replace(medium.indirect, scale=2))}
    rows = []
    for scene_name in ("courtyard", "cornell"):
        scene = load(scene_name)
        for w, h in ((320, 180), (640, 360)):
            ref = render_reference(scene, w, h, spp=1024)
            renderers = {k: Renderer(copy.deepcopy(scene), w, h, config=c) for k, c in settings.items()}
            out = {k: {"stages": {s: [] for s in STAGES}, "frame": []} for k in settings}
            first = {k: r.render() for k, r in renderers.items()}
            for _ in range(frames):
                for k, r in renderers.items():
                    f = r.render(read_back=("hdr",))
                    out[k]["frame"].append(f.wall_ms)
                    for s in STAGES:
                        out[k]["stages"][s].append(f.timings.get(s, 0.0))
            for k, r in renderers.items():
                f = first[k]
                m = metrics.compare(f.hdr[..., :3], ref[..., :3], exposure=f.exposure)
                stages = {s: float(np.median(v)) for s, v in out[k]["stages"].items()}
                rows.append({"scene": scene_name, "size": [w, h], "indirect": k,
                             "indirect_scale": settings[k].indirect.scale, "flip": m["flip"],
                             "rel_mse": m["rel_mse"],
                             "rel_mse_trimmed": metrics.rel_mse(f.hdr[..., :3], ref[..., :3], trim=1e-3),
                             "stages_ms": stages,
                             "indirect_passes_ms": float(sum(stages[s] for s in LOW_RES_STAGES)),
                             "still_frame_ms": float(np.median(out[k]["frame"]))})
                print(f"{scene_name:9s} {w}x{h} indirect {k:13s} FLIP {m['flip']:.4f}  relMSE* "
                      f"{rows[-1]['rel_mse_trimmed']:.4f}  indirect passes {rows[-1]['indirect_passes_ms']:6.1f} ms  "
                      f"still frame {rows[-1]['still_frame_ms']:6.1f} ms", flush=True)
                r.close()
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", default=os.path.join(ROOT, "benchmarks", "experiments", "results", "indirect_scale.json"))
    ap.add_argument("--frames", type=int, default=6)
    args = ap.parse_args()
    t0 = time.perf_counter()
    rows = run(args.frames)
    write_results(args.json, {"benchmark": "indirect_scale", "reference_spp": 1024, "frames": args.frames,
                              "stages": list(STAGES), "rows": rows, "seconds": time.perf_counter() - t0})


if __name__ == "__main__":
    main()

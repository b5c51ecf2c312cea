"""Refraction through glass solids against Mitsuba's dielectric.

    python benchmarks/experiments/bench_refraction.py [--size 160x90] [--spp 512] [--json FILE]

The ``glass`` scene (slab, ball, prism) rendered with ``RayTracingConfig.transmissions`` = 0 (the paper:
a refraction ray shows the first surface it hits, the solid's own back face), 1, 2 and 4 (the ray is
bent through that many transparent interfaces first), against the full Mitsuba reference: relMSE
and FLIP over all pixels and over the ray-traced ones, and the CPU ray-tracing ms (median of
frames 2..N, serial schedule). The reference is cached.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from serenity.config import RayTracingConfig, RenderConfig, ScheduleConfig
from serenity.eval.metrics import compare
from serenity.eval.reference import render_reference
from serenity.frame import Renderer
from serenity.io.results import write_results
from serenity.scene import load

HERE = os.path.dirname(os.path.abspath(__file__))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", default="160x90")
    p.add_argument("--spp", type=int, default=512)
    p.add_argument("--frames", type=int, default=3)
    p.add_argument("--json", default=os.path.join(HERE, "results", "refraction.json"))
    args = p.parse_args(argv)
    width, height = (int(x) for x in args.size.split("x"))
    scene = load("glass")
    ref = render_reference(scene, width, height, spp=args.spp, component="full", seed=0)
    rows = []
    for t in (0, 1, 2, 4):
        r = Renderer(scene, width, height, config=RenderConfig(rt=RayTracingConfig(transmissions=t),
                                                                  schedule=ScheduleConfig(overlap=False)))
        frames = [r.render() for _ in range(max(2, args.frames))]
        f = frames[-1]
        traced = f.aovs["rt_mask"][..., 0] > 0
        every = compare(f.hdr, ref, exposure=f.exposure)
        inside = compare(f.hdr, ref, mask=traced, exposure=f.exposure)
        ms = float(np.median([x.timings["cpu ray tracing"] for x in frames[1:]]))
        rows.append({"transmissions": t, "rel_mse": every["rel_mse"], "flip": every["flip"],
                     "rel_mse_traced": inside["rel_mse"], "flip_traced": inside["flip"],
                     "traced_fraction": float(traced.mean()), "ray_tracing_ms": ms})
        print(f"transmissions {t}: relMSE {every['rel_mse']:.3f} FLIP {every['flip']:.3f} | traced px "
              f"({traced.mean():.1%}) relMSE {inside['rel_mse']:.3f} FLIP {inside['flip']:.3f} | "
              f"ray tracing {ms:.1f} ms", flush=True)
    write_results(args.json, {"scene": "glass", "size": [width, height], "reference_spp": args.spp, "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())

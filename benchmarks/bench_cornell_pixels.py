"""Which pixels make the Cornell box's relMSE: the worst pixels of the full frame against Mitsuba.

    python benchmarks/bench_cornell_pixels.py [--json FILE] [--top N]

The Cornell box at 320×180, default ``RenderConfig`` with and without the LPV, against the same full
reference as ``bench_baseline.py`` (1024 spp, two cached halves). Per setting: relMSE (ε = 1e-2), the
share of its pixel sum in the worst ``--top`` pixels, the up-facing region's relMSE, and for each of
those pixels its (row, column), world position and normal, ours and the reference (linear RGB) and
our direct light (the ``direct`` AOV): whether a pixel's error is direct light or the LPV's.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from serenity.config import LPVConfig, RenderConfig
from serenity.eval.metrics import REL_MSE_EPS
from serenity.eval.reference import render_reference
from serenity.frame import Renderer
from serenity.io.results import write_results
from serenity.scene import load

HERE = os.path.dirname(os.path.abspath(__file__))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", default=os.path.join(HERE, "results", "cornell_worst_pixels.json"))
    ap.add_argument("--top", type=int, default=8)
    args = ap.parse_args(argv)
    scene = load("cornell")
    w, h = 320, 180
    ref = (render_reference(scene, w, h, spp=512, component="full", seed=0)
           + render_reference(scene, w, h, spp=512, component="full", seed=1)) / 2
    out = {"benchmark": "cornell_worst_pixels", "size": [w, h], "reference_spp": 1024, "settings": {}}
    for label, cfg in (("LPV off", RenderConfig(lpv=LPVConfig(enabled=False))), ("default", RenderConfig())):
        f = Renderer(scene, w, h, config=cfg).render()
        err = np.mean((f.hdr - ref) ** 2 / (ref * ref + REL_MSE_EPS), axis=-1)
        up = f.aovs["normal"][..., 1] > 0.5
        order = np.argsort(err.ravel())[::-1][:args.top]
        pixels = []
        for i in order:
            y, x = divmod(int(i), w)
            pixels.append({"row": y, "column": x, "share_of_sum": float(err[y, x] / err.sum()),
                           "position": f.aovs["position"][y, x][:3].tolist(), "normal": f.aovs["normal"][y, x].tolist(),
                           "ours": f.hdr[y, x].tolist(), "reference": ref[y, x].tolist(),
                           "our_direct": f.aovs["direct"][y, x][:3].tolist()})
        out["settings"][label] = {"rel_mse": float(err.mean()), "up_facing_rel_mse": float(err[up].mean()),
                                  "top_share": float(err.ravel()[order].sum() / err.sum()),
                                  "rel_mse_without_worst_pixel": float(np.delete(err.ravel(), order[0]).mean()),
                                  "pixels": pixels}
        print(f"{label}: relMSE {err.mean():.3f} (up-facing {err[up].mean():.1f}); worst {args.top} px hold "
              f"{100 * out['settings'][label]['top_share']:.1f} %; without the worst pixel "
              f"{out['settings'][label]['rel_mse_without_worst_pixel']:.3f}", flush=True)
        for p in pixels[:4]:
            print(f"  ({p['row']}, {p['column']}) at {np.round(p['position'], 3).tolist()} n "
                  f"{np.round(p['normal'], 2).tolist()}: ours {np.round(p['ours'], 2).tolist()} ref "
                  f"{np.round(p['reference'], 3).tolist()} direct {np.round(p['our_direct'], 2).tolist()} "
                  f"({100 * p['share_of_sum']:.1f} % of the sum)", flush=True)
    write_results(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

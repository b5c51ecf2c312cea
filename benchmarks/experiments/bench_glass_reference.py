"""Is the courtyard's window error ours or the reference's? (per-region report)

    python benchmarks/experiments/bench_glass_reference.py [--size 320x180] [--spp 256] [--json FILE]

The per-region report puts half of the courtyard's relMSE on its 820 window pixels (material
``glass``, transparency 0.9), which come out 2.4× brighter than the Mitsuba reference. A path tracer
cannot carry a point-like sun's light through a smooth dielectric: the shadow ray towards the sun is
blocked by the glass and the refracted ray almost never hits the 0.53° sun sphere. So the rooms behind
the windows can be sunless in the reference even though sunlight enters them.

This measures it on the window pixels (mean radiance, W·m⁻²·sr⁻¹) for four images: ours and the
reference, each with the glass panes and with the panes removed (the same rooms seen through open
window holes). If the reference is right, its windows with glass should show about T·(1 − F₀) ≈ 0.86
of what the open holes show (plus a little reflection). ``ref_glass_over_open`` is far below that
when the reference drops the sun behind glass; ``ours_glass_over_open`` is the same ratio for ours.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import sys

import numpy as np

from serenity.eval.reference import render_reference
from serenity.frame import Renderer
from serenity.io.results import write_results
from serenity.scene import load

HERE = os.path.dirname(os.path.abspath(__file__))


def without_material(scene, name: str):
    """A copy of ``scene`` with every face of material ``name`` removed."""
    idx = [m.name for m in scene.materials].index(name)
    meshes = []
    for m in scene.meshes:
        keep = m.face_material != idx
        if keep.any():
            meshes.append(dataclasses.replace(m, faces=m.faces[keep], face_material=m.face_material[keep]))
    return dataclasses.replace(scene, meshes=meshes)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", default="320x180")
    ap.add_argument("--spp", type=int, default=256, help="reference spp, two halves as bench_baseline.py")
    ap.add_argument("--json", default=os.path.join(HERE, "results", "glass_reference.json"))
    args = ap.parse_args(argv)
    w, h = (int(x) for x in args.size.split("x"))
    scene = load("courtyard")
    open_scene = without_material(scene, "glass")
    half = args.spp // 2

    def ref(s):
        return (render_reference(s, w, h, spp=half, component="full", seed=0, progress=False)
                + render_reference(s, w, h, spp=half, component="full", seed=1, progress=False)) / 2

    def ours(s):
        r = Renderer(s, w, h)
        r.render()
        return r.render()

    f = ours(scene)
    windows = f.aovs["material"][..., 0] == [m.name for m in scene.materials].index("glass")
    lum = np.array([0.2126, 0.7152, 0.0722])
    means = {"ours_glass": f.hdr, "ref_glass": ref(scene), "ours_open": ours(open_scene).hdr,
             "ref_open": ref(open_scene)}
    means = {k: float((v[windows] @ lum).mean()) for k, v in means.items()}
    out = {"benchmark": "glass_reference", "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
           "size": [w, h], "reference_spp": 2 * half, "window_pixels": int(windows.sum()),
           "mean_luminance_on_window_pixels": means,
           "ref_glass_over_open": means["ref_glass"] / means["ref_open"],
           "ours_glass_over_open": means["ours_glass"] / means["ours_open"],
           "expected_glass_over_open": 0.9 * (1 - 0.04)}
    for k, v in means.items():
        print(f"{k:<11} {v:8.2f} W/m^2/sr (luminance, mean over {int(windows.sum())} window pixels)")
    print(f"glass / open: reference {out['ref_glass_over_open']:.3f}, ours {out['ours_glass_over_open']:.3f} "
          f"(a pane of T = 0.9: about {out['expected_glass_over_open']:.2f} + reflection)")
    write_results(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

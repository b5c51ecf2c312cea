"""Where the indirect light's error comes from, split by light path and surface orientation.

    python benchmarks/bench_indirect_split.py [--preset medium] [--size 320x180] [--spp 256]
                                              [--json benchmarks/results/indirect_split.json]

Whole-image FLIP hides which term is wrong; scaling the sky or the LPV term globally moves the
courtyard's FLIP by under 0.002 (the errors have opposite signs on different surfaces). So per
scene, per region of the G-buffer's normals (vertical walls |n_y| < 0.3, up-facing n_y > 0.7,
down-facing n_y < -0.7; background and ray-traced pixels left out), the mean luminance of

- ours: the sun's direct light (the ``direct`` AOV), the sky term (a frame without the LPV minus
  the direct light: the sky volume's irradiance times SSAO), the LPV term (the full frame minus the
  frame without the LPV);
- Mitsuba (the same scene export as the references, ``serenity.eval.reference``): the full
  1024-spp reference (cached), the one-bounce reference (``component="one-bounce"``: emitters and
  one indirect bounce), the sun alone with direct light only, and the sky alone with direct light
  only and with every bounce (``--spp`` each);

and the ratios that matter: our indirect light (sky + LPV) against the reference's (the full
reference minus its sun-only direct light), against its first bounce only (the one-bounce reference
minus the sun-only direct light), and our sky term against the sky's own direct light.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from serenity.config import RenderConfig  # noqa: E402
from serenity.eval import reference as R  # noqa: E402
from serenity.frame import Renderer  # noqa: E402
from serenity.io.results import write_results  # noqa: E402
from serenity.scene import load  # noqa: E402

LUMA = np.array([0.2126, 0.7152, 0.0722])


def ratio(a: float, b: float) -> float | None:
    """a / b, or None where b is (nearly) zero (no such light on that region: the Cornell box's
    ceiling gets no direct sun)."""
    return a / b if abs(b) > 1e-3 else None


def fmt(x: float | None, spec: str = ".3f") -> str:
    return "—" if x is None else format(x, spec)


def mitsuba(scene, w: int, h: int, spp: int, max_depth: int, sun: bool, sky: bool) -> np.ndarray:
    """Mitsuba render of ``scene`` with only the emitters asked for (sun sphere, sky map): the
    references' own export (``load_mitsuba_scene``, sun calibrated), without the sun sphere when
    ``sun`` is False."""
    mi = R.mitsuba()
    sky_map = R.sky_map(scene) if sky else None
    if sun:
        ms = R.load_mitsuba_scene(scene, w, h, max_depth, sky=sky_map)
    else:
        d = R.mitsuba_scene_dict(scene, w, h, max_depth, sky_map)
        d.pop("sun", None)
        ms = mi.load_dict(d)
    return np.array(mi.render(ms, spp=spp, seed=0))[..., :3]


def ours(scene_name: str, w: int, h: int, config: RenderConfig):
    """(full frame, frame without the LPV), each the second frame of a fresh renderer."""
    out = []
    for cfg in (config, dataclasses.replace(config, lpv=dataclasses.replace(config.lpv, enabled=False))):
        r = Renderer(load(scene_name), w, h, config=cfg)
        r.render(read_back=False)
        out.append(r.render(read_back=("hdr", "aovs")))
        r.close()
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--preset", default="medium")
    ap.add_argument("--size", default="320x180")
    ap.add_argument("--spp", type=int, default=256, help="samples per pixel of the split Mitsuba renders")
    ap.add_argument("--json", default=os.path.join(ROOT, "benchmarks", "results", "indirect_split.json"))
    args = ap.parse_args(argv)
    w, h = (int(x) for x in args.size.lower().split("x"))
    t_start = time.perf_counter()
    config = RenderConfig.preset(args.preset)
    scenes = {}
    for name in ("courtyard", "cornell"):
        scene = load(name)
        print(f"{name}: our frames", flush=True)
        full, nolpv = ours(name, w, h, config)
        print(f"{name}: Mitsuba references (full and one-bounce cached; sun-only and sky-only at {args.spp} spp)",
              flush=True)
        ref = {"full": R.render_reference(scene, w, h, spp=1024, component="full", progress=False)[..., :3],
               "one_bounce": R.render_reference(scene, w, h, spp=1024, component="one-bounce",
                                                progress=False)[..., :3],
               "sun_direct": mitsuba(scene, w, h, args.spp, 2, sun=True, sky=False)}
        has_sky = R.sky_map(scene) is not None
        if has_sky:
            ref["sky_direct"] = mitsuba(scene, w, h, args.spp, 2, sun=False, sky=True)
            ref["sky_all"] = mitsuba(scene, w, h, args.spp, -1, sun=False, sky=True)
        direct = full.aovs["direct"]
        terms = {"ours_direct": direct, "ours_sky": nolpv.hdr - direct, "ours_lpv": full.hdr - nolpv.hdr,
                 **{f"ref_{k}": v for k, v in ref.items()}}
        covered = full.aovs["material"][..., 0] >= 0
        traced = full.aovs["rt_mask"][..., 0] > 0 if "rt_mask" in full.aovs else np.zeros_like(covered)
        ny = full.aovs["normal"][..., 1]
        regions = {"vertical": np.abs(ny) < 0.3, "up-facing": ny > 0.7, "down-facing": ny < -0.7}
        rows = {}
        for region, sel in regions.items():
            m = covered & ~traced & sel
            mean = {k: float((v[m] @ LUMA).mean()) if m.any() else float("nan") for k, v in terms.items()}
            ours_ind = mean["ours_sky"] + mean["ours_lpv"]
            ref_ind = mean["ref_full"] - mean["ref_sun_direct"]
            ref_first = mean["ref_one_bounce"] - mean["ref_sun_direct"]
            row = {"pixels": int(m.sum()), "mean_luminance": mean,
                   "direct_ours_over_ref": ratio(mean["ours_direct"], mean["ref_sun_direct"]),
                   "indirect_ours_over_ref": ratio(ours_ind, ref_ind),
                   "indirect_ours_over_ref_first_bounce": ratio(ours_ind, ref_first),
                   "multi_bounce_share_of_ref_indirect": ratio(ref_ind - ref_first, ref_ind)}
            if has_sky:
                row["sky_ours_over_ref_sky_direct"] = ratio(mean["ours_sky"], mean["ref_sky_direct"])
            rows[region] = row
            print(f"  {region:12s} {m.sum():6d} px  direct ours/ref {fmt(row['direct_ours_over_ref'])}  indirect "
                  f"ours/ref {fmt(row['indirect_ours_over_ref'])}, ours/first bounce "
                  f"{fmt(row['indirect_ours_over_ref_first_bounce'])}  (multi-bounce "
                  f"{fmt(row['multi_bounce_share_of_ref_indirect'], '.0%')} of the reference's)"
                  + (f"  sky ours/ref sky direct {fmt(row['sky_ours_over_ref_sky_direct'])}" if has_sky else ""),
                  flush=True)
        scenes[name] = rows
    write_results(args.json, {
        "benchmark": "indirect_split", "preset": args.preset, "size": [w, h], "spp": args.spp,
        "command": "python benchmarks/bench_indirect_split.py" + (f" {' '.join(argv)}" if argv else ""),
        "regions": {"vertical": "|n_y| < 0.3", "up-facing": "n_y > 0.7", "down-facing": "n_y < -0.7"},
        "scenes": scenes, "seconds": time.perf_counter() - t_start})
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""What spreading the volumes' updates over frames costs in accuracy and buys in time.

Two amortisations of the ``lpv-fast`` and ``traced-probes`` presets, each measured alone and together:

- the sky volume's transfer re-lights ``SkyConfig.transfer_layers`` y-layers per frame after a
  rebake of the sky map, in a continuous cycle, and only those layers are uploaded (0: every probe
  each time, the ``lpv`` preset);
- the LPV re-injects and propagates one cascade per update, in turn (``LPVConfig.stagger``).

This runs the frame benchmark's path (camera orbiting, the sun moving ~0.9° per frame, so the sky
map is rebaked and the LPV's inputs change every frame: the worst case for both) with one renderer
per setting, interleaved frame by frame so that a shared machine's load falls on all alike, and
reports per setting the median ms of the sky stage ("sky volume update" + "sky upload"), of the
LPV update (RSM, inputs, inject, propagate, upload) and of the frame, and how far each frame's HDR
image is from the image of the setting that updates everything every frame (relMSE, FLIP): the
error that the stale layers and cascades add. At ``--reference-frames`` (320×180 only, by default)
each variant's image is also compared with a Mitsuba path-traced reference of that frame's camera
and sun (``--ref-spp``, cached), which says whether the lag makes the image further from the truth
or only different.

    python benchmarks/bench_amortise.py [--json benchmarks/results/amortise.json]
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import os
import sys
import time

import numpy as np
from tqdm import tqdm

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from serenity.bench import camera_path, sun_path  # noqa: E402
from serenity.config import RenderConfig  # noqa: E402
from serenity.eval import metrics  # noqa: E402
from serenity.eval.reference import render_reference  # noqa: E402
from serenity.frame import LPV_UPDATE_STAGES, SKY_UPDATE_STAGES, Renderer  # noqa: E402
from serenity.io.results import write_results  # noqa: E402
from serenity.optional import pyplot  # noqa: E402
from serenity.scene import load  # noqa: E402

#: name → (SkyConfig.transfer_layers, LPVConfig.stagger); the first is the baseline
VARIANTS = {
    "every frame": (0, False),
    "sky: 1 layer per frame": (1, False),
    "LPV: 1 cascade per frame": (0, True),
    "both (lpv-fast)": (1, True),
}


def run_size(base, w: int, h: int, quality: str, frames: int, ref_frames=(), ref_spp: int = 256) -> dict:
    """The variants at one size, interleaved frame by frame (module doc)."""
    base_cam, base_sun = base.camera, base.sun.direction.copy()
    preset = RenderConfig.preset(quality)
    scenes, renderers = [], []
    for layers, stagger in VARIANTS.values():
        s = copy.deepcopy(base)
        cfg = dataclasses.replace(preset, sky=dataclasses.replace(preset.sky, transfer_layers=layers),
                                  lpv=dataclasses.replace(preset.lpv, stagger=stagger))
        scenes.append(s)
        renderers.append(Renderer(s, w, h, config=cfg))
    names = list(VARIANTS)
    ms = {n: {"sky": [], "lpv": [], "frame": []} for n in names}
    errors = {n: [] for n in names[1:]}
    vs_ref = {n: [] for n in names}
    for i in tqdm(range(frames), desc=f"amortise {base.name} {w}x{h}", unit="frame"):
        t = i / max(1, frames - 1)
        images = {}
        for n, s, r in zip(names, scenes, renderers, strict=True):
            s.camera = camera_path(base_cam, t)
            s.sun.direction = sun_path(base_sun, t)
            f = r.render(read_back={"hdr"})
            images[n] = f.hdr
            ms[n]["sky"].append(sum(f.timings.get(k, 0.0) for k in SKY_UPDATE_STAGES))
            ms[n]["lpv"].append(sum(f.timings.get(k, 0.0) for k in LPV_UPDATE_STAGES))
            ms[n]["frame"].append(f.wall_ms)
        for n in names[1:]:
            errors[n].append({"frame": i, "rel_mse": metrics.rel_mse(images[n], images[names[0]]),
                              "flip": metrics.flip(images[n], images[names[0]])})
        if i in ref_frames:
            ref = render_reference(scenes[0], w, h, spp=ref_spp, component="full", seed=0, progress=False)
            for n in names:
                vs_ref[n].append({"frame": i, "rel_mse": metrics.rel_mse(images[n], ref),
                                  "flip": metrics.flip(images[n], ref)})
    y = renderers[0].sky_volume.resolution[1]
    cascades = len(renderers[0].lpv.fitted)
    for r in renderers:
        r.close()
    out = {"sky_layers": int(y), "lpv_cascades": int(cascades), "variants": {}}
    for n, (layers, stagger) in VARIANTS.items():
        # the first frame builds every volume whole in every variant: left out of the medians
        row = {"transfer_layers": layers, "lpv_stagger": stagger,
               "sky_stage_ms_median": float(np.median(ms[n]["sky"][1:])),
               "lpv_update_ms_median": float(np.median(ms[n]["lpv"][1:])),
               "frame_ms_median": float(np.median(ms[n]["frame"][1:])),
               "max_sky_layer_age_frames": -(-y // layers) if layers else 1,
               "max_lpv_cascade_age_frames": cascades if stagger else 1,
               "ms_per_frame": ms[n]}
        if n in errors:
            e = errors[n][1:]
            row.update({"rel_mse_vs_every_frame_mean": float(np.mean([x["rel_mse"] for x in e])),
                        "rel_mse_vs_every_frame_max": float(np.max([x["rel_mse"] for x in e])),
                        "flip_vs_every_frame_mean": float(np.mean([x["flip"] for x in e])),
                        "flip_vs_every_frame_max": float(np.max([x["flip"] for x in e])),
                        "per_frame": errors[n]})
        if vs_ref[n]:
            row.update({"vs_reference": vs_ref[n],
                        "flip_vs_reference_mean": float(np.mean([x["flip"] for x in vs_ref[n]])),
                        "rel_mse_vs_reference_mean": float(np.mean([x["rel_mse"] for x in vs_ref[n]]))})
        out["variants"][n] = row
        print(f"{w}x{h} {n}: sky stage {row['sky_stage_ms_median']:.2f} ms, LPV update "
              f"{row['lpv_update_ms_median']:.2f} ms, frame {row['frame_ms_median']:.1f} ms"
              + (f"; vs every frame: relMSE mean {row['rel_mse_vs_every_frame_mean']:.2e} max "
                 f"{row['rel_mse_vs_every_frame_max']:.2e}, FLIP mean {row['flip_vs_every_frame_mean']:.4f} "
                 f"max {row['flip_vs_every_frame_max']:.4f}" if n in errors else "")
              + (f"; vs the reference (frames {ref_frames}): FLIP {row['flip_vs_reference_mean']:.4f}, relMSE "
                 f"{row['rel_mse_vs_reference_mean']:.4f}" if vs_ref[n] else ""))
    return out


def chart(result: dict, path: str) -> None:
    """Per size: FLIP against updating everything every frame, frame by frame (left), and the
    median ms of the sky stage and the LPV update per variant (right)."""
    plt = pyplot("the amortisation chart")
    sizes = list(result["sizes"])
    fig, axes = plt.subplots(len(sizes), 2, figsize=(11, 3.4 * len(sizes)), squeeze=False)
    for row, size in zip(axes, sizes, strict=True):
        variants = result["sizes"][size]["variants"]
        for n, v in variants.items():
            if "per_frame" in v:
                pf = v["per_frame"]
                row[0].plot([x["frame"] for x in pf], [x["flip"] for x in pf], marker="o", ms=3, label=n)
        row[0].set_xlabel("frame (sun ~0.9° and camera moving every frame)")
        row[0].set_ylabel("FLIP vs every frame")
        row[0].set_title(f"{size}: what the stale layers and cascades cost", fontsize=10)
        row[0].set_ylim(0.0, 1.5 * row[0].get_ylim()[1])  # room above the curves for the legend
        row[0].legend(fontsize=8, loc="upper left")
        row[0].grid(alpha=0.3)
        names = list(variants)
        x = np.arange(len(names))
        row[1].bar(x - 0.2, [variants[n]["sky_stage_ms_median"] for n in names], 0.4, label="sky stage")
        row[1].bar(x + 0.2, [variants[n]["lpv_update_ms_median"] for n in names], 0.4, label="LPV update")
        row[1].set_xticks(x, [n.replace(": ", ":\n").replace(" (", "\n(") for n in names], fontsize=8)
        row[1].set_ylabel("ms (median)")
        row[1].set_title(f"{size}: what they buy", fontsize=10)
        row[1].set_ylim(0.0, 1.3 * row[1].get_ylim()[1])  # room above the bars for the legend
        row[1].legend(fontsize=8)
        refs = [(n, v) for n, v in variants.items() if "flip_vs_reference_mean" in v]
        if refs:
            frames_ref = ", ".join(str(x["frame"]) for x in refs[0][1]["vs_reference"])
            text = f"vs a path-traced reference\n(frames {frames_ref}), FLIP / relMSE:\n" + "\n".join(
                f"{n}: {v['flip_vs_reference_mean']:.3f} / {v['rel_mse_vs_reference_mean']:.3f}" for n, v in refs)
            row[1].set_ylim(0.0, 1.5 * row[1].get_ylim()[1])  # and for the box
            row[1].text(0.01, 0.98, text, transform=row[1].transAxes, ha="left", va="top", fontsize=7,
                        bbox={"facecolor": "white", "alpha": 0.85, "edgecolor": "0.7"})
        row[1].grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="courtyard")
    ap.add_argument("--sizes", default="320x180,640x360")
    ap.add_argument("--quality", default="lpv-fast")
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--reference-frames", default="6,12,18",
                    help="frames compared with a path-traced reference at the first size ('' = none)")
    ap.add_argument("--ref-spp", type=int, default=256)
    ap.add_argument("--json", default=os.path.join(ROOT, "benchmarks", "results", "amortise.json"))
    ap.add_argument("--chart", default=os.path.join(ROOT, "benchmarks", "results", "amortise.png"))
    args = ap.parse_args(argv)
    base = load(args.scene)
    t_start = time.perf_counter()
    out = {"benchmark": "amortise", "scene": args.scene, "quality": args.quality, "frames": args.frames,
           "sun_deg_per_frame": 20.0 / max(1, args.frames - 1), "sizes": {}}
    ref_frames = tuple(int(v) for v in args.reference_frames.split(",") if v.strip())
    out["ref_spp"] = args.ref_spp
    for k, size in enumerate(args.sizes.split(",")):
        w, h = (int(v) for v in size.lower().split("x"))
        out["sizes"][size] = run_size(base, w, h, args.quality, args.frames, ref_frames if k == 0 else (),
                                      args.ref_spp)
    out["seconds"] = time.perf_counter() - t_start
    write_results(args.json, out)
    if args.chart:
        chart(out, args.chart)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The accuracy baseline every GI technique must beat: error against the full Mitsuba 3
reference of (a) direct light only and (b) direct + the constant ambient term (irradiance π·L_sky on
every surface, SSAO applied — the classic hack the paper replaces), for ``courtyard`` and ``cornell``.

    python benchmarks/bench_baseline.py [--size 320x180] [--spp N] [--json FILE] [--chart-dir DIR]

The reference (``serenity.eval.reference``, ``component="full"``) is rendered as two halves with
different seeds (256 spp in all for the courtyard, 1024 for the Cornell box); their average is the
reference, and mean((a − b)²/4 / (ref² + ε)) — the variance of the average over the same denominator —
estimates how much of a relMSE figure is the reference's own noise ("ref_noise_rel_mse"). "rel_mse_downward" is
relMSE over the pixels whose normal points down (n.y < -0.5: ceilings, overhangs, the undersides the LPV's
sky-light VPLs are for, paper Fig. 11). "regions": the per-region / per-material report of
``serenity.eval.regions`` (FLIP, relMSE, their shares of the total and luminance ours/reference for
sky, up-/down-facing, vertical surfaces, edges and each material; printed for the full technique).
Metrics: relMSE (ε = 1e-2) on
linear HDR (also with the worst 0.1% of pixels left out: "rel_mse_trimmed", charted) and FLIP on the
tone-mapped images (our exposure, Reinhard, sRGB), over all pixels.
The last row is the ``traced-probes`` quality preset whole (beyond the paper: its sky volume's probes are lit
by rays traced through the scene, sky and bounces, instead of quads + LPV). Our frames use the
default ``RenderConfig`` otherwise (ray-traced reflections/refractions where the
renderer has them); ms = the median total of frames 2..N. References are cached, so a re-run
costs only our frames. Writes JSON and one speed-vs-error chart per scene.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import sys
import time

import numpy as np

from serenity.config import LPVConfig, RenderConfig, SkyConfig
from serenity.eval.charts import save_speed_accuracy_chart
from serenity.eval.metrics import REL_MSE_EPS, compare, rel_mse
from serenity.eval.reference import render_reference
from serenity.eval.regions import format_region_report, region_report
from serenity.frame import Renderer
from serenity.io.results import write_results
from serenity.scene import load

HERE = os.path.dirname(os.path.abspath(__file__))
#: scene → default reference spp: the Cornell box is lit through a 13 × 10 cm hole, so its indirect light
#: comes from a small bright patch and needs 4× the samples for a similar noise floor
SCENES = {"courtyard": 256, "cornell": 1024}
TRIM = 1e-3
"""Fraction of worst pixels left out of "rel_mse_trimmed" (one leaking pixel on a black reference pixel
gave the Cornell box relMSE 4.30; without the worst 0.1% it is 0.45)."""
#: the baselines (a), (b) and the paper's techniques added one at a time (all with ray tracing)
CONFIGS = {
    "direct only": {"ambient": "none", "sky": SkyConfig(enabled=False), "lpv": LPVConfig(enabled=False)},
    "direct + constant ambient": {"ambient": "constant", "sky": SkyConfig(enabled=False),
                                  "lpv": LPVConfig(enabled=False)},
    "direct + sky volume": {"lpv": LPVConfig(enabled=False)},
    "direct + sky volume + LPV (all)": {},
    # beyond the paper: the traced-probes preset, whose sky volume is lit by rays traced per probe (sky and every
    # bounce, ``SkyConfig.method = "gather"``) instead of occlusion quads + the LPV
    "gathered probes (traced-probes preset)": {"preset": "traced-probes"},
}


def _jsonable(cfg: dict) -> dict:
    """The row's RenderConfig overrides with config dataclasses (SkyConfig, LPVConfig) as dicts."""
    return {k: ({"type": type(v).__name__, **dataclasses.asdict(v)} if dataclasses.is_dataclass(v) else v)
            for k, v in cfg.items()}


def our_frame(scene, width, height, frames, preset=None, **config):
    cfg = RenderConfig.preset(preset, **config) if preset else RenderConfig(**config)
    renderer = Renderer(scene, width, height, config=cfg)
    totals, frame = [], None
    for _ in range(frames):
        frame = renderer.render()
        totals.append(frame.total_ms)
    return frame, float(np.median(totals[1:] if len(totals) > 1 else totals))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", default="320x180")
    p.add_argument("--spp", type=int, help="reference samples per pixel, two halves (default: per scene)")
    p.add_argument("--frames", type=int, default=4)
    p.add_argument("--json", default=os.path.join(HERE, "results", "baseline.json"))
    p.add_argument("--chart-dir", default=os.path.join(HERE, "results"))
    args = p.parse_args(argv)
    width, height = (int(x) for x in args.size.split("x"))

    results = []
    for name, default_spp in SCENES.items():
        half = max(1, (args.spp or default_spp) // 2)
        scene = load(name)
        t0 = time.perf_counter()
        ref_a = render_reference(scene, width, height, spp=half, component="full", seed=0)
        ref_b = render_reference(scene, width, height, spp=half, component="full", seed=1)
        ref_s = time.perf_counter() - t0
        ref = (ref_a + ref_b) / 2
        noise = float(np.mean((ref_a - ref_b) ** 2 / 4 / (ref * ref + REL_MSE_EPS)))
        print(f"{name}: reference {width}x{height}, {2 * half} spp full, {ref_s:.1f} s "
              f"(reference noise ~ relMSE {noise:.4f})", flush=True)
        points = []
        for label, cfg in CONFIGS.items():
            frame, ms = our_frame(scene, width, height, args.frames, **cfg)
            m = compare(frame.hdr, ref, exposure=frame.exposure)
            regions = region_report(frame.hdr, ref, frame.aovs["normal"], frame.aovs["depth"],
                                    frame.aovs["material"], [mat.name for mat in scene.materials],
                                    exposure=frame.exposure, fmap=m["flip_map"])
            trimmed = rel_mse(frame.hdr, ref, trim=TRIM)
            down = frame.aovs["normal"][..., 1] < -0.5  # ceilings, overhangs: lit only indirectly (paper Fig. 11)
            down_err = rel_mse(frame.hdr, ref, mask=down) if down.any() else None
            row = {"scene": name, "config": label, "render_config": _jsonable(cfg), "ms": ms, "rel_mse": m["rel_mse"],
                   "rel_mse_trimmed": trimmed, "rel_mse_downward": down_err, "downward_pixels": int(down.sum()),
                   "rel_mse_rgb": m["rel_mse_rgb"], "flip": m["flip"], "ref_noise_rel_mse": noise,
                   "ref_spp": 2 * half, "mean_ours": frame.hdr.reshape(-1, 3).mean(0).tolist(),
                   "mean_ref": ref.reshape(-1, 3).mean(0).tolist(), "regions": regions}
            results.append(row)
            points.append({"technique": label, "label": f"{label} ({name})", "ms": ms, "error": trimmed})
            print(f"  {label:<27} {ms:8.1f} ms  relMSE {m['rel_mse']:.4f} (0.1% trimmed {trimmed:.4f}, "
                  f"downward-facing px {down_err if down_err is None else round(down_err, 4)})"
                  f"  FLIP {m['flip']:.4f}", flush=True)
            if label in list(CONFIGS)[-2:]:
                print(format_region_report(regions), flush=True)
        chart = os.path.join(args.chart_dir, f"baseline_{name}.png")
        save_speed_accuracy_chart(points, chart, error_name="relMSE vs full reference (0.1% trimmed)",
                                  title=f"baseline, {name} {width}x{height}")
        print(f"  wrote {chart}")

    import mitsuba

    out = {
        "benchmark": "baseline",
        "machine": {"platform": platform.platform(), "processor": platform.processor(),
                    "cpus": os.cpu_count(), "python": sys.version.split()[0]},
        "reference": {"renderer": f"Mitsuba {mitsuba.__version__} scalar_rgb path", "component": "full",
                      "spp": {r["scene"]: r["ref_spp"] for r in results}},
        "size": [width, height],
        "ray_tracing": True,
        "metrics": {"rel_mse": "mean (ours-ref)^2/(ref^2+1e-2), linear HDR, all pixels, mean of RGB",
                    "rel_mse_trimmed": "the same without the 0.1% of pixels with the largest error",
                    "flip": "mean FLIP (LDR) after exposure + Reinhard + sRGB (reinhard_srgb), all pixels",
                    "regions": "serenity.eval.regions.region_report: per region/material flip, rel_mse, "
                               "*_share of the all-pixel sum, luminance_ratio = mean Y ours / mean Y ref"},
        "results": results,
    }
    write_results(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

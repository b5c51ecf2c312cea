"""Render a scene and measure it against a path-traced reference (Mitsuba 3): FLIP and relMSE.

    python examples/compare_with_reference.py [SCENE] [--size 160x90] [--spp 64] [--quality traced-probes]
                                              [-o OUT.png]

Needs the ``eval`` extra (``pip install 'serenity[eval]'``: Mitsuba 3, flip-evaluator, matplotlib).
SCENE is a built-in name (default: courtyard) or a scene/model file. Writes our frame, the
reference and the FLIP error map side by side. The defaults keep it to about a minute on a laptop;
a reference of 64 spp still holds some noise, which counts as error against us, so figures to
publish use a larger ``--spp`` (``benchmarks/bench_frontier.py`` uses 1024). The reference is cached
on disk (``SERENITY_CACHE``), so a second run only renders our frame.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

import serenity
from serenity.config import DEFAULT_QUALITY, QUALITY_PRESETS, RenderConfig
from serenity.eval.metrics import compare, flip_png, tonemap
from serenity.eval.reference import render_reference
from serenity.io.png import write_png


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Our frame against a Mitsuba 3 path-traced reference: FLIP and relMSE.")
    ap.add_argument("scene", nargs="?", default="courtyard", help="built-in scene name or a scene/model file")
    ap.add_argument("--size", default="160x90", help="WxH (default %(default)s)")
    ap.add_argument("--spp", type=int, default=64, help="reference samples per pixel (default %(default)s)")
    ap.add_argument("--quality", default=DEFAULT_QUALITY, choices=QUALITY_PRESETS, help="our quality preset")
    ap.add_argument("-o", "--output", default=os.path.join("serenity_out", "compare.png"), help="PNG path")
    args = ap.parse_args(argv)
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
        scene = serenity.load(args.scene)
        with serenity.Renderer(scene, width, height, config=RenderConfig.preset(args.quality)) as renderer:
            renderer.render()  # the first frame builds the volumes
            ours = renderer.render()
        reference = render_reference(scene, width, height, spp=args.spp)  # (H, W, 3) linear radiance
        metrics = compare(ours.hdr, reference, exposure=ours.exposure)
    except (serenity.SerenityError, ValueError) as e:
        print(f"compare_with_reference: error: {e}", file=sys.stderr)
        return 2
    print(f"{scene.name} {width}x{height}, {args.quality} against {args.spp} spp: "
          f"FLIP {metrics['flip']:.4f}, relMSE {metrics['rel_mse']:.4f}")
    ref_ldr = (tonemap(reference, ours.exposure) * 255.0 + 0.5).astype(np.uint8)
    os.makedirs(os.path.dirname(os.path.abspath(args.output)), exist_ok=True)
    write_png(args.output, np.concatenate([ours.ldr, ref_ldr, flip_png(metrics["flip_map"])], axis=1))
    print(f"wrote {args.output} (ours | reference | FLIP error)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

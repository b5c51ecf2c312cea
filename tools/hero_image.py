"""The README's first image: a Serenity frame beside its path-traced reference, same scene and camera.

    python tools/hero_image.py [--scene courtyard] [--size 480x270] [--spp 1024] [-o docs/hero.png]

Ours is the last of three frames of a still camera and sun with the default quality preset
(``config.DEFAULT_QUALITY``); the reference is Mitsuba 3's ``path`` integrator with unlimited depth
(``serenity.eval.reference.render_reference``, cached after its first render). Both go through the
same exposure, Reinhard tone map and sRGB encoding (``serenity.eval.metrics.tonemap``). The image
carries no figures: accuracy and cost live in docs/benchmarks.md, printed from result JSON.
Needs the ``eval`` extra (Mitsuba 3).
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np
from PIL import Image, ImageDraw

from serenity.commands.common import parse_size
from serenity.config import DEFAULT_QUALITY, RenderConfig
from serenity.errors import SerenityError
from serenity.eval.metrics import tonemap
from serenity.eval.reference import render_reference
from serenity.frame import Renderer
from serenity.scene import load

CAPTION_PX = 24
GAP_PX = 4


def render_ours(scene, width: int, height: int, frames: int = 3) -> np.ndarray:
    """(H, W, 3) float32 linear radiance: the last of ``frames`` renders with the default preset."""
    with Renderer(scene, width, height, config=RenderConfig.preset(DEFAULT_QUALITY)) as renderer:
        for _ in range(frames):
            frame = renderer.render()
    return frame.hdr


def side_by_side(left: np.ndarray, right: np.ndarray, captions: tuple[str, str]) -> Image.Image:
    """Two tone-mapped images next to each other, each with a caption strip underneath."""
    h, w = left.shape[:2]
    sheet = Image.new("RGB", (2 * w + GAP_PX, h + CAPTION_PX), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    for k, (img, text) in enumerate(zip((left, right), captions, strict=True)):
        x = k * (w + GAP_PX)
        sheet.paste(Image.fromarray((np.clip(img, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)), (x, 0))
        draw.text((x + 6, h + 6), text, fill=(20, 20, 20))
    return sheet


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="courtyard")
    p.add_argument("--size", default="480x270", help="WxH of each half (default 480x270)")
    p.add_argument("--spp", type=int, default=1024, help="reference samples per pixel (default 1024)")
    p.add_argument("-o", "--output", default=os.path.join("docs", "hero.png"))
    args = p.parse_args(argv)
    try:
        width, height = parse_size(args.size)
        scene = load(args.scene)
        ours = render_ours(scene, width, height)
        ref = render_reference(scene, width, height, spp=args.spp)
    except SerenityError as e:
        print(f"hero_image: error: {e}", file=sys.stderr)
        return 2
    sheet = side_by_side(tonemap(ours), tonemap(ref),
                         (f"Serenity, preset {DEFAULT_QUALITY} (real time)",
                          f"Mitsuba 3 path tracer, {args.spp} spp (reference)"))
    sheet.save(args.output, optimize=True)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

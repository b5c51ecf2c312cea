"""The courtyard at sunrise, noon and sunset side by side (paper Fig. 9), and constant ambient vs
the sky lighting volume (paper Fig. 8).

    python examples/time_of_day.py [OUT_DIR]        (default: serenity_out/)

Writes ``time_of_day.png`` (three times of one summer day in Lisbon: the sky map, the sun's colour
from the atmosphere's transmittance and the sky volume all follow the sun) and ``sky_vs_ambient.png``
(the same frame lit by a constant ambient term vs by the occluded sky irradiance volume).
"""

from __future__ import annotations

import os
import sys

import numpy as np
from PIL import Image, ImageDraw

from serenity.config import LPVConfig, RenderConfig, SkyConfig
from serenity.frame import Renderer
from serenity.io.png import write_png
from serenity.scene import load, sun_from_time

TIMES = {"sunrise 06:45": "2024-06-21 06:45 +01:00", "noon 13:30": "2024-06-21 13:30 +01:00",
         "sunset 20:40": "2024-06-21 20:40 +01:00"}


def panel_row(panels: list[tuple[str, np.ndarray]]) -> np.ndarray:
    h, w = panels[0][1].shape[:2]
    canvas = Image.new("RGB", (w * len(panels), h + 20), (255, 255, 255))
    draw = ImageDraw.Draw(canvas)
    for i, (label, img) in enumerate(panels):
        canvas.paste(Image.fromarray(img), (i * w, 20))
        draw.text((i * w + 6, 4), label, fill=(0, 0, 0))
    return np.asarray(canvas)


def main(argv: list[str]) -> int:
    out = argv[1] if len(argv) > 1 else "serenity_out"
    os.makedirs(out, exist_ok=True)
    size = (480, 270)
    panels = []
    for label, when in TIMES.items():
        scene = load("courtyard")
        lat, lon = scene.location
        scene.sun = sun_from_time(when, lat, lon)
        # exposure follows the light, as a camera's auto-exposure would (stated on the panel)
        exposure = 0.02 if scene.sun.elevation_deg > 20 else 0.08
        frame = Renderer(scene, *size, config=RenderConfig(exposure=exposure)).render()
        panels.append((f"{label}  sun {scene.sun.elevation_deg:.1f} deg  exposure {exposure}", frame.ldr))
        print(f"{label}: sun elevation {scene.sun.elevation_deg:.1f} deg, frame {frame.wall_ms:.0f} ms")
    write_png(os.path.join(out, "time_of_day.png"), panel_row(panels))
    scene = load("courtyard")
    pair = []
    no_lpv = LPVConfig(enabled=False)
    for label, cfg in (("constant ambient (pi * L_sky everywhere)",
                        RenderConfig(ambient="constant", sky=SkyConfig(enabled=False), lpv=no_lpv)),
                       ("sky lighting volume (occluded, paper §7)", RenderConfig(lpv=no_lpv))):
        pair.append((label, Renderer(scene, *size, config=cfg).render().ldr))
    write_png(os.path.join(out, "sky_vs_ambient.png"), panel_row(pair))
    print(f"wrote {out}/time_of_day.png and {out}/sky_vs_ambient.png")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

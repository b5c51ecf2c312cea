"""Render your own model: a glTF / GLB / OBJ / PLY file, or a scene TOML, to a PNG and a multi-layer EXR.

    python examples/render_your_model.py [MODEL] [--size 640x360] [-o OUT.png]

MODEL defaults to the breakfast room the repository ships (``scenes/breakfast_room/``, CC BY 3.0:
see CREDITS.md). A scene TOML brings its camera, sun and sky; a bare model file gets a camera that
frames its bounds and the default sun and sky. The frame uses the default quality preset, as
``serenity render`` does; the EXR holds the linear radiance ("beauty") and the AOVs.
"""

from __future__ import annotations

import argparse
import os
import sys

import serenity
from serenity.io.exr import write_exr
from serenity.io.png import write_png

BREAKFAST_ROOM = os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir, "scenes", "breakfast_room",
                              "breakfast_room.toml")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Render a glTF/OBJ/PLY model or scene TOML to PNG + EXR.")
    ap.add_argument("model", nargs="?", default=os.path.normpath(BREAKFAST_ROOM), help="model or scene file")
    ap.add_argument("--size", default="640x360", help="WxH (default %(default)s)")
    ap.add_argument("-o", "--output", default=os.path.join("serenity_out", "my_model.png"), help="PNG path")
    args = ap.parse_args(argv)
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
        scene = serenity.load(args.model)  # the file's camera, or one fitted to the model
        with serenity.Renderer(scene, width, height) as renderer:  # closed on leaving the block
            renderer.render()  # the first frame builds the volumes
            frame = renderer.render()
    except (serenity.SerenityError, ValueError) as e:
        print(f"render_your_model: error: {e}", file=sys.stderr)
        return 2
    os.makedirs(os.path.dirname(os.path.abspath(args.output)), exist_ok=True)
    exr = os.path.splitext(args.output)[0] + ".exr"
    write_png(args.output, frame.ldr)
    write_exr(exr, {"beauty": frame.hdr, **frame.aovs})
    print(f"{scene.name}: {scene.triangle_count} triangles, {width}x{height}, {frame.wall_ms:.0f} ms a frame")
    print(f"wrote {args.output} and {exr}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

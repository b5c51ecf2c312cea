"""``serenity render``: one scene to PNG + multi-layer EXR, with the per-stage timings."""

from __future__ import annotations

import os
import sys
import time

from serenity.commands.common import (
    DEFAULT_OUT_DIR,
    DEFAULT_SCENE,
    DEFAULT_SIZE,
    DEVICE_HELP,
    add_animation_argument,
    add_quality_argument,
    add_time_arguments,
    apply_animation,
    apply_time,
    make_parent_dir,
    parse_size,
    scene_stem,
)
from serenity.config import DEFAULT_EXPOSURE


def register(subparsers) -> None:
    r = subparsers.add_parser("render", help="render a scene to PNG + multi-layer EXR and print per-stage timings")
    r.add_argument("scene", nargs="?", default=DEFAULT_SCENE, help="built-in scene name or a scene/mesh file")
    r.add_argument("-o", "--output", help=f"PNG path (default {DEFAULT_OUT_DIR}/<scene>.png)")
    r.add_argument("--exr", help="EXR path (default: beside the PNG)")
    r.add_argument("--size", default=f"{DEFAULT_SIZE[0]}x{DEFAULT_SIZE[1]}", help="WxH (default %(default)s)")
    add_time_arguments(r)
    add_animation_argument(r)
    add_quality_argument(r)
    r.add_argument("--device", help=DEVICE_HELP)
    r.add_argument("--exposure", type=float, default=DEFAULT_EXPOSURE,
                   help="exposure before Reinhard (default %(default)s)")
    r.add_argument("--ambient", choices=("none", "constant"), default="none",
                   help="constant ambient baseline term (default %(default)s)")
    r.add_argument("--serial", action="store_true",
                   help="trace rays before the GL work instead of beside it (paper §10's comparison)")
    r.add_argument("--frames", type=int, default=2,
                   help="frames to render; timings are those of the last (default %(default)s)")
    r.add_argument("--json", help="also write what it printed (scene, size, per-stage ms, frame ms) to this JSON file")
    r.set_defaults(func=run)


def format_report(report: dict) -> str:
    """What ``serenity render`` prints, from the dict its ``--json`` writes (so that a document can
    print a recorded run exactly as the command printed it: ``tools/doc_tables.py``, render-output)."""
    from serenity.frame import format_timings

    (w, h), sun = report["size"], report["sun"]
    return "\n".join([
        f"scene {report['scene']}: {report['triangles']} triangles, {w}x{h}, device {report['device']}, "
        f"sun elevation {sun['elevation_deg']:.1f} deg azimuth {sun['azimuth_deg']:.1f} deg",
        f"quality {report['quality']}; loaded in {report['load_ms']:.0f} ms",
        format_timings(report["stages_ms"], report["frame_ms"]),
        f"wrote {report['png']}",
        f"wrote {report['exr']} (layers: {', '.join(report['layers'])})"])


def run(args) -> int:
    from serenity.config import RenderConfig, ScheduleConfig
    from serenity.frame import Renderer
    from serenity.io.exr import write_exr
    from serenity.io.png import write_png
    from serenity.scene import load

    width, height = parse_size(args.size)
    t0 = time.perf_counter()
    scene = apply_animation(load(args.scene), args)
    apply_time(scene, args)
    load_ms = (time.perf_counter() - t0) * 1e3
    png = args.output or os.path.join(DEFAULT_OUT_DIR, f"{scene_stem(args.scene)}.png")
    exr = args.exr or os.path.splitext(png)[0] + ".exr"
    config = RenderConfig.preset(args.quality, exposure=args.exposure, ambient=args.ambient,
                                 schedule=ScheduleConfig(overlap=not args.serial))
    frame = None
    with Renderer(scene, width, height, device=args.device, config=config) as renderer:
        for _ in range(max(1, args.frames)):
            frame = renderer.render()
    for path in (png, exr):
        make_parent_dir(path)
    write_png(png, frame.ldr)
    layers = {"beauty": frame.hdr, **frame.aovs}
    write_exr(exr, layers)
    sun = scene.sun
    report = {
        "arguments": {k: v for k, v in vars(args).items() if k != "func"}, "scene": scene.name,
        "triangles": int(scene.triangle_count), "size": [width, height], "device": str(renderer.device),
        "quality": args.quality, "frames": max(1, args.frames), "load_ms": load_ms,
        "sun": {"elevation_deg": float(sun.elevation_deg), "azimuth_deg": float(sun.azimuth_deg)},
        "stages_ms": {k: float(v) for k, v in frame.timings.items()}, "frame_ms": float(frame.wall_ms),
        "nonfinite_pixels": int(frame.nonfinite_pixels), "png": png, "exr": exr, "layers": list(layers)}
    print(format_report(report))
    if frame.nonfinite_pixels:  # counted by the tone-mapping pass (Frame.nonfinite_pixels)
        print(f"serenity: warning: {frame.nonfinite_pixels} of {width * height} pixels are NaN or infinite "
              f"(the EXR keeps them as they are)", file=sys.stderr)
    if args.json:
        from serenity.io.results import write_results

        write_results(args.json, report)
    return 0

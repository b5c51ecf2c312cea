"""`serenity` command line: render | scenes | reference | compare (| bench | chart as they land).

Every user-facing failure is a ``SerenityError``: printed as one line ``serenity: error: ...`` on
stderr with exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from serenity.errors import SerenityError
from serenity.view.command import register as register_view

DEFAULT_SCENE = "courtyard"
DEFAULT_SIZE = (640, 360)
DEFAULT_OUT_DIR = "serenity_out"
#: where a scene without a location is assumed to be (Lisbon, the paper's home), degrees
DEFAULT_LOCATION = (38.72, -9.14)


def parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise SerenityError(f"--size must look like 640x360, got {text!r}") from None
    if not (1 <= w <= 8192 and 1 <= h <= 8192):
        raise SerenityError(f"--size must be within 1..8192 per side, got {text!r}")
    return w, h


def _apply_time(scene, args) -> None:
    from serenity.scene.sun import parse_time, sun_from_time

    when = parse_time(args.time)
    lat, lon = getattr(scene, "location", None) or DEFAULT_LOCATION
    lat = args.lat if args.lat is not None else lat
    lon = args.lon if args.lon is not None else lon
    old = scene.sun
    new = sun_from_time(when, lat, lon)
    new.angular_diameter_deg = old.angular_diameter_deg
    scene.sun = new


def cmd_render(args) -> int:
    from serenity.config import RenderConfig
    from serenity.frame import Renderer, format_timings
    from serenity.io.exr import write_exr
    from serenity.io.png import write_png
    from serenity.scene import load

    width, height = parse_size(args.size)
    t0 = time.perf_counter()
    scene = load(args.scene)
    if args.time:
        _apply_time(scene, args)
    elif args.lat is not None or args.lon is not None:
        raise SerenityError("--lat/--lon need --time")
    load_ms = (time.perf_counter() - t0) * 1e3
    stem = os.path.splitext(os.path.basename(args.scene))[0] if os.path.exists(args.scene) else args.scene
    png = args.output or os.path.join(DEFAULT_OUT_DIR, f"{stem}.png")
    exr = args.exr or os.path.splitext(png)[0] + ".exr"
    config = RenderConfig(exposure=args.exposure, ambient=args.ambient, overlap=not args.serial)
    renderer = Renderer(scene, width, height, device=args.device, config=config)
    frame = None
    for _ in range(max(1, args.frames)):
        frame = renderer.render()
    for path in (png, exr):
        d = os.path.dirname(os.path.abspath(path))
        os.makedirs(d, exist_ok=True)
    write_png(png, frame.ldr)
    layers = {"beauty": frame.hdr, **frame.aovs}
    write_exr(exr, layers)
    sun = scene.sun
    print(f"scene {scene.name}: {scene.triangle_count} triangles, {width}x{height}, device {renderer.device}, "
          f"sun elevation {sun.elevation_deg:.1f} deg azimuth {sun.azimuth_deg:.1f} deg")
    print(f"loaded in {load_ms:.0f} ms")
    print(format_timings(frame.timings, frame.wall_ms))
    print(f"wrote {png}")
    print(f"wrote {exr} (layers: {', '.join(layers)})")
    return 0


def cmd_scenes(args) -> int:
    from serenity.scene.procedural import scene_descriptions

    for name, desc in scene_descriptions().items():
        print(f"{name:<12} {desc}")
    return 0


def cmd_bench(args) -> int:
    from serenity.bench import bench

    width, height = parse_size(args.size)
    if args.frames < 2:
        raise SerenityError("--frames must be at least 2 (the first frame builds and uploads)")
    bench(args.scene, width, height, args.frames, args.device, args.json, args.chart)
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="serenity", description="Real-time GI by rasterisation + ray tracing")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("render", help="render a scene to PNG + multi-layer EXR and print per-stage timings")
    r.add_argument("scene", nargs="?", default=DEFAULT_SCENE, help="built-in scene name or a scene/mesh file")
    r.add_argument("-o", "--output", help=f"PNG path (default {DEFAULT_OUT_DIR}/<scene>.png)")
    r.add_argument("--exr", help="EXR path (default: beside the PNG)")
    r.add_argument("--size", default=f"{DEFAULT_SIZE[0]}x{DEFAULT_SIZE[1]}", help="WxH (default %(default)s)")
    r.add_argument("--time", help='local time "YYYY-MM-DD HH:MM[ +HH:MM]" for the sun position')
    r.add_argument("--lat", type=float, help="latitude in degrees (with --time)")
    r.add_argument("--lon", type=float, help="longitude in degrees, east positive (with --time)")
    r.add_argument("--device", help="cpu | cuda:0 (default: cuda:0 when present, else cpu)")
    r.add_argument("--exposure", type=float, default=0.02, help="exposure before Reinhard (default %(default)s)")
    r.add_argument("--ambient", choices=("none", "constant"), default="none",
                   help="constant ambient baseline term (default %(default)s)")
    r.add_argument("--serial", action="store_true",
                   help="trace rays before the GL work instead of beside it (paper §10's comparison)")
    r.add_argument("--frames", type=int, default=2,
                   help="frames to render; timings are those of the last (default %(default)s)")
    r.set_defaults(func=cmd_render)

    s = sub.add_parser("scenes", help="list the built-in scenes")
    s.set_defaults(func=cmd_scenes)

    b = sub.add_parser("bench", help="frame benchmark: Table-1-style stage timings, overlapped vs serial, "
                                     "timeline chart, memory")
    b.add_argument("scene", nargs="?", default=DEFAULT_SCENE)
    b.add_argument("--frames", type=int, default=30, help="frames per schedule (default %(default)s)")
    b.add_argument("--size", default=f"{DEFAULT_SIZE[0]}x{DEFAULT_SIZE[1]}", help="WxH (default %(default)s)")
    b.add_argument("--device", help="cpu | cuda:0")
    b.add_argument("--json", default=os.path.join(DEFAULT_OUT_DIR, "bench.json"), help="JSON output path")
    b.add_argument("--chart", default=os.path.join(DEFAULT_OUT_DIR, "timeline.png"), help="timeline PNG path")
    b.set_defaults(func=cmd_bench)

    register_view(sub)

    try:
        from serenity.eval.commands import add_subcommands
    except ImportError:
        pass
    else:
        add_subcommands(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except SerenityError as e:
        print(f"serenity: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("serenity: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

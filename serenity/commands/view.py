"""``serenity view``: the interactive viewer (:mod:`serenity.view`). Needs the ``view`` extra
(moderngl-window, glfw, imgui-bundle); without it the command says what to install."""

from __future__ import annotations

import os

from serenity.commands.common import (
    DEFAULT_OUT_DIR,
    DEFAULT_SCENE,
    DEFAULT_SIZE,
    DEVICE_HELP,
    add_quality_argument,
    parse_size,
)
from serenity.config import DEFAULT_EXPOSURE
from serenity.errors import SerenityError
from serenity.view import TAA_SAMPLES


def register(subparsers) -> None:
    v = subparsers.add_parser("view", help="interactive viewer: fly camera, live sun and technique switches, "
                                           "AOVs, stage timings, reference comparison (needs serenity[view])")
    v.add_argument("scene", nargs="?", default=DEFAULT_SCENE, help="built-in scene name or a scene/mesh file")
    v.add_argument("--size", default=f"{DEFAULT_SIZE[0]}x{DEFAULT_SIZE[1]}",
                   help="render size WxH (default %(default)s); the window opens at this size")
    add_quality_argument(v)
    v.add_argument("--device", help=DEVICE_HELP)
    v.add_argument("--exposure", type=float, default=DEFAULT_EXPOSURE,
                   help="exposure before Reinhard (default %(default)s)")
    v.add_argument("--script", help="TOML file of timed input steps (see serenity/view/script.py)")
    v.add_argument("--screenshot", help="write the window as a PNG when the run ends (--exit-after or the "
                                        "script's end)")
    v.add_argument("--exit-after", type=int, help="quit after this many frames")
    v.add_argument("--trace", help="write a JSON log of every frame (camera, sun, stage timings, convergence)")
    v.add_argument("--no-panel", action="store_true", help="start with the panel hidden (F1 toggles it)")
    v.add_argument("--out-dir", default=os.path.join(DEFAULT_OUT_DIR, "view"),
                   help="where F12 writes PNG + EXR + TOML (default %(default)s)")
    v.add_argument("--spp", type=int, default=64, help="samples per pixel of the reference (R; default %(default)s)")
    v.add_argument("--taa", type=int, default=TAA_SAMPLES, metavar="N",
                   help="jittered frames a still view accumulates until it is converged (default %(default)s; "
                        "0 or 1: no temporal anti-aliasing)")
    v.set_defaults(func=run)


def run(args) -> int:
    from serenity.scene import load
    from serenity.view.controls import Settings, quality_config
    from serenity.view.script import load_script

    width, height = parse_size(args.size)
    quality_config(args.quality)  # an unknown preset fails before a window opens
    if args.exit_after is not None and args.exit_after < 1:
        raise SerenityError(f"--exit-after must be at least 1, got {args.exit_after}")
    if not 0 <= args.taa <= 1024:
        raise SerenityError(f"--taa must be in 0..1024 samples, got {args.taa}")
    if args.spp < 1:
        raise SerenityError(f"--spp must be at least 1, got {args.spp}")
    if args.screenshot and not args.screenshot.lower().endswith(".png"):
        raise SerenityError(f"--screenshot must be a .png path, got {args.screenshot!r}")
    script = load_script(args.script) if args.script else None
    scene = load(args.scene)
    settings = Settings(quality=args.quality, exposure=args.exposure)
    settings.config()

    from serenity.view.app import Viewer  # the window, GL and the panel: after the arguments are checked

    viewer = Viewer(scene, width, height, settings, device=args.device, script=script, screenshot=args.screenshot,
                    exit_after=args.exit_after, trace=args.trace, panel=not args.no_panel, out_dir=args.out_dir,
                    spp=args.spp, taa_samples=args.taa)
    return viewer.run()

"""What several ``serenity`` subcommands share: defaults, ``--size`` parsing, placing the sun from
``--time``/``--lat``/``--lon``, posing an animation at ``--at``, output paths, and the one-line
error report."""

from __future__ import annotations

import math
import os
import sys

from serenity.config import DEFAULT_QUALITY, PRESET_ALIASES, QUALITY_PRESETS, check_image_size, preset_name
from serenity.errors import SerenityError

DEFAULT_SCENE = "courtyard"
DEFAULT_SIZE = (640, 360)
#: --device help, shared by render, view and bench
DEVICE_HELP = "Warp device (default: cuda:0 where there is a GPU, else cpu; SERENITY_DEVICE overrides)"
DEFAULT_OUT_DIR = "serenity_out"


def parse_size(text: str) -> tuple[int, int]:
    """``"640x360"`` → (640, 360); a malformed or out-of-range size is a one-line ``SerenityError``."""
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise SerenityError(f"--size must look like 640x360, got {text!r}") from None
    return check_image_size(w, h, what="--size")


def add_time_arguments(parser) -> None:
    """``--time``, ``--lat``, ``--lon``: the sun of a local time at a place (see :func:`apply_time`)."""
    parser.add_argument("--time", help='local time "YYYY-MM-DD HH:MM[ +HH:MM]" for the sun position')
    parser.add_argument("--lat", type=float, help="latitude in degrees (with --time)")
    parser.add_argument("--lon", type=float, help="longitude in degrees, east positive (with --time)")


def apply_time(scene, args) -> None:
    """Move ``scene``'s sun to ``args.time`` at (``args.lat``, ``args.lon``), each defaulting to the
    scene's location or :data:`~serenity.scene.sun.DEFAULT_LOCATION`; the sun's angular size is kept.
    ``--lat``/``--lon`` without ``--time`` is an error."""
    if not args.time:
        if args.lat is not None or args.lon is not None:
            raise SerenityError("--lat/--lon need --time")
        return
    from serenity.scene.sun import DEFAULT_LOCATION, parse_time, sun_from_time

    when = parse_time(args.time)
    lat, lon = getattr(scene, "location", None) or DEFAULT_LOCATION
    lat = args.lat if args.lat is not None else lat
    lon = args.lon if args.lon is not None else lon
    old = scene.sun
    new = sun_from_time(when, lat, lon)
    new.angular_diameter_deg = old.angular_diameter_deg
    scene.sun = new


def add_animation_argument(parser) -> None:
    """``--at``: the scene's animated meshes posed at a time (see :func:`apply_animation`)."""
    parser.add_argument("--at", type=float, metavar="SECONDS",
                        help="animation time in seconds: the meshes a scene file's [[animation]] moves, posed then")


def apply_animation(scene, args):
    """``scene`` posed at ``args.at`` seconds (``serenity.scene.animation.pose_scene``); the scene as
    it is without ``--at``. ``--at`` on a scene without an animation, or not finite, is an error."""
    if args.at is None:
        return scene
    if not math.isfinite(args.at):
        raise SerenityError(f"--at must be a finite number of seconds, got {args.at}")
    if scene.animation is None:
        raise SerenityError(f"--at: scene {scene.name!r} has no animation (a scene file's [[animation]] tables)")
    from serenity.scene.animation import pose_scene

    return pose_scene(scene, args.at)


def scene_stem(name: str) -> str:
    """A file name stem for outputs of scene ``name``: a file's base name without extension, or a
    built-in scene's name."""
    return os.path.splitext(os.path.basename(name))[0] if os.path.exists(name) else name


def make_parent_dir(path: str) -> None:
    """Create the folder ``path`` will be written in."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)


def report_error(error: BaseException) -> int:
    """Print ``error`` as the one line ``serenity: error: ...`` on stderr; the exit status (2)."""
    print(f"serenity: error: {error}", file=sys.stderr)
    return 2


def quality_argument(text: str) -> str:
    """``--quality``'s type: a former preset name becomes its current one (``preset_name``, with its
    one-line warning); any other text is left for ``choices`` to accept or refuse."""
    return preset_name(text) if text in PRESET_ALIASES else text


def add_quality_argument(parser, default: str = DEFAULT_QUALITY) -> None:
    """``--quality`` (a ``RenderConfig.preset`` name; the former names low, medium and high still work)."""
    parser.add_argument("--quality", type=quality_argument, choices=QUALITY_PRESETS, default=default,
                        help="quality preset (default %(default)s: probes lit by traced rays; 'lpv' and "
                             "'lpv-fast': the paper's light propagation volumes; 'paper': the paper's settings)")

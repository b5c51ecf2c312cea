"""``serenity bench``: the frame benchmark (:mod:`serenity.bench`): Table-1-style stage timings,
overlapped vs serial, the timeline chart and memory."""

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
from serenity.errors import SerenityError


def register(subparsers) -> None:
    b = subparsers.add_parser("bench", help="frame benchmark: Table-1-style stage timings, overlapped vs serial, "
                                            "timeline chart, memory")
    b.add_argument("scene", nargs="?", default=DEFAULT_SCENE)
    b.add_argument("--frames", type=int, default=30, help="frames per schedule (default %(default)s)")
    b.add_argument("--size", default=f"{DEFAULT_SIZE[0]}x{DEFAULT_SIZE[1]}", help="WxH (default %(default)s)")
    b.add_argument("--device", help=DEVICE_HELP)
    add_quality_argument(b)
    b.add_argument("--json", default=os.path.join(DEFAULT_OUT_DIR, "bench.json"), help="JSON output path")
    b.add_argument("--chart", default=os.path.join(DEFAULT_OUT_DIR, "timeline.png"), help="timeline PNG path")
    b.set_defaults(func=run)


def run(args) -> int:
    from serenity.bench import bench

    width, height = parse_size(args.size)
    if args.frames < 2:
        raise SerenityError("--frames must be at least 2 (the first frame builds and uploads)")
    bench(args.scene, width, height, args.frames, args.device, args.json, args.chart, quality=args.quality)
    return 0

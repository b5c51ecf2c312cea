"""``serenity reference``: path-trace a Mitsuba 3 reference of a scene to an EXR.

    serenity reference courtyard --spp 256 --size 320x180 --component full -o ref.exr

An even spp renders two independent halves and prints their noise floor (FLIP and relMSE between
them, ``serenity.eval.reference.reference_with_floor``); the EXR is their mean.

Needs the ``eval`` extra (Mitsuba 3); without it the command says so in one line.
"""

from __future__ import annotations

import os
import time

from serenity.commands.common import (
    DEFAULT_OUT_DIR,
    add_animation_argument,
    apply_animation,
    make_parent_dir,
    parse_size,
    scene_stem,
)
from serenity.errors import SerenityError


def register(subparsers) -> None:
    r = subparsers.add_parser("reference", help="path-trace a Mitsuba 3 reference of a scene to an EXR "
                                                "(needs serenity[eval])")
    r.add_argument("scene", help="built-in scene name or a scene/mesh file")
    r.add_argument("-o", "--output", help=f"EXR path (default {DEFAULT_OUT_DIR}/<scene>_ref.exr)")
    r.add_argument("--size", default="320x180", help="WxH (default %(default)s)")
    r.add_argument("--spp", type=int, default=64, help="samples per pixel (default %(default)s)")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--component", default="full",
                   help="direct (depth 2) | one-bounce (3) | full | indirect = full - direct (default %(default)s)")
    g.add_argument("--depth", type=int, help="path integrator max depth instead (-1 = unlimited; 2 = direct)")
    r.add_argument("--seed", type=int, default=0, help="sampler seed (default %(default)s)")
    add_animation_argument(r)
    r.add_argument("--no-cache", action="store_true", help="render even if a cached result exists")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=run)


def run(args) -> int:
    from serenity.eval.reference import COMPONENTS, reference_with_floor, render_reference
    from serenity.io.exr import write_exr
    from serenity.scene import load

    if args.component not in COMPONENTS:
        raise SerenityError(f"--component must be one of {', '.join(COMPONENTS)}, got {args.component!r}")
    width, height = parse_size(args.size)
    scene = apply_animation(load(args.scene), args)
    out = args.output or os.path.join(DEFAULT_OUT_DIR, f"{scene_stem(args.scene)}_ref.exr")
    t0 = time.perf_counter()
    info: dict = {}
    kw = dict(component=args.component, seed=args.seed, max_depth=args.depth, cache=not args.no_cache,
              progress=not args.quiet)
    floor = None
    if args.spp >= 2 and args.spp % 2 == 0:
        ref = reference_with_floor(scene, width, height, spp=args.spp, **kw)
        img, floor, info["cached"] = ref.image, ref.floor, ref.cached
    else:
        img = render_reference(scene, width, height, spp=args.spp, info=info, **kw)
    secs = time.perf_counter() - t0
    make_parent_dir(out)
    write_exr(out, {"beauty": img})
    what = f"max depth {args.depth}" if args.depth is not None else f"component {args.component}"
    print(f"reference {scene.name}: {width}x{height}, {args.spp} spp, {what}, {secs:.1f} s"
          f"{' (from the cache)' if info['cached'] else ''}")
    print(f"mean radiance {img.reshape(-1, 3).mean(0).round(3).tolist()} W/m^2/sr")
    if floor is not None:
        print(f"noise floor (two halves of {args.spp // 2} spp): FLIP {floor['flip']:.4f}, "
              f"relMSE {floor['rel_mse']:.4g}")
    else:
        print("noise floor: not measured (needs an even spp: two halves)")
    print(f"wrote {out}")
    return 0

"""``serenity reference`` and ``serenity compare`` (added to the CLI by :func:`add_subcommands`).

    serenity reference courtyard --spp 256 --size 320x180 --component full -o ref.exr
    serenity compare ours.exr ref.exr --mask mask.png -o flip.png
"""

from __future__ import annotations

import os
import time

import numpy as np

from serenity.errors import SerenityError


def _scene_stem(name: str) -> str:
    return os.path.splitext(os.path.basename(name))[0] if os.path.exists(name) else name


def cmd_reference(args) -> int:
    from serenity.cli import parse_size
    from serenity.eval.reference import render_reference
    from serenity.io.exr import write_exr
    from serenity.scene import load

    width, height = parse_size(args.size)
    scene = load(args.scene)
    out = args.output or os.path.join("serenity_out", f"{_scene_stem(args.scene)}_ref.exr")
    t0 = time.perf_counter()
    info: dict = {}
    img = render_reference(scene, width, height, spp=args.spp, component=args.component, seed=args.seed,
                           max_depth=args.depth, cache=not args.no_cache, progress=not args.quiet, info=info)
    secs = time.perf_counter() - t0
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    write_exr(out, {"beauty": img})
    what = f"max depth {args.depth}" if args.depth is not None else f"component {args.component}"
    print(f"reference {scene.name}: {width}x{height}, {args.spp} spp, {what}, {secs:.1f} s"
          f"{' (from the cache)' if info['cached'] else ''}")
    print(f"mean radiance {img.reshape(-1, 3).mean(0).round(3).tolist()} W/m^2/sr")
    print(f"wrote {out}")
    return 0


def _read_mask(path: str, shape) -> np.ndarray:
    if path.lower().endswith(".exr"):
        from serenity.io.exr import read_exr

        layers = read_exr(path)
        m = layers.get("mask", layers.get("beauty", next(iter(layers.values()))))
        m = np.asarray(m)[..., 0] > 0.5
    else:
        from serenity.io.png import read_png

        m = read_png(path)[..., 0] > 127
    if m.shape != tuple(shape):
        raise SerenityError(f"{path}: mask is {m.shape[1]}x{m.shape[0]}, images are {shape[1]}x{shape[0]}")
    return m


def _layer(path: str, name: str) -> np.ndarray:
    from serenity.io.exr import read_exr

    layers = read_exr(path)
    if name not in layers:
        raise SerenityError(f"{path}: no layer {name!r} (layers: {', '.join(layers)})")
    img = layers[name]
    if img.shape[-1] == 1:
        img = np.repeat(img, 3, axis=-1)
    return img[..., :3]


def cmd_compare(args) -> int:
    from serenity.eval.metrics import compare, flip_png
    from serenity.io.png import write_png

    ours = _layer(args.image, args.layer)
    ref = _layer(args.reference, args.ref_layer)
    if ours.shape != ref.shape:
        raise SerenityError(f"{args.image} is {ours.shape[1]}x{ours.shape[0]}, {args.reference} is "
                            f"{ref.shape[1]}x{ref.shape[0]} (shape mismatch)")
    mask = _read_mask(args.mask, ours.shape[:2]) if args.mask else None
    r = compare(ours, ref, mask, exposure=args.exposure)
    where = f" over {int(mask.sum())} masked pixels" if mask is not None else ""
    print(f"relMSE {r['rel_mse']:.5f}  (R {r['rel_mse_rgb'][0]:.5f}, G {r['rel_mse_rgb'][1]:.5f}, "
          f"B {r['rel_mse_rgb'][2]:.5f}; eps 1e-2){where}")
    print(f"FLIP   {r['flip']:.5f}  (LDR after exposure {args.exposure:g} + Reinhard + sRGB){where}")
    if args.output:
        os.makedirs(os.path.dirname(os.path.abspath(args.output)), exist_ok=True)
        write_png(args.output, flip_png(r["flip_map"]))
        print(f"wrote {args.output} (FLIP error map, magma)")
    return 0


def add_subcommands(sub) -> None:
    """Add ``reference`` and ``compare`` to the CLI's subparsers."""
    from serenity.eval.reference import COMPONENTS

    r = sub.add_parser("reference", help="path-trace a Mitsuba 3 reference of a scene to an EXR")
    r.add_argument("scene", help="built-in scene name or a scene/mesh file")
    r.add_argument("-o", "--output", help="EXR path (default serenity_out/<scene>_ref.exr)")
    r.add_argument("--size", default="320x180", help="WxH (default %(default)s)")
    r.add_argument("--spp", type=int, default=64, help="samples per pixel (default %(default)s)")
    g = r.add_mutually_exclusive_group()
    g.add_argument("--component", choices=COMPONENTS, default="full",
                   help="direct (depth 2) | one-bounce (3) | full | indirect = full - direct (default %(default)s)")
    g.add_argument("--depth", type=int, help="path integrator max depth instead (-1 = unlimited; 2 = direct)")
    r.add_argument("--seed", type=int, default=0, help="sampler seed (default %(default)s)")
    r.add_argument("--no-cache", action="store_true", help="render even if a cached result exists")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=cmd_reference)

    c = sub.add_parser("compare", help="relative MSE and FLIP of an EXR against a reference EXR")
    c.add_argument("image", help="EXR to judge (e.g. from serenity render)")
    c.add_argument("reference", help="reference EXR (e.g. from serenity reference)")
    c.add_argument("--mask", help="PNG (white = counted) or EXR (layer 'mask' or beauty > 0.5) of the pixels to count")
    c.add_argument("-o", "--output", help="write the FLIP error map here (PNG)")
    c.add_argument("--exposure", type=float, default=0.02, help="exposure before the tone map (default %(default)s)")
    c.add_argument("--layer", default="beauty", help="layer of IMAGE to compare (default %(default)s)")
    c.add_argument("--ref-layer", default="beauty", help="layer of REFERENCE (default %(default)s)")
    c.set_defaults(func=cmd_compare)

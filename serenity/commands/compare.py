"""``serenity compare``: relative MSE and FLIP of an EXR against a reference EXR.

    serenity compare ours.exr ref.exr --mask mask.png -o flip.png
    serenity compare ours.exr ref.exr --regions --scene courtyard [--json regions.json]

``--regions`` splits FLIP, relMSE and the luminance ratio ours/reference by sky / up-facing /
down-facing / vertical surfaces / edge pixels and by material (``serenity.eval.regions``), from
IMAGE's ``normal``, ``depth`` and ``material`` layers (as ``serenity render`` writes them).

FLIP needs the ``eval`` extra (flip-evaluator; matplotlib for ``-o``); without it the command says
so in one line.
"""

from __future__ import annotations

from serenity.commands.common import make_parent_dir
from serenity.config import DEFAULT_EXPOSURE
from serenity.errors import SerenityError


def register(subparsers) -> None:
    c = subparsers.add_parser("compare", help="relative MSE and FLIP of an EXR against a reference EXR "
                                              "(needs serenity[eval])")
    c.add_argument("image", help="EXR to judge (e.g. from serenity render)")
    c.add_argument("reference", help="reference EXR (e.g. from serenity reference)")
    c.add_argument("--mask", help="PNG (white = counted) or EXR (layer 'mask' or beauty > 0.5) of the pixels to count")
    c.add_argument("-o", "--output", help="write the FLIP error map here (PNG)")
    c.add_argument("--exposure", type=float, default=DEFAULT_EXPOSURE,
                   help="exposure before the tone map (default %(default)s)")
    c.add_argument("--layer", default="beauty", help="layer of IMAGE to compare (default %(default)s)")
    c.add_argument("--ref-layer", default="beauty", help="layer of REFERENCE (default %(default)s)")
    c.add_argument("--regions", action="store_true",
                   help="also split FLIP, relMSE and luminance ours/ref by sky / up- / down-facing / vertical "
                        "surfaces / edges and by material, from IMAGE's normal, depth and material layers")
    c.add_argument("--scene", help="with --regions: scene whose material names label the material rows")
    c.add_argument("--json", help="with --regions: write the per-region report here")
    c.set_defaults(func=run)


def run(args) -> int:
    from serenity.eval.metrics import compare, flip_png
    from serenity.io.exr import read_rgb_layer
    from serenity.io.mask import read_mask
    from serenity.io.png import write_png

    if (args.scene or args.json) and not args.regions:
        raise SerenityError("--scene and --json go with --regions")
    ours = read_rgb_layer(args.image, args.layer)
    ref = read_rgb_layer(args.reference, args.ref_layer)
    if ours.shape != ref.shape:
        raise SerenityError(f"{args.image} is {ours.shape[1]}x{ours.shape[0]}, {args.reference} is "
                            f"{ref.shape[1]}x{ref.shape[0]} (shape mismatch)")
    mask = read_mask(args.mask, ours.shape[:2]) if args.mask else None
    r = compare(ours, ref, mask, exposure=args.exposure)
    where = f" over {int(mask.sum())} masked pixels" if mask is not None else ""
    print(f"relMSE {r['rel_mse']:.5f}  (R {r['rel_mse_rgb'][0]:.5f}, G {r['rel_mse_rgb'][1]:.5f}, "
          f"B {r['rel_mse_rgb'][2]:.5f}; eps 1e-2){where}")
    print(f"FLIP   {r['flip']:.5f}  (LDR after exposure {args.exposure:g} + Reinhard + sRGB){where}")
    if args.regions:
        _print_regions(args, ours, ref, r["flip_map"], mask)
    if args.output:
        make_parent_dir(args.output)
        write_png(args.output, flip_png(r["flip_map"]))
        print(f"wrote {args.output} (FLIP error map, magma)")
    return 0


def _print_regions(args, ours, ref, fmap, mask) -> None:
    """``--regions``: the per-region / per-material table (and JSON) from IMAGE's AOV layers."""
    import json

    from serenity.eval.regions import format_region_report, region_report
    from serenity.io.exr import read_exr

    if mask is not None:
        raise SerenityError("--regions and --mask cannot be combined (the regions are the masks)")
    layers = read_exr(args.image)
    missing = [k for k in ("normal", "depth") if k not in layers]
    if missing:
        raise SerenityError(f"{args.image}: --regions needs the layer(s) {', '.join(missing)} "
                            f"(as serenity render writes them); layers: {', '.join(layers)}")
    names = None
    if args.scene:
        from serenity.scene import load

        names = [m.name for m in load(args.scene).materials]
    rep = region_report(ours, ref, layers["normal"], layers["depth"], layers.get("material"), names,
                        exposure=args.exposure, fmap=fmap)
    print(format_region_report(rep))
    if args.json:
        make_parent_dir(args.json)
        with open(args.json, "w") as f:
            json.dump(rep, f, indent=2)
        print(f"wrote {args.json}")

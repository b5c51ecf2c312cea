"""``serenity compare``: relative MSE and FLIP of an EXR against a reference EXR.

    serenity compare ours.exr ref.exr --mask mask.png -o flip.png

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
    c.set_defaults(func=run)


def run(args) -> int:
    from serenity.eval.metrics import compare, flip_png
    from serenity.io.exr import read_rgb_layer
    from serenity.io.mask import read_mask
    from serenity.io.png import write_png

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
    if args.output:
        make_parent_dir(args.output)
        write_png(args.output, flip_png(r["flip_map"]))
        print(f"wrote {args.output} (FLIP error map, magma)")
    return 0

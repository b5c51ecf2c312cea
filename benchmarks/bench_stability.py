"""Where each method fails: every stability case beside its exact answer, mitigation off and on
(issue #15). Writes one PNG grid and one JSON; the README's "Where each method fails" table is
printed at the end (``--markdown``) from the same JSON.

    python benchmarks/bench_stability.py [--json FILE] [--png FILE] [--quick] [--only NAME ...]

Cases (serenity/eval/stability.py has each one's set-up, metric and exact answer): LPV thin wall,
self-illumination, near field; sky volume SH truncation under a low sun, quads on terrain; shadow
acne at 2°, peter-panning, cascade seams, PCSS penumbra at 10°; glass slab refraction, off-screen
geometry in a mirror; sunset pops; frame to frame with the sun moving 0.05°/frame and the camera on
``serenity bench``'s path (60 frames each). ``--quick`` shrinks sizes and frame counts (a smoke run;
the committed results are from the full run). Milliseconds are wall clock on the CPU of the
machine that ran it (the committed ones: a 2-core machine shared with other jobs — compare within a
row, not across machines).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np

from serenity.device import cpu_threads
from serenity.eval import stability as S

HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS = os.path.join(HERE, "results")


def cases(quick: bool):
    """(name, thunk) of every case, in gallery order."""
    f = 20 if quick else 60
    return [
        ("lpv_thin_wall", lambda: S.lpv_thin_wall_case()),
        ("lpv_self_illumination", lambda: S.lpv_self_illumination_case()),
        ("lpv_near_field", lambda: S.lpv_near_field_case(h=1.0)),
        ("gather_thin_wall", lambda: S.gather_thin_wall_case()),
        ("sky_ringing", lambda: S.sky_ringing_case(3.0, rays=1024 if quick else 4096)),
        ("sky_terrain", lambda: S.terrain_sky_case(24 if quick else 64, 128 if quick else 256)),
        ("shadow_acne", lambda: S.shadow_acne_case(2.0, (160, 90))),
        ("peter_panning", lambda: S.peter_panning_case(10.0, (160, 90))),
        ("contact_leak", lambda: S.contact_leak_case((320, 180))),
        ("cascade_seams", lambda: S.cascade_seam_case((320, 180))),
        ("penumbra", lambda: S.penumbra_case(10.0, (192, 192) if quick else (256, 256))),
        ("glass_slab", lambda: S.glass_slab_case(64)),
        ("mirror_shadows", lambda: S.mirror_shadow_case((160, 90))),
        ("horizon", lambda: S.horizon_case((48, 27))),
        ("sun_motion", lambda: S.sun_motion_case(f, (64, 36) if quick else (96, 54))),
        ("camera_path", lambda: S.camera_path_case(f, (64, 36) if quick else (96, 54))),
    ]


def _show(ax, img, vmin=None, vmax=None, cmap="magma"):
    img = np.asarray(img, np.float64)
    if img.ndim == 3:
        img = img.mean(axis=2)
    ax.imshow(np.ma.masked_invalid(img), cmap=cmap, vmin=vmin, vmax=vmax, aspect="auto", interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks([])


def gallery(results: list, path: str) -> None:
    """One row per case: exact, without mitigation, with mitigation (one colour scale per row), the
    error map of the mitigated version (its own scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(results)
    fig, axes = plt.subplots(n, 4, figsize=(13, 1.55 * n + 0.6), gridspec_kw={"width_ratios": [1, 1, 1, 1]})
    cols = ("exact / reference", "without mitigation", "with mitigation", "|error| (with)")
    for j, c in enumerate(cols):
        axes[0, j].set_title(c, fontsize=10)
    for i, case in enumerate(results):
        im = case.images
        vals = np.concatenate([np.asarray(im[k], np.float64).ravel() for k in ("exact", "without", "with")])
        vals = vals[np.isfinite(vals)]
        hi = float(np.percentile(vals, 99.5)) if vals.size else 1.0
        lo = float(min(0.0, vals.min())) if vals.size else 0.0
        for j, k in enumerate(("exact", "without", "with")):
            _show(axes[i, j], im[k], lo, hi if hi > lo else lo + 1, "magma")
        err = np.asarray(im["error"], np.float64)
        fin = err[np.isfinite(err)]
        _show(axes[i, 3], err, 0.0, float(fin.max()) if fin.size and fin.max() > 0 else 1.0, "viridis")
        axes[i, 0].set_ylabel(f"{case.technique}\n{case.name}", fontsize=7, rotation=0, ha="right", va="center",
                              labelpad=4)
        axes[i, 1].set_xlabel(f"{_fmt(case.error_without)}", fontsize=8, labelpad=1)
        axes[i, 2].set_xlabel(f"{_fmt(case.error_with)}  ({case.mitigation})", fontsize=7, labelpad=1)
    fig.suptitle("Where each method fails: exact answer, mitigation off / on, error map "
                 "(numbers under the images: the case's error metric, see the JSON/README table)", fontsize=10)
    fig.tight_layout(rect=(0.12, 0, 1, 0.985))
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _fmt(x) -> str:
    if x is None:
        return "-"
    x = float(x)
    if x == 0:
        return "0"
    return f"{x:.2e}" if abs(x) < 1e-3 or abs(x) >= 1e3 else f"{x:.3g}"


def markdown(rows: list[dict]) -> str:
    out = ["| technique | case | error metric (exact answer: 0) | without mitigation | with mitigation | "
           "mitigation | ms without | ms with |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['technique']} | {r['case']} | {r['metric']} | {_fmt(r['error_without'])} | "
                   f"{_fmt(r['error_with'])} | {r['mitigation']} | {r['ms_without']:.0f} | {r['ms_with']:.0f} |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", default=os.path.join(RESULTS, "stability.json"))
    ap.add_argument("--png", default=os.path.join(RESULTS, "stability.png"))
    ap.add_argument("--quick", action="store_true", help="small sizes and 20 frames (smoke run)")
    ap.add_argument("--only", nargs="*", help="run only these case keys")
    ap.add_argument("--markdown", action="store_true", help="print the README table from --json and exit")
    args = ap.parse_args(argv)
    if args.markdown:
        with open(args.json) as fh:
            print(markdown(json.load(fh)["cases"]))
        return 0
    results, rows = [], []
    for key, thunk in cases(args.quick):
        if args.only and key not in args.only:
            continue
        t0 = time.perf_counter()
        case = thunk()
        dt = time.perf_counter() - t0
        results.append(case)
        rows.append({"key": key, **case.row(), "seconds": dt})
        print(f"{key:<22} {_fmt(case.error_without):>10} -> {_fmt(case.error_with):>10}   ({dt:.0f} s)", flush=True)
    os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
    with open(args.json, "w") as fh:
        json.dump({"machine": {"platform": platform.platform(), "python": sys.version.split()[0],
                               "cpu_threads": cpu_threads()}, "quick": bool(args.quick), "cases": rows},
                  fh, indent=1, default=float)
    gallery(results, args.png)
    print(markdown(rows))
    print(f"wrote {args.json} and {args.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

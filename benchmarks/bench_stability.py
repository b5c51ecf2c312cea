"""Where each method fails: every stability case beside its exact answer, mitigation off and on.
Writes one PNG grid and one JSON; the README's "Where each method fails" table is
printed at the end (``--markdown``) from the same JSON.

    python benchmarks/bench_stability.py [--json FILE] [--png FILE] [--quick] [--only NAME ...]

Cases (the package serenity/eval/stability/ has each one's set-up, metric and exact answer): LPV
thin wall, self-illumination, near field; sky volume SH truncation under a low sun, quads on terrain; shadow
acne at 2°, peter-panning, cascade seams, PCSS penumbra at 10°; glass slab refraction, off-screen
geometry in a mirror; sunset pops; frame to frame with the sun moving 0.05°/frame and the camera on
``serenity bench``'s path (60 frames each). ``--quick`` shrinks sizes and frame counts (a smoke run;
the committed results are from the full run). Milliseconds are wall clock on the CPU of the
machine that ran it (the committed ones: a 2-core machine shared with other jobs — compare within a
row, not across machines).

``--temporal`` instead measures every preset frame to frame (``serenity/eval/stability/temporal.py``):
the courtyard at 160×90, the camera still and the sun's elevation sinking 0.05° per frame, then the
sun still and the camera moved 5 cm per frame, 40 steps each; per step the mean-luminance step and
the 99th-percentile pixel step of the tone-mapped luminance, and which part of the light (direct
sun, the rest) and which amortisation switch each pixel step comes from. It writes
``results/temporal_stability.json`` and, with ``results/temporal_stability_baseline.json`` (the same
measurement of the renderer without its temporal mitigations, ``--baseline``) beside it, the chart
``results/temporal_stability.png``:

    python benchmarks/bench_stability.py --temporal [--frames N] [--no-breakdown]
    python benchmarks/bench_stability.py --temporal --baseline COMMIT   # run against an older tree
    python benchmarks/bench_stability.py --temporal-markdown            # the docs' table from the JSON
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
from serenity.io.results import write_results

_fmt = S.format_error

HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS = os.path.join(HERE, "results")
TEMPORAL_JSON = os.path.join(RESULTS, "temporal_stability.json")
BASELINE_JSON = os.path.join(RESULTS, "temporal_stability_baseline.json")
TEMPORAL_PNG = os.path.join(RESULTS, "temporal_stability.png")


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


def markdown(rows: list[dict]) -> str:
    out = ["| technique | case | error metric (exact answer: 0) | without mitigation | with mitigation | "
           "mitigation | ms without | ms with |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['technique']} | {r['case']} | {r['metric']} | {_fmt(r['error_without'])} | "
                   f"{_fmt(r['error_with'])} | {r['mitigation']} | {r['ms_without']:.0f} | {r['ms_with']:.0f} |")
    return "\n".join(out)


def temporal(frames: int, breakdown: bool, size=(160, 90), presets=S.TEMPORAL_PRESETS) -> dict:
    """Every preset's sun sweep and camera pan (and with ``breakdown`` the sun sweep with each of
    ``S.TEMPORAL_SWITCHES`` that applies), as the JSON's fields."""
    out = {"definition": {
        "display luminance": "L = luminance of Reinhard(exposure * HDR), before the sRGB encoding, in [0, 1)",
        "mean step": "|mean(L_k) - mean(L_k-1)| / mean(L_k-1)",
        "p99 pixel step": f"99th percentile over pixels of |L_k - L_k-1| / max(L_k-1, {S.DISPLAY_FLOOR})",
        "sun sweep": f"camera still, sun elevation sinking {S.SUN_STEP_DEG} deg per frame from the scene's",
        "camera pan": f"sun still, camera and target moved {S.CAMERA_STEP_M} m per frame along the camera's right "
                      "vector; frame k-1 reprojected (bilinear), pixels whose reprojected surface disagrees "
                      "(disocclusions, edges), sharp edges and ray-traced pixels left out",
        "parts": "99th percentile of the step of the direct sun light / of the rest, over the pixel's HDR luminance"},
        "bounds": {"mean_step": S.MEAN_STEP_BOUND, "p99_step": S.P99_STEP_BOUND},
        "scene": "courtyard", "size": list(size), "frames": frames, "presets": {}, "breakdown": {}}
    for q in presets:
        t0 = time.perf_counter()
        sun = S.sun_sweep(q, frames, size)
        cam = S.camera_pan(q, frames, size)
        out["presets"][q] = {"sun": sun, "camera": cam}
        print(f"{q:<14} sun: mean {sun['worst_mean_step']:.4f} p99 {sun['worst_p99_step']:.4f}   camera: mean "
              f"{cam['worst_mean_step']:.4f} p99 {cam['worst_p99_step']:.4f}   ({time.perf_counter() - t0:.0f} s)",
              flush=True)
        if not breakdown:
            continue
        rows = []
        for name, overrides in S.TEMPORAL_SWITCHES:
            if not S.switch_applies(q, overrides):
                continue
            r = S.sun_sweep(q, frames, size, overrides=overrides)
            rows.append({"switch": name, "overrides": overrides, "worst_mean_step": r["worst_mean_step"],
                         "worst_p99_step": r["worst_p99_step"], "worst_parts_p99": r["worst_parts_p99"],
                         "p99_step": r["p99_step"]})
            print(f"    {name:<42} p99 {r['worst_p99_step']:.4f}", flush=True)
        out["breakdown"][q] = rows
    return out


def temporal_chart(now: dict, baseline: dict | None, path: str) -> None:
    """Per preset, the per-step 99th-percentile pixel step of the sun sweep (without the temporal
    mitigations, where the baseline JSON has it, and with them) and of the camera pan, with the goal."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(now["presets"])
    fig, axes = plt.subplots(1, len(names), figsize=(4.2 * len(names), 3.2), sharey=True)
    for ax, q in zip(np.atleast_1d(axes), names, strict=True):
        r = now["presets"][q]
        if baseline and q in baseline.get("presets", {}):
            b = baseline["presets"][q]["sun"]["p99_step"]
            ax.plot(np.arange(1, len(b) + 1), 100 * np.array(b), color="tab:red", lw=1.2,
                    label="sun sweep, without the mitigations")
        for case, colour, label in (("sun", "tab:blue", "sun sweep"), ("camera", "tab:green", "camera pan")):
            v = r[case]["p99_step"]
            ax.plot(np.arange(1, len(v) + 1), 100 * np.array(v), color=colour, lw=1.2, label=label)
        ax.axhline(100 * now["bounds"]["p99_step"], color="k", ls="--", lw=0.8, label="goal")
        ax.set_title(q)
        ax.set_xlabel("frame-to-frame step")
    np.atleast_1d(axes)[0].set_ylabel("99th-percentile pixel step (%)")
    np.atleast_1d(axes)[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", default=os.path.join(RESULTS, "stability.json"))
    ap.add_argument("--png", default=os.path.join(RESULTS, "stability.png"))
    ap.add_argument("--quick", action="store_true", help="small sizes and 20 frames (smoke run)")
    ap.add_argument("--only", nargs="*", help="run only these case keys")
    ap.add_argument("--markdown", action="store_true", help="print the README table from --json and exit")
    ap.add_argument("--temporal", action="store_true", help="every preset frame to frame (temporal_stability.json)")
    ap.add_argument("--frames", type=int, default=40, help="--temporal: frame-to-frame steps per case")
    ap.add_argument("--no-breakdown", action="store_true", help="--temporal: no per-switch breakdown")
    ap.add_argument("--baseline", metavar="COMMIT", help="--temporal: record the renderer of this older commit "
                    "(serenity on PYTHONPATH from that commit, this script's measurement) as the baseline JSON")
    ap.add_argument("--temporal-markdown", action="store_true", help="print the docs' temporal table and exit")
    args = ap.parse_args(argv)
    if args.temporal_markdown:
        baseline = json.load(open(BASELINE_JSON)) if os.path.exists(BASELINE_JSON) else None
        with open(TEMPORAL_JSON) as fh:
            print(S.temporal_stability_markdown(json.load(fh), baseline))
        return 0
    if args.temporal:
        data = temporal(args.frames, not args.no_breakdown)
        if args.baseline:  # the renderer measured is another tree's: its commit, not this checkout's
            data["commit"] = args.baseline
            frames = "" if args.frames == 40 else f" --frames {args.frames}"
            data["command"] = (f"git archive {args.baseline} serenity | tar -x -C DIR && "
                               "rm -f DIR/serenity/eval/stability.py && "
                               "cp -r serenity/eval/stability DIR/serenity/eval/ && "
                               "PYTHONPATH=DIR python benchmarks/bench_stability.py --temporal "
                               f"--baseline {args.baseline}{frames}")
        write_results(BASELINE_JSON if args.baseline else TEMPORAL_JSON, data)
        if os.path.exists(TEMPORAL_JSON):
            baseline = json.load(open(BASELINE_JSON)) if os.path.exists(BASELINE_JSON) else None
            temporal_chart(json.load(open(TEMPORAL_JSON)), baseline, TEMPORAL_PNG)
            print(f"wrote {TEMPORAL_PNG}")
        return 0
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
    write_results(args.json, json.loads(json.dumps(
        {"machine": {"platform": platform.platform(), "python": sys.version.split()[0], "cpu_threads": cpu_threads()},
         "quick": bool(args.quick), "cases": rows}, default=float)))
    gallery(results, args.png)
    print(markdown(rows))
    print(f"wrote {args.json} and {args.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

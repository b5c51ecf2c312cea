"""Where the error against a reference sits: FLIP and relMSE split by region and by material.

Regions come from the judged frame's own AOVs (``serenity render``'s EXR layers): its ``depth``
(inf = background) and world ``normal`` (the shading normal facing the camera, y up):

- ``sky``: background pixels (depth inf);
- ``up-facing``: n.y > 0.5 (floors, roofs, the ground — lit by the sky from above);
- ``down-facing``: n.y < −0.5 (ceilings, overhangs — lit only by bounced light);
- ``vertical``: covered pixels with |n.y| ≤ 0.5 (walls);
- ``edges``: depth-discontinuity pixels (:func:`serenity.eval.metrics.depth_edges`), the pixels
  anti-aliasing is about; they overlap the four regions above, which partition the image.

and, with a ``material`` layer (the G-buffer's material index, −1 = background), one entry per material.
:func:`leak_ratio` looks for light where the reference is dark, box by box.

Per region: ``pixels``, ``fraction`` of the image, mean ``flip`` and ``rel_mse`` over its pixels,
``flip_share`` / ``rel_mse_share`` (the region's part of the all-pixel sum: where the total comes from),
and ``luminance_ratio`` = mean luminance ours / mean luminance reference (Rec. 709 Y of linear
radiance; 1 = as bright as the reference on average, None where the reference is black there).
The FLIP map is computed once on the whole image (its filters need the neighbours) and averaged per
region, as :func:`serenity.eval.metrics.flip` does with a mask.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter

from serenity.errors import SerenityError
from serenity.eval.metrics import DEFAULT_EXPOSURE, REL_MSE_EPS, depth_edges, flip_map

UP_Y = 0.5
"""|n.y| above which a surface counts as up- or down-facing (60° from vertical)."""
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
"""Rec. 709 luminance weights of linear RGB."""
REGIONS = ("sky", "up-facing", "down-facing", "vertical", "edges")


def _plane(a, name: str, shape) -> np.ndarray:
    a = np.asarray(a, np.float64)
    if a.ndim == 3:
        a = a[..., 0]
    if a.shape != tuple(shape):
        raise SerenityError(f"{name} layer is {a.shape[1]}x{a.shape[0]}, images are {shape[1]}x{shape[0]}")
    return a


def region_masks(normal, depth, material=None, material_names=None) -> tuple[dict, dict]:
    """({region: (H, W) bool}, {material name: (H, W) bool}) from the AOVs (see the module doc).

    normal: (H, W, 3) world normals; depth: (H, W[, 1]) view depth, inf = background;
    material: optional (H, W[, 1]) material index (< 0 = background); material_names: index → name
    (default ``material <i>``)."""
    depth = np.asarray(depth)
    shape = depth.shape[:2]
    d = _plane(depth, "depth", shape)
    n = np.asarray(normal, np.float64)
    if n.ndim != 3 or n.shape[:2] != shape or n.shape[2] < 3:
        raise SerenityError(f"normal layer has shape {n.shape}; expected {shape[0]}x{shape[1]}x3")
    covered = np.isfinite(d)
    ny = np.where(covered, n[..., 1], 0.0)
    regions = {
        "sky": ~covered,
        "up-facing": covered & (ny > UP_Y),
        "down-facing": covered & (ny < -UP_Y),
        "vertical": covered & (np.abs(ny) <= UP_Y),
        "edges": depth_edges(d),
    }
    materials = {}
    if material is not None:
        ids = np.rint(_plane(material, "material", shape)).astype(np.int64)
        ids = np.where(covered, ids, -1)
        names = list(material_names or [])
        for i in np.unique(ids[ids >= 0]):
            name = names[i] if i < len(names) else f"material {i}"
            materials[name] = ids == i
    return regions, materials


def luminance(img) -> np.ndarray:
    """(H, W) Rec. 709 luminance of linear RGB."""
    return np.asarray(img, np.float64)[..., :3] @ LUMINANCE


LEAK_BOX = 5
"""Side (pixels) of the boxes :func:`leak_ratio` compares: a region, not a single noisy pixel."""
LEAK_DARK = 0.25
"""A box is dark where the reference's mean luminance there is under this fraction of its image mean."""


def leak_ratio(ours, ref, box: int = LEAK_BOX, dark: float = LEAK_DARK) -> dict:
    """Light where the reference has little (a leak through a wall, blinds, a curtain): over every
    ``box``×``box`` box (a box filter, centred at each pixel) whose reference mean luminance is under
    ``dark`` × the reference image's mean, the largest ratio ours ÷ reference of the box means.
    {"max_ratio": float or None (no dark box), "dark_fraction": the image's share of dark boxes,
    "over_4": the share of the dark boxes where ours is more than 4× the reference}."""
    lo, lr = luminance(ours), luminance(ref)
    if lo.shape != lr.shape:
        raise SerenityError(f"images differ in size: {lo.shape} vs reference {lr.shape} (shape mismatch)")
    mo, mr = uniform_filter(lo, int(box), mode="nearest"), uniform_filter(lr, int(box), mode="nearest")
    is_dark = mr < dark * float(lr.mean())
    if not is_dark.any():
        return {"max_ratio": None, "dark_fraction": 0.0, "over_4": 0.0}
    ratio = mo[is_dark] / np.maximum(mr[is_dark], 1e-6 * max(float(lr.mean()), 1e-30))
    return {"max_ratio": float(ratio.max()), "dark_fraction": float(is_dark.mean()),
            "over_4": float((ratio > 4.0).mean())}


def _stats(mask, fmap, rmap, lum_ours, lum_ref, flip_sum, rel_sum) -> dict:
    n = int(mask.sum())
    if n == 0:
        return {"pixels": 0, "fraction": 0.0, "flip": None, "rel_mse": None, "flip_share": 0.0,
                "rel_mse_share": 0.0, "luminance_ours": None, "luminance_ref": None, "luminance_ratio": None}
    lo, lr = float(lum_ours[mask].mean()), float(lum_ref[mask].mean())
    return {
        "pixels": n,
        "fraction": n / mask.size,
        "flip": float(fmap[mask].mean()),
        "rel_mse": float(rmap[mask].mean()),
        "flip_share": float(fmap[mask].sum() / flip_sum) if flip_sum > 0 else 0.0,
        "rel_mse_share": float(rmap[mask].sum() / rel_sum) if rel_sum > 0 else 0.0,
        "luminance_ours": lo,
        "luminance_ref": lr,
        "luminance_ratio": lo / lr if lr > 1e-6 else None,
    }


def region_report(ours, ref, normal, depth, material=None, material_names=None,
                  exposure: float = DEFAULT_EXPOSURE, fmap: np.ndarray | None = None) -> dict:
    """{"all": stats, "regions": {name: stats}, "materials": {name: stats}} of ``ours`` against ``ref``
    (both (H, W, 3) linear HDR; stats as in the module doc). ``fmap``: a FLIP map already computed
    with the same exposure (else computed here)."""
    a = np.asarray(ours, np.float64)[..., :3]
    b = np.asarray(ref, np.float64)[..., :3]
    if a.shape != b.shape:
        raise SerenityError(f"images differ in size: {a.shape[:2]} vs reference {b.shape[:2]} (shape mismatch)")
    regions, materials = region_masks(normal, depth, material, material_names)
    h, w = next(iter(regions.values())).shape
    if (h, w) != a.shape[:2]:
        raise SerenityError(f"AOV layers are {w}x{h}, images are {a.shape[1]}x{a.shape[0]} (shape mismatch)")
    fm = flip_map(a, b, exposure) if fmap is None else np.asarray(fmap, np.float64)
    rm = ((a - b) ** 2 / (b * b + REL_MSE_EPS)).mean(axis=-1)
    lo, lr = luminance(a), luminance(b)
    fs, rs = float(fm.sum()), float(rm.sum())
    everything = np.ones(a.shape[:2], bool)
    return {
        "all": _stats(everything, fm, rm, lo, lr, fs, rs),
        "regions": {k: _stats(m, fm, rm, lo, lr, fs, rs) for k, m in regions.items()},
        "materials": {k: _stats(m, fm, rm, lo, lr, fs, rs) for k, m in materials.items()},
    }


def format_region_report(report: dict) -> str:
    """The report as a text table: one row per region, then per material."""
    head = f"{'region':<22} {'pixels':>7} {'FLIP':>7} {'share':>6} {'relMSE':>9} {'share':>6} {'lum ours/ref':>12}"
    lines = [head]

    def row(name, s):
        if not s["pixels"]:
            return f"{name:<22} {0:>7} {'-':>7} {'-':>6} {'-':>9} {'-':>6} {'-':>12}"
        ratio = "-" if s["luminance_ratio"] is None else f"{s['luminance_ratio']:.3f}"
        return (f"{name:<22} {s['pixels']:>7} {s['flip']:7.4f} {100 * s['flip_share']:5.1f}% {s['rel_mse']:9.4f} "
                f"{100 * s['rel_mse_share']:5.1f}% {ratio:>12}")

    lines.append(row("all", report["all"]))
    lines += [row(k, s) for k, s in report["regions"].items()]
    if report["materials"]:
        lines.append("by material:")
        lines += [row(k, s) for k, s in report["materials"].items()]
    return "\n".join(lines)

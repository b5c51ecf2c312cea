"""Image error metrics against a reference (docs/architecture.md, "Accuracy").

- :func:`rel_mse` — relative MSE on linear HDR radiance: mean over pixels (and channels) of
  (a − b)² / (b² + ε), b the reference, ε = 1e-2 (W·m⁻²·sr⁻¹)² so that black reference pixels do
  not divide by zero. ε is absolute: at the radiances of our scenes (tens to hundreds) it matters only
  for near-black pixels (b ≲ 0.3), where it caps a pixel's error at (a − b)²/ε.
- :func:`flip` — NVIDIA's FLIP (``flip-evaluator``, LDR mode, 67 pixels per degree) on the
  tone-mapped images: both go through :func:`serenity.colour.reinhard_srgb` (the renderer's
  own numpy twin of its tone map: exposure, Reinhard, sRGB, 8 bits) with the same exposure, so a FLIP of 0 means
  "looks the same on screen after our tone map". Mean over pixels, in [0, 1].

Both take an optional boolean pixel mask (H, W); the mean runs over the masked pixels only (the
FLIP map itself is computed on the whole image: its filters need the neighbours).
"""

from __future__ import annotations

import numpy as np

from serenity.colour import reinhard_srgb
from serenity.config import DEFAULT_EXPOSURE
from serenity.errors import SerenityError
from serenity.optional import require

REL_MSE_EPS = 1e-2
"""ε of relative MSE, (W·m⁻²·sr⁻¹)²."""


def _pair(a, b) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    if a.ndim == 2:
        a = a[..., None]
    if b.ndim == 2:
        b = b[..., None]
    a, b = a[..., :3], b[..., :3]
    if a.shape != b.shape:
        raise SerenityError(f"images differ in size: {a.shape[:2]} vs reference {b.shape[:2]} (shape mismatch)")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise SerenityError("images contain NaN or infinite values")
    return a, b


def _mask(mask, shape) -> np.ndarray | None:
    if mask is None:
        return None
    m = np.asarray(mask)
    if m.ndim == 3:
        m = m[..., 0]
    if m.shape != shape:
        raise SerenityError(f"mask is {m.shape}, images are {shape} (shape mismatch)")
    m = m.astype(bool)
    if not m.any():
        raise SerenityError("mask selects no pixels")
    return m


def rel_mse_per_channel(img, ref, mask=None, eps: float = REL_MSE_EPS) -> np.ndarray:
    """(C,) relative MSE of each channel: mean over (masked) pixels of (img − ref)² / (ref² + eps)."""
    a, b = _pair(img, ref)
    m = _mask(mask, a.shape[:2])
    e = (a - b) ** 2 / (b * b + eps)
    if m is not None:
        e = e[m]
    return e.reshape(-1, a.shape[-1]).mean(axis=0)


def rel_mse(img, ref, mask=None, eps: float = REL_MSE_EPS, trim: float = 0.0) -> float:
    """Relative MSE on linear HDR, averaged over (masked) pixels and channels (see the module doc).

    ``trim``: fraction of the pixels with the largest error left out (e.g. 1e-3, the usual outlier
    rejection: one light leak onto a pixel whose reference is nearly black can otherwise outweigh
    every other pixel together)."""
    if trim <= 0.0:
        return float(rel_mse_per_channel(img, ref, mask, eps).mean())
    a, b = _pair(img, ref)
    m = _mask(mask, a.shape[:2])
    e = ((a - b) ** 2 / (b * b + eps)).mean(axis=-1)
    e = np.sort(e[m] if m is not None else e.reshape(-1))
    keep = max(1, int(round(len(e) * (1.0 - min(trim, 1.0)))))
    return float(e[:keep].mean())


def tonemap(hdr, exposure: float = DEFAULT_EXPOSURE) -> np.ndarray:
    """(H, W, 3) float32 display values in [0, 1]: exactly the renderer's 8-bit sRGB output for this HDR
    image (exposure, Reinhard, sRGB, rounding: ``reinhard_srgb``), divided by 255."""
    return reinhard_srgb(np.asarray(hdr, np.float32), exposure).astype(np.float32) / np.float32(255.0)


def flip_map(img, ref, exposure: float = DEFAULT_EXPOSURE) -> np.ndarray:
    """(H, W) float32 FLIP error per pixel, in [0, 1], of the tone-mapped HDR images."""
    flip_evaluator = require("flip_evaluator", "the FLIP metric")
    a, b = _pair(img, ref)
    if a.shape[-1] != 3:
        a, b = np.repeat(a[..., :1], 3, -1), np.repeat(b[..., :1], 3, -1)
    err, _, _ = flip_evaluator.evaluate(tonemap(b, exposure), tonemap(a, exposure), "LDR", inputsRGB=True,
                                        applyMagma=False, computeMeanError=False)
    err = np.asarray(err, np.float32)
    return err[..., 0] if err.ndim == 3 else err


def flip(img, ref, mask=None, exposure: float = DEFAULT_EXPOSURE) -> float:
    """Mean FLIP error of the tone-mapped images over the (masked) pixels, in [0, 1]."""
    e = flip_map(img, ref, exposure)
    m = _mask(mask, e.shape)
    return float(e[m].mean() if m is not None else e.mean())


def flip_png(error_map: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 of a FLIP error map through matplotlib's magma colour map (0 black, 1 bright)."""
    colormaps = require("matplotlib", "the FLIP error map").colormaps
    e = np.clip(np.asarray(error_map, np.float32), 0.0, 1.0)
    return (colormaps["magma"](e)[..., :3] * 255.0 + 0.5).astype(np.uint8)


def compare(img, ref, mask=None, exposure: float = DEFAULT_EXPOSURE) -> dict:
    """Every metric of ``img`` against ``ref``: {"rel_mse", "rel_mse_rgb", "flip", "flip_map"}."""
    fm = flip_map(img, ref, exposure)
    m = _mask(mask, fm.shape)
    return {
        "rel_mse": rel_mse(img, ref, m),
        "rel_mse_rgb": [float(x) for x in rel_mse_per_channel(img, ref, m)],
        "flip": float(fm[m].mean() if m is not None else fm.mean()),
        "flip_map": fm,
    }


def depth_edges(depth, rel_jump: float = 0.05) -> np.ndarray:
    """(H, W) bool: pixels on a depth discontinuity — a 4-neighbour whose view depth differs by more than
    ``rel_jump`` of the nearer one, or that is background (inf) where this one is not (both sides marked)."""
    d = np.asarray(depth, np.float64)
    if d.ndim == 3:
        d = d[..., 0]
    finite = np.isfinite(d)
    big = np.where(finite, d, 0.0)
    e = np.zeros(d.shape, bool)
    for axis in (0, 1):
        n = d.shape[axis]
        a, b = np.take(big, range(n - 1), axis=axis), np.take(big, range(1, n), axis=axis)
        fa, fb = np.take(finite, range(n - 1), axis=axis), np.take(finite, range(1, n), axis=axis)
        near = np.maximum(np.minimum(np.abs(a), np.abs(b)), 1e-9)
        jump = (fa != fb) | (fa & fb & (np.abs(a - b) > rel_jump * near))
        if axis == 0:
            e[:-1] |= jump
            e[1:] |= jump
        else:
            e[:, :-1] |= jump
            e[:, 1:] |= jump
    return e


def edge_iou(depth_a, depth_b, rel_jump: float = 0.05) -> float:
    """Intersection over union of the depth-discontinuity pixels of two depth maps (1 = silhouettes align;
    1 also when neither has an edge)."""
    ea, eb = depth_edges(depth_a, rel_jump), depth_edges(depth_b, rel_jump)
    union = int((ea | eb).sum())
    return 1.0 if union == 0 else float((ea & eb).sum()) / union

"""Textures on the device for the ray tracer (``raytrace``): every mip level of every texture in one
array of packed RGBA8 texels, and the table that decodes them.

A texel is a uint32, r in the low byte, then g, b, a: rgb sRGB-encoded for albedo maps, linear for
normal maps, alpha always linear, each rounded to the nearest of 256 steps in [0, 1]
(:func:`encode_rgba8`, on the device). The tracer decodes a texel to linear before it filters, as a
GPU filters an sRGB8 texture, with one load per channel from :func:`lut8` (512 float32: the 256 sRGB
codes decoded, then the 256 linear ones): a quarter of float32 RGBA's memory and loads; an 8-bit
image's level 0 decodes to exactly the scene's float values (``scene.texture``), the box-filtered mips
to within half an 8-bit step. :func:`pack_mip_chains` lays out the levels and returns the tables that
find them (first level and level count per texture, offset, size and encoding per level).

Compiled with the tracer's module options (no FMA contraction): the rounding x·255 + 0.5 gives the
same codes on the CPU and on CUDA.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from serenity.colour import srgb_to_linear
from serenity.kernels.kdtree import TRACE_MODULE_OPTIONS
from serenity.kernels.launch import launch

wp.set_module_options(TRACE_MODULE_OPTIONS)

#: the sRGB encoder's table: linear [0, 1] in this many steps, each the first 8-bit code at or above it
SRGB8_STEPS = wp.constant(4096)


@wp.func
def _unorm8(x: float) -> wp.uint32:
    return wp.uint32(wp.floor(wp.clamp(x, 0.0, 1.0) * 255.0 + 0.5))


@wp.func
def _srgb8(x: float, bounds: wp.array(dtype=float), first: wp.array(dtype=wp.int32)) -> wp.uint32:
    v = wp.clamp(x, 0.0, 1.0)
    k = first[int(v * float(SRGB8_STEPS))]
    while v >= bounds[k]:
        k += 1
    return wp.uint32(k)


@wp.kernel
def encode_rgba8_kernel(src: wp.array2d(dtype=float), srgb: int, bounds: wp.array(dtype=float),
                        codes: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.uint32), first: int, offset: int):
    """Texel i of a level (rows of ``src``, C channels) packed into ``out[first + i]`` (``encode_rgba8``)."""
    i = wp.tid() + offset
    c = src.shape[1]
    r = src[i, 0]
    g = r
    b = r
    if c >= 3:
        g = src[i, 1]
        b = src[i, 2]
    a = wp.uint32(255)
    if c == 2 or c == 4:
        a = _unorm8(src[i, c - 1])
    q = wp.uint32(0)
    if srgb != 0:
        q = _srgb8(r, bounds, codes) | (_srgb8(g, bounds, codes) << wp.uint32(8)) \
            | (_srgb8(b, bounds, codes) << wp.uint32(16))
    else:
        q = _unorm8(r) | (_unorm8(g) << wp.uint32(8)) | (_unorm8(b) << wp.uint32(16))
    out[first + i] = q | (a << wp.uint32(24))


def lut8() -> np.ndarray:
    """(512,) float32 the decoded 8-bit values: [0, 256) sRGB → linear, [256, 512) k / 255 — exactly
    what ``scene.texture`` makes of an 8-bit image (float64 arithmetic, then float32)."""
    k = np.arange(256) / 255.0
    return np.concatenate([srgb_to_linear(k), k]).astype(np.float32)


def srgb8_tables() -> tuple[np.ndarray, np.ndarray]:
    """(bounds (256,) float32: the linear value from which code k + 1 is nearer than k (inf for the
    last), first (SRGB8_STEPS + 1,) int32: the code of j / SRGB8_STEPS): sRGB encoding to 8 bits as a
    table lookup and a step or two up, without a pow per texel."""
    bounds = np.append(srgb_to_linear((np.arange(255) + 0.5) / 255.0), np.inf).astype(np.float32)
    first = np.searchsorted(bounds, (np.arange(SRGB8_STEPS + 1) / SRGB8_STEPS).astype(np.float32), side="right")
    return bounds, first.astype(np.int32)


def encode_rgba8(levels: list, srgb: list, device="cpu"):
    """(Σ H·W,) Warp uint32 array of packed RGBA8 texels (r in the low byte) of (H, W, C) linear
    levels, one after the other: rgb sRGB-encoded where ``srgb`` (per level; else linear), alpha
    linear, each rounded to the nearest of 256 steps in [0, 1]; one channel is grey, two grey and
    alpha, alpha 1 without one. An 8-bit image's level 0 decodes exactly (:func:`lut8`)."""
    total = sum(int(np.shape(m)[0]) * int(np.shape(m)[1]) for m in levels)
    out = wp.empty(max(total, 1), dtype=wp.uint32, device=device)
    bounds, codes = (wp.array(a, device=device) for a in srgb8_tables())
    first = 0
    for mip, enc in zip(levels, srgb, strict=True):
        a = np.ascontiguousarray(mip, np.float32)
        h, w, c = a.shape
        src = wp.array(a.reshape(h * w, c), dtype=float, device="cpu")
        if not str(device).startswith("cpu"):
            src = src.to(device)
        launch(encode_rgba8_kernel, h * w, [src, int(enc), bounds, codes, out, first], device=device)
        first += h * w
    return out


def pack_mip_chains(textures: list, srgb=None, device="cpu"):
    """All mip levels of ``textures`` in one Warp array of packed RGBA8 texels (``encode_rgba8``): a
    quarter of float32 RGBA's memory (98 MB of the breakfast room's textures) and of its loads.

    ``srgb``: per texture, whether its rgb is stored sRGB-encoded (albedo maps: 8-bit steps where the
    eye sees them, as GPUs store such textures) or linear (normal maps); default all sRGB.
    Returns (first_level (T,), levels (T,), level_offset (L,), level_size (L,2) as (w, h),
    level_srgb (L,), texels (texels,) uint32 Warp array on ``device``)."""
    srgb = [True] * len(textures) if srgb is None else [bool(x) for x in srgb]
    first, nlev, offs, sizes, flags, levels = [], [], [], [], [], []
    n_texels = 0
    for tex, enc in zip(textures, srgb, strict=True):
        first.append(len(levels))
        nlev.append(len(tex.mips))
        for mip in tex.mips:
            h, w = np.shape(mip)[:2]
            offs.append(n_texels)
            sizes.append((w, h))
            flags.append(int(enc))
            levels.append(mip)
            n_texels += h * w
    texels = encode_rgba8(levels, flags, device)
    if not levels:  # Warp arrays may not be empty in a struct: one dummy (white) texel
        texels.fill_(wp.uint32(0xFFFFFFFF))
        offs, sizes, flags = [0], [(1, 1)], [0]
    return (np.array(first or [0], np.int32), np.array(nlev or [1], np.int32), np.array(offs, np.int32),
            np.array(sizes, np.int32).reshape(-1, 2), np.array(flags, np.int32), texels)

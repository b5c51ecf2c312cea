"""Colour in numpy: the sRGB transfer functions, luminance, and the tone map's numpy twin.

The one place for these; the GL side has its own copies in GLSL (``raster/glsl/common.glsl``,
``raster/glsl/tonemap.glsl``) that ``tests/raster/test_tonemap.py`` checks against these.

- ``srgb_to_linear`` / ``linear_to_srgb``: the exact piecewise transfer functions of IEC 61966-2-1
  (sRGB), element-wise; values outside [0, 1] are clamped. Computed in float32 for float32 input
  (as the tone map's shader does), in float64 for anything else.
- ``luminance``: Rec. 709 / sRGB primaries, linear RGB → relative luminance.
- ``reinhard`` / ``reinhard_srgb``: the renderer's tone map (paper §4), exactly as
  ``raster/glsl/tonemap.glsl`` computes it::

      Lw = luminance(exposure · L);  Ld = Lw / (1 + Lw);  out = srgb(exposure · L · Ld / Lw)

  ``reinhard_srgb`` rounds to 8 bits like the GL pass's ``rgba8`` target; the metrics tone-map a
  reference through it so that ours and the reference are compared after the same mapping.
"""

from __future__ import annotations

import numpy as np

__all__ = ["LUMA_REC709", "linear_to_srgb", "luminance", "reinhard", "reinhard_srgb", "srgb_to_linear"]

# IEC 61966-2-1 constants
_SRGB_DECODE_KNEE = 0.04045  # encoded value where the linear segment ends
_SRGB_ENCODE_KNEE = 0.0031308  # linear value where the linear segment ends
_SRGB_SLOPE = 12.92
_SRGB_A = 0.055
_SRGB_GAMMA = 2.4

LUMA_REC709 = np.array([0.2126, 0.7152, 0.0722], np.float32)
"""Linear RGB → relative luminance weights (Rec. 709 primaries, those of sRGB)."""


def _float(x) -> np.ndarray:
    """``x`` as float32 if it is float32, else as float64."""
    a = np.asarray(x)
    return a if a.dtype == np.float32 else a.astype(np.float64)


def srgb_to_linear(x) -> np.ndarray:
    """sRGB-encoded values in [0, 1] → linear values in [0, 1] (IEC 61966-2-1)."""
    v = np.clip(_float(x), 0.0, 1.0)
    return np.where(v <= _SRGB_DECODE_KNEE, v / _SRGB_SLOPE, ((v + _SRGB_A) / (1 + _SRGB_A)) ** _SRGB_GAMMA)


def linear_to_srgb(x) -> np.ndarray:
    """Linear values in [0, 1] → sRGB-encoded values in [0, 1] (IEC 61966-2-1)."""
    v = np.clip(_float(x), 0.0, 1.0)
    return np.where(v <= _SRGB_ENCODE_KNEE, v * _SRGB_SLOPE, (1 + _SRGB_A) * v ** (1 / _SRGB_GAMMA) - _SRGB_A)


def luminance(rgb) -> np.ndarray:
    """(..., 3) linear RGB → (...) relative luminance (same units as the input)."""
    return np.asarray(rgb)[..., :3] @ LUMA_REC709


def reinhard(hdr: np.ndarray, exposure: float) -> np.ndarray:
    """(H, W, 3) float32 linear display values in [0, 1) (before sRGB encoding) of linear radiance
    ``hdr`` (W·m⁻²·sr⁻¹) scaled by ``exposure``."""
    c = np.maximum(np.asarray(hdr, np.float32)[..., :3], 0.0) * np.float32(exposure)
    lw = c @ LUMA_REC709
    scale = np.where(lw > 0, 1.0 / (1.0 + lw), 0.0).astype(np.float32)
    return c * scale[..., None]


def reinhard_srgb(hdr: np.ndarray, exposure: float) -> np.ndarray:
    """(H, W, 3) uint8 sRGB: the GL tone map's output for ``hdr`` at ``exposure``."""
    return np.round(linear_to_srgb(reinhard(hdr, exposure)) * 255.0).astype(np.uint8)

"""Exposure + Reinhard tone mapping + sRGB encoding (paper §4), on GL and, identically, in numpy.

    Lw = luminance(exposure · L);  Ld = Lw / (1 + Lw);  out = srgb(exposure · L · Ld / Lw)

The numpy twin ``reinhard_srgb`` is what metrics use to tone-map a reference the same way.
"""

from __future__ import annotations

import numpy as np

from serenity.raster.context import FullscreenPass
from serenity.raster.interop import read_texture

_LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)


def linear_to_srgb(c: np.ndarray) -> np.ndarray:
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)


def reinhard(hdr: np.ndarray, exposure: float) -> np.ndarray:
    """Linear display values in [0, 1) (before sRGB encoding)."""
    c = np.maximum(np.asarray(hdr, np.float32)[..., :3], 0.0) * np.float32(exposure)
    lw = c @ _LUMA
    scale = np.where(lw > 0, 1.0 / (1.0 + lw), 0.0).astype(np.float32)
    return c * scale[..., None]


def reinhard_srgb(hdr: np.ndarray, exposure: float) -> np.ndarray:
    """(H, W, 3) uint8 sRGB, the same mapping as the GL pass."""
    return np.round(linear_to_srgb(reinhard(hdr, exposure)) * 255.0).astype(np.uint8)


class TonemapPass(FullscreenPass):
    SHADER = "tonemap.glsl"
    TARGETS = {"ldr": (4, "f1")}

    def render(self, hdr_texture, exposure: float):
        with self.ctx.debug_scope("tonemap"):
            self.fbo.use()
            hdr_texture.use(location=0)
            self.program["u_hdr"].value = 0
            self.program["u_exposure"].value = float(exposure)
            self.vao.render(vertices=3)
        return self.ldr

    def read(self) -> np.ndarray:
        return read_texture(self.ldr, 3)

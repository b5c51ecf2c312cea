"""Exposure + Reinhard tone mapping + sRGB encoding (paper §4), on GL and, identically, in numpy.

    Lw = luminance(exposure · L);  Ld = Lw / (1 + Lw);  out = srgb(exposure · L · Ld / Lw)

Its numpy twin is :func:`serenity.colour.reinhard_srgb` (what the metrics tone-map a reference with).
"""

from __future__ import annotations

import moderngl
import numpy as np

from serenity.raster.context import FullscreenPass
from serenity.raster.interop import read_texture


class TonemapPass(FullscreenPass):
    SHADER = "tonemap.glsl"
    TARGETS = {"ldr": (4, "f1")}

    def __init__(self, ctx):
        super().__init__(ctx)
        self.counter = ctx.buffer(reserve=4)

    def render(self, hdr_texture, exposure: float):
        with self.ctx.debug_scope("tonemap"):
            self.fbo.use()
            hdr_texture.use(location=0)
            self.counter.write(b"\0\0\0\0")
            self.counter.bind_to_storage_buffer(self.program["NonFinite"].binding)  # as the shader declares it
            self.program["u_hdr"].value = 0
            self.program["u_exposure"].value = float(exposure)
            self.vao.render(vertices=3)
        return self.ldr

    def nonfinite_pixels(self) -> int:
        """How many pixels of the last rendered HDR image were NaN or infinite in any channel (4 bytes
        read back: waits for the pass)."""
        self.ctx.memory_barrier(moderngl.BUFFER_UPDATE_BARRIER_BIT)  # the shader's atomic writes, visible to the read
        return int(np.frombuffer(self.counter.read(), np.uint32)[0])

    def read(self) -> np.ndarray:
        return read_texture(self.ldr, 3)

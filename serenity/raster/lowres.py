"""Reduced-resolution views of the G-buffer.

``LowResGuide`` (``glsl/lowres_guide.glsl``): per low-res texel, the normal and view depth of its
representative G-buffer pixel (``glsl/lowres.glsl``), drawn once per frame for the SSAO blur and the
indirect light's joint bilateral upsampling, whose taps each read one guide texel instead of two
G-buffer texels. ``GBufferSamples`` (``glsl/gbuffer_samples.glsl``): every n-th G-buffer pixel
gathered on the GL side, so the LPV's sky VPLs read back 1/n² of the G-buffer."""

from __future__ import annotations

import moderngl
import numpy as np

from serenity.raster.context import fullscreen_vao, load_program, low_res_size
from serenity.raster.interop import read_texture


class LowResGuide:
    def __init__(self, ctx, scale: int):
        self.ctx = ctx
        self.scale = max(1, int(scale))
        self.program = load_program(ctx, "lowres_guide.glsl")
        self.vao = fullscreen_vao(ctx, self.program)
        self.size = None

    def resize(self, width: int, height: int) -> None:
        if self.size == (width, height):
            return
        if self.size is not None:
            self.fbo.release()
            self.guide.release()
        self.guide = self.ctx.texture(low_res_size(width, height, self.scale), 4, dtype="f4")
        self.guide.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.fbo = self.ctx.framebuffer(color_attachments=[self.guide])
        self.size = (width, height)

    def render(self, gbuffer, camera_pos, camera_forward):
        """The (W/scale, H/scale) RGBA32F guide texture of ``gbuffer``."""
        p = self.program
        with self.ctx.debug_scope("lowres guide"):
            self.fbo.use()
            gbuffer.position.use(location=0)
            gbuffer.normal.use(location=1)
            p["g_position"].value = 0
            p["g_normal"].value = 1
            p["u_scale"].value = self.scale
            p["u_camera_pos"].value = tuple(float(x) for x in camera_pos)
            p["u_camera_forward"].value = tuple(float(x) for x in camera_forward)
            self.vao.render(vertices=3)
        return self.guide


class GBufferSamples:
    """Every ``stride``-th pixel of the G-buffer's position, normal and albedo, starting at ``stride // 2``
    (``glsl/gbuffer_samples.glsl``), read back as (rows, cols, 4) float32 images, top row first — the
    same arrays as ``read_texture(target)[c::s, c::s]`` at 1/stride² of the read-back."""

    NAMES = ("position", "normal", "albedo")

    def __init__(self, ctx, stride: int):
        self.ctx = ctx
        self.stride = max(1, int(stride))
        self.program = load_program(ctx, "gbuffer_samples.glsl")
        self.vao = fullscreen_vao(ctx, self.program)
        self.size = None

    def resize(self, width: int, height: int) -> None:
        if self.size == (width, height):
            return
        if self.size is not None:
            self.fbo.release()
            for t in self.targets:
                t.release()
        first = self.stride // 2
        self.out_size = (len(range(first, width, self.stride)), len(range(first, height, self.stride)))
        self.targets = [self.ctx.texture(self.out_size, 4, dtype="f4") for _ in self.NAMES]
        self.fbo = self.ctx.framebuffer(color_attachments=self.targets)
        self.size = (width, height)

    def read(self, gbuffer) -> dict[str, np.ndarray]:
        """{"position", "normal", "albedo"}: the sampled pixels, (rows, cols, 4) float32."""
        p = self.program
        with self.ctx.debug_scope("gbuffer samples"):
            self.fbo.use()
            for loc, name in enumerate(self.NAMES):
                getattr(gbuffer, name).use(location=loc)
                p[f"g_{name}"].value = loc
            p["u_first"].value = self.stride // 2
            p["u_stride"].value = self.stride
            p["u_rows_out"].value = self.out_size[1]
            self.vao.render(vertices=3)
        return {name: read_texture(t, 4) for name, t in zip(self.NAMES, self.targets, strict=True)}

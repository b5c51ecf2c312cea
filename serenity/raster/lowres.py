"""The guide of the reduced-resolution passes (``glsl/lowres_guide.glsl``): per low-res texel, the
normal and view depth of its representative G-buffer pixel (``glsl/lowres.glsl``), drawn once per
frame for the SSAO blur and the indirect light's joint bilateral upsampling, whose taps each read
one guide texel instead of two G-buffer texels."""

from __future__ import annotations

import moderngl

from serenity.raster.context import fullscreen_vao, load_program, low_res_size


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

"""Screen-space ambient occlusion with a bilateral blur (paper §3; ``glsl/ssao.glsl``).

Main view only: the ray-traced views skip it (paper §9), because their pixels' neighbours are not
their neighbours in the scene. The AO multiplies indirect light only (sky volume, LPV, ambient).

``scale`` > 1 computes and blurs the AO at 1/scale of the view per axis (``glsl/lowres.glsl``: each
AO texel is its block's representative G-buffer pixel), the resolution of the indirect light it
multiplies; on a CPU rasteriser the pass costs in proportion to its pixels.
"""

from __future__ import annotations

import moderngl
import numpy as np

from serenity.raster.context import finish, fullscreen_vao, load_program, low_res_layout


class SSAOPass:
    def __init__(self, ctx, config, scale: int = 1, balance: bool = True):
        self.ctx = ctx
        self.config = config
        self.scale = max(1, int(scale))
        self.balance = balance  # the padded layout of the passes' targets (raster/context.LowResLayout)
        self.program = load_program(ctx, "ssao.glsl")
        self.blur = load_program(ctx, "bilateral_blur.glsl")
        self.vao = fullscreen_vao(ctx, self.program)
        self.blur_vao = fullscreen_vao(ctx, self.blur)
        self.size = None

    def resize(self, width: int, height: int) -> None:
        if self.size == (width, height):
            return
        if self.size is not None:
            for o in (self.fbo_a, self.fbo_b, self.fbo_out, self.tex_a, self.tex_b, self.tex_out):
                o.release()
        # the AO and the blur's first pass in the padded layout (their cost is in the shading); the
        # blur's last pass writes the unpadded AO that the lighting passes, the AOV and the viewer read
        self.layout = lay = low_res_layout(width, height, self.scale, self.balance)
        self.tex_a = self.ctx.texture(lay.texture_size, 1, dtype="f2")
        self.tex_b = self.ctx.texture(lay.texture_size, 1, dtype="f2")
        self.tex_out = self.ctx.texture(lay.size, 1, dtype="f2")
        for t in (self.tex_a, self.tex_b, self.tex_out):
            t.filter = (moderngl.LINEAR, moderngl.LINEAR)  # the blur and upsampling use texelFetch
            t.repeat_x = t.repeat_y = False
        self.fbo_a = self.ctx.framebuffer(color_attachments=[self.tex_a])
        self.fbo_b = self.ctx.framebuffer(color_attachments=[self.tex_b])
        self.fbo_out = self.ctx.framebuffer(color_attachments=[self.tex_out])
        for fbo in (self.fbo_a, self.fbo_b):
            fbo.viewport = lay.viewport
        self.size = (width, height)

    def render(self, gbuffer, view_proj: np.ndarray, camera_pos, camera_forward, guide):
        """AO texture (r16f, 1 = unoccluded) of the G-buffer, at ``low_res_size`` of the view;
        ``guide``: the frame's :class:`~serenity.raster.lowres.LowResGuide` texture (same scale)."""
        cfg = self.config
        cam = tuple(float(x) for x in camera_pos)
        fwd = tuple(float(x) for x in camera_forward)
        with self.ctx.debug_scope("ssao"):
            p = self.program
            self.fbo_a.use()
            gbuffer.position.use(location=0)
            gbuffer.normal.use(location=1)
            p["g_position"].value = 0
            p["g_normal"].value = 1
            p["u_view_proj"].write(view_proj.T.astype(np.float32).tobytes())
            p["u_camera_pos"].value = cam
            p["u_camera_forward"].value = fwd
            p["u_radius"].value = float(cfg.radius)
            p["u_bias"].value = float(cfg.bias)
            p["u_thickness"].value = float(cfg.thickness)
            p["u_directions"].value = int(cfg.directions)
            p["u_steps"].value = int(cfg.steps)
            p["u_scale"].value = self.scale
            lay = self.layout
            lay.set_uniforms(p)
            b = self.blur
            lay.set_uniforms(b)
            self.vao.render(vertices=3)
            guide.use(location=3)
            b["u_guide"].value = 3
            b["u_src"].value = 2
            if cfg.blur_radius <= 0:  # no blur: a radius-0 pass copies the AO into the unpadded texture
                passes = ((self.tex_a, self.fbo_out, (1.0, 0.0), 0),)
            else:
                r = max(1, round(cfg.blur_radius / self.scale))
                passes = ((self.tex_a, self.fbo_b, (1.0, 0.0), r), (self.tex_b, self.fbo_out, (0.0, 1.0), r))
            for src, dst, axis, radius in passes:
                finish(self.ctx)  # each pass reads the one before: wait with the GIL released
                dst.use()
                src.use(location=2)
                b["u_axis"].value = axis
                b["u_radius"].value = radius
                b["u_dst_origin"].value = (0, 0) if dst is self.fbo_out else lay.origin
                self.blur_vao.render(vertices=3)
        return self.tex_out

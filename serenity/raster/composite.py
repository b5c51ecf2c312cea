"""Fresnel composite of the reflection/refraction effect buffers over the main view
(``glsl/composite.glsl``)."""

from __future__ import annotations

from serenity.raster.context import fullscreen_vao, load_program


class CompositePass:
    def __init__(self, ctx):
        self.ctx = ctx
        self.program = load_program(ctx, "composite.glsl")
        self.vao = fullscreen_vao(ctx, self.program)
        self.size = None

    def resize(self, width: int, height: int) -> None:
        if self.size == (width, height):
            return
        if self.size is not None:
            self.fbo.release()
            self.hdr.release()
        self.hdr = self.ctx.texture((width, height), 4, dtype="f4")
        self.fbo = self.ctx.framebuffer(color_attachments=[self.hdr])
        self.size = (width, height)

    def render(self, surface, effects, gbuffer, flags, camera_pos):
        """``effects``: the lit ray-traced views, stacked (W, 2H): reflection on top, refraction
        below (see :mod:`serenity.raster.rt_gbuffer`). ``flags``: the ray-casting buffer target
        whose alpha holds the per-pixel flags."""
        p = self.program
        with self.ctx.debug_scope("composite"):
            self.fbo.use()
            for loc, (name, tex) in enumerate((("u_surface", surface), ("u_effects", effects),
                                               ("g_normal", gbuffer.normal),
                                               ("g_position", gbuffer.position), ("g_material", gbuffer.material),
                                               ("u_flags", flags))):
                tex.use(location=loc)
                p[name].value = loc
            p["u_camera_pos"].value = tuple(float(x) for x in camera_pos)
            self.vao.render(vertices=3)
        return self.hdr

"""G-buffer pass (paper §3): rasterise the scene into float targets for deferred lighting.

Targets (see ``glsl/gbuffer.glsl``): albedo (rgba16f), normal (rgba16f), position (rgba32f),
material (rgba16f) and a 32-bit depth buffer. The ray tracer fills a G-buffer of the same
layout for reflected/refracted views, so the same deferred pass lights both.
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from serenity.raster.context import load_program, uniform


@dataclass
class GBuffer:
    albedo: object
    normal: object
    position: object
    material: object
    depth: object
    width: int
    height: int


class GBufferPass:
    def __init__(self, ctx, scene_gl, texture_taps: int = 1):
        self.ctx = ctx
        self.scene_gl = scene_gl
        self.texture_taps = int(texture_taps)
        """Trilinear taps per textured fragment along the footprint's major axis (1 = plain GL)."""
        # one program for untextured materials and one for textured ones (``glsl/gbuffer.glsl``,
        # TEXTURE_TAPS): llvmpipe would otherwise sample for every fragment, textured or not
        self.program = load_program(ctx, "gbuffer.glsl", defines={"TEXTURE_TAPS": 0})
        self.vao = scene_gl.vao(self.program)
        self.program_textured = self.vao_textured = None  # only for a scene with textures
        if scene_gl.textures:
            self.program_textured = load_program(ctx, "gbuffer.glsl",
                                                 defines={"TEXTURE_TAPS": max(1, self.texture_taps)})
            self.vao_textured = scene_gl.vao(self.program_textured)
        self.size = None
        self.gbuffer = None

    def resize(self, width: int, height: int) -> None:
        if self.size == (width, height):
            return
        if self.gbuffer is not None:
            for t in (self.gbuffer.albedo, self.gbuffer.normal, self.gbuffer.position, self.gbuffer.material,
                      self.gbuffer.depth):
                t.release()
            self.fbo.release()
        ctx = self.ctx
        size = (width, height)
        g = GBuffer(
            albedo=ctx.texture(size, 4, dtype="f2"),
            normal=ctx.texture(size, 4, dtype="f2"),
            position=ctx.texture(size, 4, dtype="f4"),
            material=ctx.texture(size, 4, dtype="f2"),
            depth=ctx.depth_texture(size),
            width=width,
            height=height,
        )
        for t in (g.albedo, g.normal, g.position, g.material):
            t.filter = (moderngl.NEAREST, moderngl.NEAREST)
            t.repeat_x = t.repeat_y = False
        self.fbo = ctx.framebuffer(color_attachments=[g.albedo, g.normal, g.position, g.material],
                                   depth_attachment=g.depth)
        self.gbuffer = g
        self.size = size

    def render(self, view_proj: np.ndarray, camera_pos: np.ndarray) -> GBuffer:
        ctx = self.ctx
        with ctx.debug_scope("gbuffer"):
            self.fbo.use()
            self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.disable(moderngl.CULL_FACE)
            vp = view_proj.T.astype(np.float32).tobytes()
            for p in (self.program, self.program_textured):
                if p is not None:
                    p["u_view_proj"].write(vp)
                    if (u := uniform(p, "u_camera_pos")) is not None:
                        u.value = tuple(float(x) for x in camera_pos)
            for r in self.scene_gl.ranges:
                m = self.scene_gl.materials[r.material]
                tex = self.scene_gl.textures.get(r.material)
                p, vao = (self.program, self.vao) if tex is None else (self.program_textured, self.vao_textured)
                if tex is not None:
                    tex.use(location=0)
                    p["u_albedo_tex"].value = 0
                p["u_albedo"].value = tuple(float(x) for x in m.albedo)
                p["u_material_index"].value = float(r.material)
                p["u_specular"].value = float(m.specular)
                p["u_material"].value = (float(m.shininess), float(m.reflectivity), float(m.transparency),
                                         float(m.ior))
                vao.render(moderngl.TRIANGLES, vertices=r.count, first=r.first)
            ctx.disable(moderngl.DEPTH_TEST)
        return self.gbuffer

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
from serenity.raster.scene_gl import LOD_PIXEL_ERROR
from serenity.scene.model import normal_map_frame


def _uv_uniforms(program, prefix: str, m: np.ndarray) -> None:
    """A (2, 3) uv transform as the two row uniforms ``prefix``0 and ``prefix``1 (where the variant reads them)."""
    for k in range(2):
        if (u := uniform(program, f"{prefix}{k}")) is not None:
            u.value = tuple(float(x) for x in m[k])


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
        # one program per variant drawn (``glsl/gbuffer.glsl``): untextured (TEXTURE_TAPS 0), textured,
        # and the cut-outs' and normal-mapped materials' variants — llvmpipe would otherwise sample for
        # every fragment, textured or not
        self._programs: dict[tuple[bool, bool, bool], tuple] = {}
        self.program, self.vao = self._variant(False, False, False)
        self.program_textured = self.vao_textured = None  # only for a scene with textures
        if scene_gl.textures:
            self.program_textured, self.vao_textured = self._variant(True, False, False)
        self.size = None
        self.gbuffer = None
        self.ranges = scene_gl.culled(scene_gl.ranges + scene_gl.lod_ranges)
        #: skip the draw ranges outside the view frustum (``culling.py``; the image is the same)
        self.cull = True
        #: draw each dense mesh at the coarsest level of detail within this many pixels of its surface
        #: (``SceneGL.levels``; 0 = the full meshes)
        self.lod_pixel_error = LOD_PIXEL_ERROR
        #: (draw ranges drawn, draw ranges) of the last ``render``
        self.last_draws = (0, len(self.ranges.ranges))

    def _variant(self, textured: bool, masked: bool, normal_map: bool) -> tuple:
        key = (textured or masked, masked, normal_map)
        if key not in self._programs:
            p = load_program(self.ctx, "gbuffer.glsl", defines={
                "TEXTURE_TAPS": max(1, self.texture_taps) if key[0] else 0, "ALPHA_MASK": int(masked),
                "NORMAL_MAP": int(normal_map)})
            self._programs[key] = (p, self.scene_gl.vao(p))
        return self._programs[key]

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
            cam = tuple(float(x) for x in camera_pos)
            sgl = self.scene_gl
            ready = set()  # programs whose per-frame uniforms are set
            levels = sgl.levels(view_proj, self.size[0], self.size[1], self.lod_pixel_error)
            for r in self.ranges.visible(view_proj if self.cull else None, levels=levels):
                m = sgl.materials[r.material]
                tex = sgl.textures.get(r.material)
                ntex = sgl.normal_textures.get(r.material)
                p, vao = self._variant(tex is not None, m.alpha_tested, ntex is not None)
                if id(p) not in ready:
                    ready.add(id(p))
                    p["u_view_proj"].write(vp)
                    if (u := uniform(p, "u_camera_pos")) is not None:
                        u.value = cam
                if tex is not None:
                    tex.use(location=0)
                    p["u_albedo_tex"].value = 0
                    _uv_uniforms(p, "u_albedo_uv", m.albedo_uv_transform)
                if m.alpha_tested:
                    p["u_alpha"].value = float(m.alpha)
                    p["u_alpha_cutoff"].value = float(m.alpha_cutoff)
                if ntex is not None:
                    ntex.use(location=1)
                    p["u_normal_tex"].value = 1
                    _uv_uniforms(p, "u_normal_uv", m.normal_uv_transform)
                    p["u_normal_frame"].write(normal_map_frame(m.normal_uv_transform).T.astype(np.float32).tobytes())
                    p["u_normal_scale"].value = float(m.normal_scale)
                p["u_albedo"].value = tuple(float(x) for x in m.albedo)
                p["u_material_index"].value = float(r.material)
                p["u_specular"].value = float(m.specular)
                p["u_material"].value = (float(m.shininess), float(m.reflectivity), float(m.transparency),
                                         float(m.ior))
                vao.render(moderngl.TRIANGLES, vertices=r.count, first=r.first)
            self.last_draws = (self.ranges.drawn, self.ranges.candidates)
            ctx.disable(moderngl.DEPTH_TEST)
        return self.gbuffer

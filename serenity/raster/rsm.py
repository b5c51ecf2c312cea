"""Reflective shadow map of the sun (paper §8): the light propagation volumes' virtual point lights.

The sun's orthographic view of the scene's bounding sphere (``ShadowPass``'s single-map fit),
``size``² texels; each covered texel becomes a VPL at its surface point with normal n and flux
ρ·E·A (W), A = the texel's area perpendicular to the sun. The sum of all VPL fluxes is therefore
the sun power the scene's directly lit surfaces reflect diffusely.

ρ of a textured material is the material albedo times the texture's mean: an RSM texel (and the
LPV cell it lands in) is far coarser than texture detail, and binding a texture per draw made this
256² pass cost ~115 ms instead of ~1.5 ms on llvmpipe (measured on the courtyard). Cut-outs
(``Material.alpha_tested``) are the exception: they are drawn with their texture's alpha test
(``rsm.glsl``'s ALPHA_MASK variant), so light passes their holes as it does in the shadow maps.
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from serenity.raster.context import load_program
from serenity.raster.interop import read_texture
from serenity.raster.scene_gl import LOD_PIXEL_ERROR
from serenity.raster.shadow import look_at, ortho


@dataclass
class VPLs:
    """Virtual point lights: positions (N,3) m, normals (N,3), flux (N,3) W, texel_area m²."""

    positions: np.ndarray
    normals: np.ndarray
    flux: np.ndarray
    texel_area: float

    @property
    def count(self) -> int:
        return int(len(self.positions))


def fit_sun_view(sun_direction, bounds) -> tuple[np.ndarray, float]:
    """World → light clip for an orthographic sun view of the bounds' sphere; returns (M, radius)."""
    center = bounds.mean(axis=0)
    radius = max(float(np.linalg.norm(bounds[1] - bounds[0])) / 2, 1e-3) * 1.01
    eye = center + np.asarray(sun_direction, np.float64) * radius * 2
    view = look_at(eye, center, np.array([0.0, 1.0, 0.0]))
    return ortho(-radius, radius, -radius, radius, radius * 0.5, radius * 3.5) @ view, radius


class RSMPass:
    def __init__(self, ctx, scene_gl, size: int = 256):
        self.ctx = ctx
        self.scene_gl = scene_gl
        self.size = size
        self.program = load_program(ctx, "rsm.glsl")
        self.vao = scene_gl.vao(self.program)
        self.program_masked = self.vao_masked = None  # cut-outs: the alpha test (ALPHA_MASK)
        if any(scene_gl.materials[r.material].alpha_tested for r in scene_gl.ranges):
            self.program_masked = load_program(ctx, "rsm.glsl", defines={"ALPHA_MASK": 1})
            self.vao_masked = scene_gl.vao(self.program_masked)
        self.targets = [ctx.texture((size, size), 4, dtype="f4") for _ in range(3)]
        for t in self.targets:
            t.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.depth = ctx.depth_texture((size, size))
        self.fbo = ctx.framebuffer(color_attachments=self.targets, depth_attachment=self.depth)
        self.ranges = scene_gl.culled(scene_gl.ranges + scene_gl.lod_ranges)
        #: skip the draw ranges outside the sun's view (``culling.py``; the map is the same)
        self.cull = True
        #: ``RenderConfig.lod_pixel_error``: each dense mesh is drawn at the coarsest level of detail
        #: within this many texels of its surface (``SceneGL.levels``; 0 = the full meshes)
        self.lod_pixel_error = LOD_PIXEL_ERROR
        #: (draw ranges drawn, draw ranges) of the last ``render``
        self.last_draws = (0, len(self.ranges.ranges))

    def render(self, sun_direction, sun_irradiance, bounds) -> None:
        ctx, p = self.ctx, self.program
        vp, radius = fit_sun_view(sun_direction, bounds)
        self.texel_area = (2 * radius / self.size) ** 2
        with ctx.debug_scope("rsm"):
            self.fbo.use()
            self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.disable(moderngl.CULL_FACE)
            for q in (p, self.program_masked):
                if q is not None:
                    q["u_view_proj"].write(vp.T.astype(np.float32).tobytes())
                    q["u_sun_dir"].value = tuple(float(x) for x in sun_direction)
                    q["u_sun_irradiance"].value = tuple(float(x) for x in sun_irradiance)
                    q["u_texel_area"].value = float(self.texel_area)
            levels = self.scene_gl.levels(vp, self.size, self.size, self.lod_pixel_error)
            for r in self.ranges.visible(vp if self.cull else None, levels=levels):
                m = self.scene_gl.materials[r.material]
                albedo = np.asarray(m.albedo, np.float64) * self.scene_gl.mean_texture_albedo.get(r.material, 1.0)
                q, vao = (self.program_masked, self.vao_masked) if m.alpha_tested else (p, self.vao)
                if m.alpha_tested:
                    self.scene_gl.bind_alpha_test(q, r.material)
                q["u_albedo"].value = tuple(float(x) for x in albedo)
                vao.render(moderngl.TRIANGLES, vertices=r.count, first=r.first)
            self.last_draws = (self.ranges.drawn, self.ranges.candidates)
            ctx.disable(moderngl.DEPTH_TEST)

    def read(self) -> VPLs:
        flux, nrm, pos = (read_texture(t, 4).reshape(-1, 4) for t in self.targets)
        # covered texels with flux (channel by channel and np.take: a max over the strided (N, 3) view
        # and boolean indexing of it cost 1.5 ms of a 128² map's 1.8 ms)
        keep = np.flatnonzero((flux[:, 3] > 0) & ((flux[:, 0] > 0) | (flux[:, 1] > 0) | (flux[:, 2] > 0)))
        pos, nrm, flux = (np.take(a, keep, axis=0)[:, :3].copy() for a in (pos, nrm, flux))
        return VPLs(pos, nrm, flux, float(self.texel_area))

"""Ray-casting buffer pass (paper §9, Fig. 12–13): which pixels need ray tracing, and their rays.

The whole scene is drawn (opaque surfaces hide reflective ones behind them) with a small shader
that writes, for reflective/refractive pixels only, the ray origin, reflected and refracted
directions and the ray cone (``glsl/raycast.glsl``). ``read()`` brings it back to the CPU as
compact ray lists: only the pixels that need rays (paper: "ray tracing only where pixels need it").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import moderngl
import numpy as np

from serenity.raster.context import load_program
from serenity.raster.interop import read_texture

TRACE_REFLECTION = 1
TRACE_REFRACTION = 2
TOTAL_INTERNAL_REFLECTION = 4


@dataclass
class RayCastingBuffer:
    """Compacted rays of the pixels that need them (row 0 = top; index = row * width + col).

    pixels: (N,) int32 flat pixel indices.  origins: (N,3).  reflect_dirs / refract_dirs: (N,3)
    (refraction zero where not traced).  cone_width: (N,) m at the surface.  cone_spread: (N,) rad.
    flags: (N,) int32 of TRACE_REFLECTION | TRACE_REFRACTION | TOTAL_INTERNAL_REFLECTION.
    normals: (N,3) viewer-facing shading normals.  material: (N,) int32.
    """

    width: int
    height: int
    pixels: np.ndarray
    origins: np.ndarray
    reflect_dirs: np.ndarray
    refract_dirs: np.ndarray
    cone_width: np.ndarray
    cone_spread: np.ndarray
    flags: np.ndarray
    normals: np.ndarray
    material: np.ndarray

    @property
    def count(self) -> int:
        return int(len(self.pixels))

    def reflection_rays(self) -> np.ndarray:
        """(N,) bool: the rays with a reflected direction to trace."""
        return (self.flags & TRACE_REFLECTION) != 0

    def refraction_rays(self) -> np.ndarray:
        """(N,) bool: the rays with a refracted direction to trace (not under total internal reflection)."""
        return ((self.flags & TRACE_REFRACTION) != 0) & np.any(self.refract_dirs != 0, axis=1)

    def select(self, reflections: bool = True, refractions: bool = True) -> RayCastingBuffer:
        """This buffer with only the ray kinds switched on (``RenderConfig.reflections`` /
        ``.refractions``): the other kind's flag cleared, and pixels left with no ray to trace
        dropped. The composite shows the rasterised surface where a pixel's ray is missing."""
        if reflections and refractions:
            return self
        flags = self.flags.copy()
        if not reflections:
            flags &= ~TRACE_REFLECTION
        if not refractions:
            flags &= ~TRACE_REFRACTION
        keep = ((flags & TRACE_REFLECTION) != 0) | (((flags & TRACE_REFRACTION) != 0)
                                                    & np.any(self.refract_dirs != 0, axis=1))
        return RayCastingBuffer(self.width, self.height, self.pixels[keep], self.origins[keep],
                                self.reflect_dirs[keep], self.refract_dirs[keep], self.cone_width[keep],
                                self.cone_spread[keep], flags[keep], self.normals[keep], self.material[keep])

    def mask(self) -> np.ndarray:
        m = np.zeros(self.width * self.height, bool)
        m[self.pixels] = True
        return m.reshape(self.height, self.width)


class RayCastPass:
    def __init__(self, ctx, scene_gl):
        self.ctx = ctx
        self.scene_gl = scene_gl
        self.program = load_program(ctx, "raycast.glsl")
        self.vao = scene_gl.vao(self.program, with_attributes=("in_position", "in_normal"))
        self.size = None
        self.any_traced_material = any(m.needs_ray_tracing for m in scene_gl.materials)

    def resize(self, width: int, height: int) -> None:
        if self.size == (width, height):
            return
        if self.size is not None:
            self.fbo.release()
            for t in self.targets:
                t.release()
            self.depth.release()
        self.targets = [self.ctx.texture((width, height), 4, dtype="f4") for _ in range(4)]
        for t in self.targets:
            t.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.depth = self.ctx.depth_texture((width, height))
        self.fbo = self.ctx.framebuffer(color_attachments=self.targets, depth_attachment=self.depth)
        self.size = (width, height)

    def render(self, view_proj: np.ndarray, camera) -> None:
        ctx, p = self.ctx, self.program
        w, h = self.size
        with ctx.debug_scope("raycast"):
            self.fbo.use()
            self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.disable(moderngl.CULL_FACE)
            p["u_view_proj"].write(view_proj.T.astype(np.float32).tobytes())
            p["u_camera_pos"].value = tuple(float(x) for x in camera.position)
            p["u_pixel_spread"].value = math.atan(2 * math.tan(math.radians(camera.fov_y_deg) / 2) / h)
            for r in self.scene_gl.ranges:
                m = self.scene_gl.materials[r.material]
                p["u_reflectivity"].value = float(m.reflectivity)
                p["u_transparency"].value = float(m.transparency)
                p["u_ior"].value = float(m.ior)
                p["u_material_index"].value = float(r.material)
                self.vao.render(moderngl.TRIANGLES, vertices=r.count, first=r.first)
            ctx.disable(moderngl.DEPTH_TEST)

    def read(self) -> RayCastingBuffer:
        """Read back (sync point 1 of paper §10) and compact to the pixels that need rays."""
        w, h = self.size
        origin, refl, refr, nrm = (read_texture(t, 4).reshape(-1, 4) for t in self.targets)
        flags = refr[:, 3].astype(np.int32)
        pix = np.flatnonzero(flags > 0).astype(np.int32)
        return RayCastingBuffer(
            width=w, height=h, pixels=pix,
            origins=np.ascontiguousarray(origin[pix, :3]),
            reflect_dirs=np.ascontiguousarray(refl[pix, :3]),
            refract_dirs=np.ascontiguousarray(refr[pix, :3]),
            cone_width=np.ascontiguousarray(origin[pix, 3]),
            cone_spread=np.ascontiguousarray(refl[pix, 3]),
            flags=flags[pix],
            normals=np.ascontiguousarray(nrm[pix, :3]),
            material=nrm[pix, 3].astype(np.int32),
        )

"""Ray-casting buffer pass (paper §9, Fig. 12–13): which pixels need ray tracing, and their rays.

Drawn after the G-buffer, against its depth buffer: only the reflective/refractive material ranges
are rasterised, and a fragment survives only where its surface is the visible one (opaque surfaces
in front already hid it in the G-buffer's depth). Each surviving fragment appends the ray origin,
reflected and refracted directions, ray cone, flags, normal, material and pixel to a storage buffer
through an atomic counter (``glsl/raycast.glsl``), so ``read()`` brings back only the pixels that
need rays (paper: "ray tracing only where pixels need it") — the count and N records, sorted by
pixel so the order does not depend on the rasteriser's threads. Before, the whole scene was drawn
into four full-screen RGBA32F targets that were read back whole: at 640×360 that was 14–17 CPU-ms
of drawing and 15–16 of read-back for ~4k rays on llvmpipe.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import moderngl
import numpy as np

from serenity.raster.context import finish, load_program

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


RECORD_VEC4S = 5
"""vec4s per ray record in the storage buffer (``glsl/raycast.glsl``)."""


class RayCastPass:
    def __init__(self, ctx, scene_gl):
        self.ctx = ctx
        self.scene_gl = scene_gl
        self.program = load_program(ctx, "raycast.glsl")
        self.vao = scene_gl.vao(self.program, with_attributes=("in_position", "in_normal"))
        self.size = None
        self.traced_ranges = [r for r in scene_gl.ranges if scene_gl.materials[r.material].needs_ray_tracing]
        self.any_traced_material = bool(self.traced_ranges)
        self.counter = ctx.buffer(reserve=4)
        self.records = None
        self.fbo = None
        self._depth = None

    def resize(self, width: int, height: int) -> None:
        if self.size == (width, height):
            return
        if self.records is not None:
            self.records.release()
        # one record per pixel at most (a pixel's visible surface is one fragment; coplanar ties
        # can add a second, dropped on read)
        self.records = self.ctx.buffer(reserve=width * height * RECORD_VEC4S * 16)
        self.size = (width, height)

    def render(self, view_proj: np.ndarray, camera, depth) -> None:
        """Append the rays of the reflective/refractive pixels; ``depth``: the frame's G-buffer
        depth texture (already rendered with the same ``view_proj``)."""
        ctx, p = self.ctx, self.program
        w, h = self.size
        self.counter.write(np.zeros(1, np.uint32).tobytes())
        if not self.traced_ranges:
            return
        if self._depth is not depth:
            if self.fbo is not None:
                self.fbo.release()
            self.fbo = ctx.framebuffer(depth_attachment=depth)
            self._depth = depth
        with ctx.debug_scope("raycast"):
            self.fbo.use()
            self.fbo.depth_mask = False
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.depth_func = "<="
            ctx.disable(moderngl.CULL_FACE)
            self.counter.bind_to_storage_buffer(0)
            self.records.bind_to_storage_buffer(1)
            p["u_view_proj"].write(view_proj.T.astype(np.float32).tobytes())
            p["u_camera_pos"].value = tuple(float(x) for x in camera.position)
            p["u_pixel_spread"].value = math.atan(2 * math.tan(math.radians(camera.fov_y_deg) / 2) / h)
            p["u_width"].value = w
            p["u_height"].value = h
            p["u_capacity"].value = w * h
            for r in self.traced_ranges:
                m = self.scene_gl.materials[r.material]
                p["u_transparency"].value = float(m.transparency)
                p["u_ior"].value = float(m.ior)
                p["u_material_index"].value = float(r.material)
                self.vao.render(moderngl.TRIANGLES, vertices=r.count, first=r.first)
            ctx.disable(moderngl.DEPTH_TEST)
            ctx.depth_func = "<"
            self.fbo.depth_mask = True

    def read(self) -> RayCastingBuffer:
        """Read back (sync point 1 of paper §10): the count, then only that many records."""
        w, h = self.size
        n = 0
        if self.traced_ranges:
            # llvmpipe does not count a draw's storage-buffer writes as pending on the buffer: a read
            # without the barrier and the finish returns what the previous draw left
            self.ctx.memory_barrier()
            finish(self.ctx)
            n = min(int(np.frombuffer(self.counter.read(), np.uint32)[0]), w * h)
        rec = np.frombuffer(self.records.read(size=n * RECORD_VEC4S * 16), np.float32) if n else \
            np.zeros(0, np.float32)
        rec = rec.reshape(n, RECORD_VEC4S, 4)
        pix = rec[:, 4, 0].astype(np.int32)
        # pixel order (the atomic counter's is the rasteriser threads'); a coplanar tie's second
        # fragment on the same pixel is dropped
        pix, first = np.unique(pix, return_index=True)
        rec = rec[first]
        return RayCastingBuffer(
            width=w, height=h, pixels=pix,
            origins=np.ascontiguousarray(rec[:, 0, :3]),
            reflect_dirs=np.ascontiguousarray(rec[:, 1, :3]),
            refract_dirs=np.ascontiguousarray(rec[:, 2, :3]),
            cone_width=np.ascontiguousarray(rec[:, 0, 3]),
            cone_spread=np.ascontiguousarray(rec[:, 1, 3]),
            flags=rec[:, 2, 3].astype(np.int32),
            normals=np.ascontiguousarray(rec[:, 3, :3]),
            material=rec[:, 3, 3].astype(np.int32),
        )

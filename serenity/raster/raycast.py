"""Ray-casting buffer pass (paper §9, Fig. 12–13): which pixels need ray tracing, and their rays.

Each pixel whose visible surface reflects or refracts appends the ray origin, reflected and
refracted directions, ray cone, flags, normal, material and pixel to a storage buffer through an
atomic counter (``glsl/raycast.glsl``), so ``read()`` brings back only the pixels that need rays
(paper: "ray tracing only where pixels need it") — the count and N records, sorted by pixel so the
order does not depend on the rasteriser's threads. The pixels are found one of two ways, whichever
costs less this frame: the paper's, rasterising the reflective and refractive ranges again against
the G-buffer's depth (its cost follows their triangles: 21 ms for the breakfast room's 105k chrome
triangles at 320×180 on llvmpipe, 0.5 ms for the courtyard's mirror and windows), or a fullscreen
pass that reads each pixel's point, normal and material from the G-buffer over the screen tiles
those ranges' boxes cover (its cost follows the pixels: 2 ms for the whole 320×180 view).
``PIXELS_PER_TRIANGLE`` weighs one against the other; both give the same rays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import moderngl
import numpy as np

from serenity.raster.context import draw_fullscreen, finish, fullscreen_vao, load_program
from serenity.raster.culling import boxes_in_frustum

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
        """This buffer with only the ray kinds switched on (``RayTracingConfig.reflections`` /
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


PIXELS_PER_TRIANGLE = 5.0
"""What one reflective or refractive triangle rasterised again costs, in pixels of the fullscreen
pass (llvmpipe, 2 cores: 105k triangles about 20 ms, 57,600 pixels about 2 ms, so ~5)."""
TILE = 32
"""Pixels per side of the screen tiles the pass shades (``RayCastPass.tiles``)."""
RECORD_VEC4S = 5
"""vec4s per ray record in the storage buffer (``glsl/raycast.glsl``)."""


class RayCastPass:
    def __init__(self, ctx, scene_gl):
        self.ctx = ctx
        self.scene_gl = scene_gl
        self.program = load_program(ctx, "raycast.glsl", defines={"FROM_GBUFFER": 1})
        self.vao = fullscreen_vao(ctx, self.program)
        self.program_geometry = load_program(ctx, "raycast.glsl", defines={"FROM_GBUFFER": 0})
        self.vao_geometry = scene_gl.vao(self.program_geometry, with_attributes=("in_position", "in_normal"))
        self.size = None
        traced = [r for r in scene_gl.ranges if scene_gl.materials[r.material].needs_ray_tracing]
        self.traced_ranges = traced
        self.any_traced_material = bool(traced)
        #: which way the last ``render`` found the pixels: "gbuffer", "geometry" or None (nothing to find)
        self.last_method: str | None = None
        #: the reflective and refractive draw ranges' world boxes (``lo``, ``hi``: (R, 3), following
        #: moving meshes): the pass shades only the screen tiles they cover
        self.traced_culled = scene_gl.culled(traced)
        #: rectangles (x, y, w, h) the last ``render`` shaded (the fullscreen way)
        self.last_rects: list[tuple[int, int, int, int]] = []
        self.counter = ctx.buffer(reserve=4)
        self.records = None
        self.fbo = None
        self._depth = self._depth_fbo = None  # the geometry way's framebuffer: the G-buffer's depth

    def resize(self, width: int, height: int) -> None:
        if self.size == (width, height):
            return
        if self.records is not None:
            self.records.release()
            self.fbo.release()
        # one record per pixel at most
        self.records = self.ctx.buffer(reserve=width * height * RECORD_VEC4S * 16)
        # the pass writes the storage buffer only: a masked 8-bit target keeps the framebuffer complete
        self._target = self.ctx.texture((width, height), 1, dtype="f1")
        self.fbo = self.ctx.framebuffer(color_attachments=[self._target])
        self.fbo.color_mask = (False, False, False, False)
        self.size = (width, height)

    def tiles(self, view_proj: np.ndarray, visible: np.ndarray) -> list[tuple[int, int, int, int]]:
        """Scissor rectangles (x, y, w, h; GL origin bottom-left), not overlapping, over the
        ``TILE``-pixel tiles that the boxes of the reflective and refractive ranges in the frustum
        (``visible``, a mask) cover on screen (all of the view where a box reaches behind the
        camera): a fullscreen pass over a courtyard whose mirror fills 2 % of the view cost 4 times
        the geometry it replaces."""
        w, h = self.size
        lo, hi = self.traced_culled.lo[visible], self.traced_culled.hi[visible]
        if not len(lo):
            return []
        corners = np.stack([np.where(np.array([(k >> a) & 1 for a in range(3)], bool), hi, lo)
                            for k in range(8)], axis=1)                                     # (R, 8, 3)
        clip = corners @ view_proj[:3, :3].T + view_proj[:3, 3]
        cw = corners @ view_proj[3, :3] + view_proj[3, 3]                                    # (R, 8)
        tx, ty = -(-w // TILE), -(-h // TILE)
        mask = np.zeros((ty, tx), bool)
        for c, ww in zip(clip, cw, strict=True):
            if np.any(ww <= 1e-6):  # reaches behind the camera: its projection is unbounded
                mask[:] = True
                break
            ndc = c[:, :2] / ww[:, None]
            x0, y0 = np.floor((ndc.min(axis=0) * 0.5 + 0.5) * (w, h)).astype(int)
            x1, y1 = np.ceil((ndc.max(axis=0) * 0.5 + 0.5) * (w, h)).astype(int)
            x0, x1 = max(x0, 0) // TILE, min(x1, w) - 1
            y0, y1 = max(y0, 0) // TILE, min(y1, h) - 1
            if x1 >= 0 and y1 >= 0 and x0 * TILE <= x1 and y0 * TILE <= y1:
                mask[y0:y1 // TILE + 1, x0:x1 // TILE + 1] = True
        rects = []
        for j in range(ty):  # each row's runs of covered tiles, one rectangle each
            row = np.flatnonzero(np.diff(np.concatenate(([0], mask[j].astype(np.int8), [0]))))
            for a, b in zip(row[::2], row[1::2], strict=True):
                x, y = a * TILE, j * TILE
                rects.append((x, y, min(b * TILE, w) - x, min(y + TILE, h) - y))
        return rects

    def render(self, view_proj: np.ndarray, camera, gbuffer, method: str | None = None) -> None:
        """Append the rays of the reflective/refractive pixels of ``gbuffer`` (the frame's G-buffer,
        drawn from ``camera`` with ``view_proj``); ``method`` "gbuffer" or "geometry" forces one way
        (None: the cheaper, module doc)."""
        self.counter.write(np.zeros(1, np.uint32).tobytes())
        self.last_rects, self.last_method = [], None
        if not self.traced_ranges:
            return
        visible = boxes_in_frustum(view_proj, self.traced_culled.lo, self.traced_culled.hi)
        rects = self.tiles(view_proj, visible)
        if not rects:
            return
        triangles = sum(r.count for r, k in zip(self.traced_ranges, visible, strict=True) if k) // 3
        pixels = sum(r[2] * r[3] for r in rects)
        if method is None:
            method = "geometry" if triangles * PIXELS_PER_TRIANGLE < pixels else "gbuffer"
        self.last_method = method
        if method == "geometry":
            self._render_geometry(view_proj, camera, gbuffer.depth, visible)
            return
        self.last_rects = rects
        ctx, p = self.ctx, self.program
        with ctx.debug_scope("raycast"):
            self.fbo.use()
            for loc, (name, tex) in enumerate((("g_albedo", gbuffer.albedo), ("g_normal", gbuffer.normal),
                                               ("g_position", gbuffer.position), ("g_material", gbuffer.material))):
                tex.use(location=loc)
                p[name].value = loc
            self._bind_records(p, camera)
            draw_fullscreen(ctx, self.vao, self.last_rects)

    def _bind_records(self, p, camera) -> None:
        """The storage buffers and the uniforms both ways' programs share (``append_rays``)."""
        w, h = self.size
        self.counter.bind_to_storage_buffer(0)
        self.records.bind_to_storage_buffer(1)
        p["u_camera_pos"].value = tuple(float(x) for x in camera.position)
        p["u_pixel_spread"].value = math.atan(2 * math.tan(math.radians(camera.fov_y_deg) / 2) / h)
        p["u_width"].value = w
        p["u_height"].value = h
        p["u_capacity"].value = w * h

    def _render_geometry(self, view_proj, camera, depth, visible) -> None:
        """The paper's way: the visible reflective/refractive ranges drawn against ``depth``."""
        ctx, p = self.ctx, self.program_geometry
        if self._depth is not depth:
            if self._depth_fbo is not None:
                self._depth_fbo.release()
            self._depth_fbo = ctx.framebuffer(depth_attachment=depth)
            self._depth = depth
        with ctx.debug_scope("raycast"):
            fbo = self._depth_fbo
            fbo.use()
            fbo.depth_mask = False
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.depth_func = "<="
            ctx.disable(moderngl.CULL_FACE)
            self._bind_records(p, camera)
            p["u_view_proj"].write(view_proj.T.astype(np.float32).tobytes())
            try:
                for r, k in zip(self.traced_ranges, visible, strict=True):
                    if not k:
                        continue
                    m = self.scene_gl.materials[r.material]
                    p["u_transparency"].value = float(m.transparency)
                    p["u_ior"].value = float(m.ior)
                    p["u_material_index"].value = float(r.material)
                    self.vao_geometry.render(moderngl.TRIANGLES, vertices=r.count, first=r.first)
            finally:
                ctx.disable(moderngl.DEPTH_TEST)
                ctx.depth_func = "<"
                fbo.depth_mask = True

    def read(self) -> RayCastingBuffer:
        """Read back (sync point 1 of paper §10): the count, then only that many records."""
        w, h = self.size
        n = 0
        if self.last_method is not None:  # else nothing was drawn: the counter holds its reset 0
            # llvmpipe does not count a draw's storage-buffer writes as pending on the buffer: a read
            # without the barrier and the finish returns what the previous draw left
            self.ctx.memory_barrier()
            finish(self.ctx)
            n = min(int(np.frombuffer(self.counter.read(), np.uint32)[0]), w * h)
        rec = np.frombuffer(self.records.read(size=n * RECORD_VEC4S * 16), np.float32) if n else \
            np.zeros(0, np.float32)
        rec = rec.reshape(n, RECORD_VEC4S, 4)
        pix = rec[:, 4, 0].astype(np.int32)
        # pixel order (the atomic counter's is the rasteriser threads'); with the geometry, a coplanar
        # tie's second fragment on the same pixel is dropped
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

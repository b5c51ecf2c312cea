"""Ray-traced G-buffers on the GL side (paper §9, Fig. 14–16): the CPU ray tracer's hits, scattered
back to their pixels and uploaded as textures with the rasterised G-buffer's layout, so the same
deferred lighting program lights them.

Packed, not per pixel: the traced rays — reflection rays first, then refraction rays, each in the
order of ``rcb.pixels`` — fill the texels of a (W, 2H) target in order, k → (k mod W, k div W)
(GL texel coordinates), so the lighting passes draw only the ``ceil(N / W)`` rows the N rays fill
(``RTView.rects``) instead of the screen rectangles around them: on a CPU rasteriser the cost of a
pass is its pixels, and a mirror seen at a grazing angle covers a large rectangle with few traced
pixels. ``RTView.points`` lists, for each traced screen pixel, its reflection and refraction texels
(−1: none; −2 for the refraction: total internal reflection); the composite
(``glsl/composite.glsl``) draws one point per entry and reads the lit rays through it.

Per-pixel layout (as ``glsl/gbuffer.glsl``): albedo.rgb; normal.xyz + specular k_s in w;
position.xyz + coverage in w (1 = hit, 0 = miss: the deferred pass shows the sky along the ray);
material = (shininess, reflectivity, transparency, ior); plus, for ray-traced views only, eye.xyz
(the ray origin: the viewer of that pixel; w = the sun's visibility when the tracer cast shadow
rays) and ray_dir.xyz (0 = pixel not traced).
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from serenity.gbuffer_layout import GBUFFER_TARGETS, RT_GBUFFER_KEYS
from serenity.raster.raycast import TOTAL_INTERNAL_REFLECTION


@dataclass
class RTView:
    """The packed ray-traced G-buffer textures, (W, 2H) each, and the composite's points."""

    albedo: object
    normal: object
    position: object
    material: object
    eye: object
    ray_dir: object
    width: int
    height: int  # the view's height; the packed textures are 2 * height tall
    rects: list = None
    """(x, y, w, h) GL texels of the packed target that hold rays this frame: the only texels
    written and the only ones the lighting passes draw."""
    points: np.ndarray = None
    """(N, 3) float32, one row per pixel of the frame's ray-casting buffer: flat pixel index
    (row 0 = top), the packed texel k of its reflection ray, of its refraction ray (−1: not
    traced; −2: total internal reflection, no refraction)."""


class RTGBufferUpload:
    """Owns the stacked textures and the CPU staging images (reused every frame: no allocation)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.size = None
        self.view: RTView | None = None

    def resize(self, width: int, height: int) -> None:
        if self.size == (width, height):
            return
        if self.view is not None:
            for n in RT_GBUFFER_KEYS:
                getattr(self.view, n).release()
        tex = {}
        for n in RT_GBUFFER_KEYS:
            t = self.ctx.texture((width, 2 * height), 4, dtype="f4")
            t.filter = (moderngl.NEAREST, moderngl.NEAREST)
            t.repeat_x = t.repeat_y = False
            tex[n] = t
        self.view = RTView(**tex, width=width, height=height)
        self._staging = {n: np.zeros((2 * height, width, 4), np.float32) for n in RT_GBUFFER_KEYS}
        self.size = (width, height)

    def upload(self, rcb, reflection: dict | None, refraction: dict | None) -> RTView:
        """Pack the tracer's per-ray results, upload them, and list the composite's points.

        ``rcb``: the frame's :class:`~serenity.raster.raycast.RayCastingBuffer`. ``reflection`` /
        ``refraction``: the ray tracer's outputs for ``rcb.reflection_rays()`` /
        ``rcb.refraction_rays()``, in the order of ``rcb.pixels``, each with (N, 4) arrays under the
        names of ``RT_GBUFFER_KEYS`` (``eye``/``ray_dir``: the last segment of each ray)."""
        w, h = self.size
        points = np.full((rcb.count, 3), -1.0, np.float32)
        points[:, 0] = rcb.pixels
        count = 0
        flat = {n: self._staging[n].reshape(-1, 4) for n in RT_GBUFFER_KEYS}
        for channel, res, sel in ((0, reflection, rcb.reflection_rays()), (1, refraction, rcb.refraction_rays())):
            if res is None or not sel.any():
                continue
            pix = rcb.pixels[sel]
            k = count + np.arange(len(pix))
            for n in GBUFFER_TARGETS:
                flat[n][k] = res[n]
            # the viewer and direction of the ray's last segment (after any transmissions); eye.w:
            # the sun's visibility from the tracer's shadow ray (RayTracingConfig.sun_shadows)
            flat["eye"][k] = res["eye"]
            flat["ray_dir"][k, :3] = res["ray_dir"][:, :3]
            points[sel, 1 + channel] = k
            count += len(pix)
        points[(rcb.flags & TOTAL_INTERNAL_REFLECTION) != 0, 2] = -2.0  # the composite's F = 1
        rects = []
        if count:
            used = -(-count // w)  # whole rows; the tail of the last one is marked untraced
            tail = slice(count, used * w)
            for n in RT_GBUFFER_KEYS:
                flat[n][tail] = 0.0
            rect = (0, 0, w, used)
            for n in RT_GBUFFER_KEYS:
                getattr(self.view, n).write(np.ascontiguousarray(self._staging[n][:used]).tobytes(), viewport=rect)
            rects.append(rect)
        self.view.rects = rects
        self.view.points = points
        return self.view

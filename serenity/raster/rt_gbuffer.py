"""Ray-traced G-buffers on the GL side (paper §9, Fig. 14–16): the CPU ray tracer's hits, scattered
back to their pixels and uploaded as textures with the rasterised G-buffer's layout, so the same
deferred lighting program lights them.

Reflection and refraction share one stacked target of (W, 2H) texels: the top half of the image
(GL v ∈ [0.5, 1)) holds the reflection G-buffer, the bottom half (v ∈ [0, 0.5)) the refraction
G-buffer. One lighting pass per technique then lights both views, and the composite samples the
two halves (``glsl/composite.glsl``).

Per-pixel layout (as ``glsl/gbuffer.glsl``): albedo.rgb; normal.xyz + specular k_s in w;
position.xyz + coverage in w (1 = hit, 0 = miss: the deferred pass shows the sky along the ray);
material = (shininess, reflectivity, transparency, ior); plus, for ray-traced views only, eye.xyz
(the ray origin: the viewer of that pixel) and ray_dir.xyz (0 = pixel not traced).
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from serenity.gbuffer_layout import GBUFFER_TARGETS, RT_GBUFFER_KEYS


@dataclass
class RTView:
    """Stacked reflection (top) + refraction (bottom) G-buffer textures, (W, 2H) each."""

    albedo: object
    normal: object
    position: object
    material: object
    eye: object
    ray_dir: object
    width: int
    height: int  # of ONE half (the view's height); the textures are 2 * height tall
    rects: list = None
    """(x, y, w, h), GL pixels of the stacked target, of each half's traced pixels' bounding box:
    the only texels written this frame and the only ones the lighting passes draw."""


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
        """Scatter the tracer's per-ray results back to pixels and upload.

        ``rcb``: the frame's :class:`~serenity.raster.raycast.RayCastingBuffer`. ``reflection`` /
        ``refraction``: the ray tracer's outputs for ``rcb.reflection_rays()`` /
        ``rcb.refraction_rays()``, in the order of ``rcb.pixels``, each with (N, 4) arrays under the
        names of ``RT_GBUFFER_KEYS`` (``eye``/``ray_dir``: the last segment of each ray). Only the
        bounding rectangle of each half's traced pixels is written (``RTView.rects``); texels
        outside them are stale and nothing reads them (the lighting passes draw the rectangles
        only, the composite reads traced pixels only)."""
        w, h = self.size
        rects = []
        for half, res, sel in ((0, reflection, rcb.reflection_rays()), (1, refraction, rcb.refraction_rays())):
            if res is None or not sel.any():
                continue
            pix = rcb.pixels[sel]
            rows, cols = np.divmod(pix, w)
            rows = rows + half * h
            r0, r1, c0, c1 = int(rows.min()), int(rows.max()) + 1, int(cols.min()), int(cols.max()) + 1
            for n in RT_GBUFFER_KEYS:
                self._staging[n][r0:r1, c0:c1] = 0.0
            for n in GBUFFER_TARGETS:
                self._staging[n][rows, cols] = res[n]
            # the viewer and direction of the ray's last segment (after any transmissions)
            self._staging["eye"][rows, cols, :3] = res["eye"][:, :3]
            self._staging["ray_dir"][rows, cols, :3] = res["ray_dir"][:, :3]
            # GL rows run bottom-up: image row r is texture row 2h - 1 - r
            rect = (c0, 2 * h - r1, c1 - c0, r1 - r0)
            for n in RT_GBUFFER_KEYS:
                block = np.ascontiguousarray(self._staging[n][r0:r1, c0:c1][::-1])
                getattr(self.view, n).write(block.tobytes(), viewport=rect)
            rects.append(rect)
        self.view.rects = rects
        return self.view

"""Fresnel composite of the reflection/refraction effect buffers over the main view, in place, one
point per traced pixel (``glsl/composite.glsl``)."""

from __future__ import annotations

import moderngl
import numpy as np

from serenity.raster.context import BlendedTargets, load_program


class CompositePass:
    def __init__(self, ctx):
        self.ctx = ctx
        self.program = load_program(ctx, "composite.glsl")
        self._targets = BlendedTargets(ctx, (moderngl.ONE, moderngl.SRC_ALPHA))  # premultiplied over
        self._vbo = None
        self._vao = None

    def render(self, surface, effects, points: np.ndarray, gbuffer, camera_pos):
        """Blend the lit rays ``effects`` (packed; :mod:`serenity.raster.rt_gbuffer`) into the lit
        main view ``surface`` (RGBA32F, changed in place and returned) at the pixels of ``points``
        (``RTView.points``)."""
        ctx, p = self.ctx, self.program
        if not len(points):
            return surface
        data = np.ascontiguousarray(points, np.float32)
        if self._vbo is None or self._vbo.size < data.nbytes:
            if self._vbo is not None:
                self._vao.release()
                self._vbo.release()
            self._vbo = ctx.buffer(reserve=max(data.nbytes, 4096))
            self._vao = ctx.vertex_array(p, [(self._vbo, "3f", "in_point")])
        self._vbo.write(data)
        with ctx.debug_scope("composite"), self._targets.adding_to(surface):
            for loc, (name, tex) in enumerate((("u_effects", effects), ("g_normal", gbuffer.normal),
                                               ("g_position", gbuffer.position), ("g_material", gbuffer.material))):
                tex.use(location=loc)
                p[name].value = loc
            p["u_camera_pos"].value = tuple(float(x) for x in camera_pos)
            p["u_size"].value = (surface.width, surface.height)
            self._vao.render(moderngl.POINTS, vertices=len(data))
        return surface

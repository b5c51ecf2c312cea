"""Fresnel composite of the reflection/refraction effect buffers over the main view
(``glsl/composite.glsl``)."""

from __future__ import annotations

from serenity.raster.context import FullscreenPass


class CompositePass(FullscreenPass):
    SHADER = "composite.glsl"
    TARGETS = {"hdr": (4, "f4")}

    def render(self, surface, effects, index, gbuffer, camera_pos):
        """``effects``: the lit traced rays, packed, and ``index`` the per-pixel ray index
        (``RTView.index``; see :mod:`serenity.raster.rt_gbuffer`; −2 in its refraction channel marks
        total internal reflection)."""
        p = self.program
        with self.ctx.debug_scope("composite"):
            self.fbo.use()
            for loc, (name, tex) in enumerate((("u_surface", surface), ("u_effects", effects), ("u_index", index),
                                               ("g_normal", gbuffer.normal),
                                               ("g_position", gbuffer.position), ("g_material", gbuffer.material))):
                tex.use(location=loc)
                p[name].value = loc
            p["u_camera_pos"].value = tuple(float(x) for x in camera_pos)
            self.vao.render(vertices=3)
        return self.hdr

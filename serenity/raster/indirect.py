"""Indirect lighting passes (``glsl/indirect.glsl``): the sky volume's irradiance (paper §7) and
the light propagation volumes' diffuse + glossy light (paper §8), each its own fullscreen program
added onto the lit image with additive blending, so that each technique is timed on its own
(paper Table 1) and can be switched off without touching the others.

The volumes' textures and uniforms are bound by their owners (``SkyTexturesGL.bind``,
``LPVTexturesGL.bind``) through the ``bind`` callable given to :meth:`IndirectPass.render`.
"""

from __future__ import annotations

from serenity.raster.context import draw_fullscreen, fullscreen_vao, load_program

TECHNIQUES = {"sky": 1, "lpv": 2}
#: texture units 0..5 are the G-buffer, eye and AO; the volume's own textures start here
FIRST_VOLUME_UNIT = 6


class IndirectPass:
    def __init__(self, ctx, technique: str):
        if technique not in TECHNIQUES:
            raise ValueError(f"technique must be one of {sorted(TECHNIQUES)}")
        self.ctx = ctx
        self.technique = technique
        self.program = load_program(ctx, "indirect.glsl", defines={"TECHNIQUE": TECHNIQUES[technique]})
        self.vao = fullscreen_vao(ctx, self.program)
        self._fbos: dict[int, object] = {}

    def _fbo(self, target):
        key = target.glo
        if key not in self._fbos:
            self._fbos[key] = self.ctx.framebuffer(color_attachments=[target])
        return self._fbos[key]

    def render(self, target, gbuffer, bind, camera_pos, ao=None, rt_view=None) -> None:
        """Add this technique's light onto ``target`` (the lit HDR texture of the same size)."""
        import moderngl

        ctx, p = self.ctx, self.program
        with ctx.debug_scope(f"indirect:{self.technique}"):
            self._fbo(target).use()
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = moderngl.ONE, moderngl.ONE
            ctx.blend_equation = moderngl.FUNC_ADD
            for loc, (name, tex) in enumerate((("g_albedo", gbuffer.albedo), ("g_normal", gbuffer.normal),
                                               ("g_position", gbuffer.position), ("g_material", gbuffer.material))):
                tex.use(location=loc)
                if name in p:
                    p[name].value = loc
            if rt_view is not None and "g_eye" in p:
                rt_view.eye.use(location=4)
                p["g_eye"].value = 4
            if ao is not None and rt_view is None and "u_ao" in p:
                ao.use(location=5)
                p["u_ao"].value = 5
            for name, value in (("u_use_ao", ao is not None and rt_view is None), ("u_rt_view", rt_view is not None),
                                ("u_camera_pos", tuple(float(x) for x in camera_pos))):
                if name in p:
                    p[name].value = value
            bind(p, FIRST_VOLUME_UNIT)
            draw_fullscreen(ctx, self.vao, None if rt_view is None else rt_view.rects)
            ctx.disable(moderngl.BLEND)

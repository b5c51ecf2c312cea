"""Indirect lighting passes (``glsl/indirect.glsl``): the sky volume's irradiance (paper §7) and
the light propagation volumes' diffuse + glossy light (paper §8), each its own fullscreen program
added onto the lit image with additive blending, so that each technique is timed on its own
(paper Table 1) and can be switched off without touching the others.

The volumes' textures and uniforms are bound by their owners (``SkyTexturesGL.bind``,
``LPVTexturesGL.bind``) through the ``bind`` callable given to :meth:`IndirectPass.render`.

Reduced resolution (``IndirectConfig.scale`` > 1, main view): the passes built with
``lowres=True`` write the light *per unit albedo* at 1/scale of the view per axis into
:class:`LowResIndirect`'s two targets (diffuse E/π·AO and glossy·AO), drawn before the deferred
pass, which adds ``albedo·E + glossy`` as it lights each full-resolution pixel, with a joint
bilateral filter (``glsl/upsample.glsl``; ``DeferredPass.render(upsample=...)``). Indirect light
is smooth, so at scale 2 a quarter of the pixels carry it; texture detail comes back from the
full-resolution albedo.
"""

from __future__ import annotations

import moderngl

from serenity.raster.context import (
    BlendedTargets,
    draw_fullscreen,
    fullscreen_vao,
    load_program,
    low_res_layout,
    uniform,
)

TECHNIQUES = {"sky": 1, "lpv": 2}
#: texture units 0..5 are the G-buffer, eye and AO; the volume's own textures start here
FIRST_VOLUME_UNIT = 6
#: Low-res draws: (LPV terms, NDC depth the fullscreen triangle is drawn at) against the guide's
#: class depth with test ">" (glsl/lowres.glsl): the sky's light and the LPV's diffuse term at the
#: far plane (every surface class), the LPV's glossy term at 0.375 in window depth (the glossy class,
#: 0.25, alone). llvmpipe shades no pixel the test rejects: background texels cost nothing, and the
#: glossy march runs where k_s calls for it (2 % of the courtyard's texels) instead of everywhere.
LOWRES_DRAWS = {"sky": ((3, 1.0),), "lpv": ((1, 1.0), (2, -0.25))}


class IndirectPass:
    def __init__(self, ctx, technique: str, lowres: bool = False, defines: dict | None = None):
        """``defines``: more compile-time switches of indirect.glsl and what it includes (e.g.
        lpv.glsl's ``LPV_DAMPING``)."""
        if technique not in TECHNIQUES:
            raise ValueError(f"technique must be one of {sorted(TECHNIQUES)}")
        self.ctx = ctx
        self.technique = technique
        self.lowres = lowres
        self._draws = []  # (program, vao, LPV terms it adds)
        for terms, z in (LOWRES_DRAWS[technique] if lowres else ((3, None),)):
            d = {"TECHNIQUE": TECHNIQUES[technique], "LOWRES": int(lowres), "LPV_TERMS": terms, **(defines or {})}
            if z is not None:
                d["FULLSCREEN_Z"] = z
            program = load_program(ctx, "indirect.glsl", defines=d)
            self._draws.append((program, fullscreen_vao(ctx, program), terms))
        self._targets = BlendedTargets(ctx)

    def render(self, target, gbuffer, bind, camera_pos, ao=None, rt_view=None, diffuse: bool = True,
               glossy: bool = True) -> None:
        """Add this technique's light onto ``target``: the lit HDR texture of the same size, or for a
        ``lowres`` pass the :class:`LowResIndirect` whose targets (and the guide's class depth) it
        draws into. ``diffuse`` / ``glossy``: which of the LPV's two terms to add (the sky pass
        ignores them: its glossy term is compiled in or out by ``SKY_GLOSSY``, ``SkyConfig.glossy``)."""
        ctx = self.ctx
        wanted = (1 if diffuse else 0) | (2 if glossy else 0) if self.technique == "lpv" else 3
        draws = [d for d in self._draws if d[2] & wanted]
        adding = (self._targets.adding_to_framebuffer(target.fbo) if self.lowres
                  else self._targets.adding_to(target))
        with ctx.debug_scope(f"indirect:{self.technique}"), adding:
            for loc, tex in enumerate((gbuffer.albedo, gbuffer.normal, gbuffer.position, gbuffer.material)):
                tex.use(location=loc)
            if rt_view is not None:
                rt_view.eye.use(location=4)
            if ao is not None and rt_view is None:
                ao.use(location=5)
            for p, _, _ in draws:
                self._set_uniforms(p, target, bind, camera_pos, ao, rt_view, diffuse, glossy)
            if not self.lowres:  # one program, all pixels (the ray-traced views: their rectangles)
                for _, vao, _ in draws:
                    draw_fullscreen(ctx, vao, None if rt_view is None else rt_view.rects)
                return
            target.fbo.depth_mask = False
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.depth_func = ">"
            try:
                for _, vao, _ in draws:
                    vao.render(vertices=3)
            finally:
                ctx.disable(moderngl.DEPTH_TEST)
                ctx.depth_func = "<"
                target.fbo.depth_mask = True

    def _set_uniforms(self, p, target, bind, camera_pos, ao, rt_view, diffuse: bool, glossy: bool) -> None:
        if self.lowres:
            p["u_scale"].value = target.scale
            target.layout.set_uniforms(p)
            if (u := uniform(p, "u_ao_div")) is not None:
                u.value = target.ao_div
        for loc, name in enumerate(("g_albedo", "g_normal", "g_position", "g_material")):
            if (u := uniform(p, name)) is not None:
                u.value = loc
        if rt_view is not None and (u := uniform(p, "g_eye")) is not None:
            u.value = 4
        if ao is not None and rt_view is None and (u := uniform(p, "u_ao")) is not None:
            u.value = 5
        for name, value in (("u_use_ao", ao is not None and rt_view is None), ("u_rt_view", rt_view is not None),
                            ("u_camera_pos", tuple(float(x) for x in camera_pos)),
                            ("u_diffuse", bool(diffuse)), ("u_glossy", bool(glossy))):
            if (u := uniform(p, name)) is not None:
                u.value = value
        bind(p, FIRST_VOLUME_UNIT)


class LowResIndirect:
    """The main view's indirect light at 1/``scale`` resolution (see the module docstring): two
    RGBA16F targets that the ``lowres`` :class:`IndirectPass` programs add to; the deferred pass
    upsamples them (joint bilateral, ``glsl/upsample.glsl``) as it lights the full-resolution view."""

    def __init__(self, ctx, scale: int, balance: bool = True):
        self.ctx = ctx
        self.scale = max(1, int(scale))
        self.balance = balance  # the padded layout of the targets (raster/context.LowResLayout)
        self.size = None
        self.layout = None
        self.depth = None  # the guide's class depth attached to fbo (LowResGuide)
        self.ao_div = 1  # the AO is at this resolution too

    def resize(self, width: int, height: int) -> None:
        if self.size == (width, height):
            return
        if self.size is not None:
            for o in {self.fbo, self._colour_fbo, self.irr, self.gloss}:
                o.release()
        self.layout = low_res_layout(width, height, self.scale, self.balance)
        low = self.layout.texture_size
        self.irr = self.ctx.texture(low, 4, dtype="f2")
        self.gloss = self.ctx.texture(low, 4, dtype="f2")
        self._colour_fbo = self.ctx.framebuffer(color_attachments=[self.irr, self.gloss])  # clears keep the depth
        self._colour_fbo.viewport = self.layout.viewport
        self.fbo = self._colour_fbo
        self.depth = None
        self.size = (width, height)

    def use_depth(self, depth) -> None:
        """Attach the low-res guide's class depth (same size) for the passes' depth tests."""
        if depth is not self.depth:
            if self.fbo is not self._colour_fbo:
                self.fbo.release()
            self.fbo = self.ctx.framebuffer(color_attachments=[self.irr, self.gloss], depth_attachment=depth)
            self.fbo.viewport = self.layout.viewport
            self.depth = depth

    def clear(self) -> None:
        """Zero the two targets (not the attached depth)."""
        self._colour_fbo.clear(0.0, 0.0, 0.0, 0.0)

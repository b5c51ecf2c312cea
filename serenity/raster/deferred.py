"""Deferred lighting (paper §3, §6): Phong direct light with the sun's shadow map, indirect terms,
and the sky behind uncovered pixels, into linear HDR float targets (``glsl/deferred.glsl``).
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from serenity.config import ShadowConfig
from serenity.raster.context import (
    FullscreenPass,
    draw_fullscreen,
    finish,
    fullscreen_vao,
    load_program,
    low_res_size,
    uniform,
)
from serenity.raster.shadow import disc_defines

UPSAMPLE_UNIT = 16
"""First of the 3 texture units of the upsampled indirect light (units 0..15: G-buffer, shadows, sky)."""
VISIBILITY_UNIT = UPSAMPLE_UNIT + 3
"""Texture unit of the sparsely sampled sun visibility (``DeferredPass.render_visibility``)."""
HISTORY_UNIT = VISIBILITY_UNIT + 1
"""Texture unit of the last frame's indirect light (``raster/temporal.py``)."""
REFINE_UNIT = HISTORY_UNIT + 1
"""First of the 2 texture units of the indirect light refined at full resolution (``raster/lowres.py``)."""
VISIBILITY_MODES = {"checkerboard": 1, "half": 2}
"""ShadowConfig.visibility → glsl/visibility_upsample.glsl's VIS_CHECKERBOARD / VIS_HALF ("pixel": none)."""
SHADOW_FILTERS = {"hard": 0, "pcf": 1, "pcss": 2}
"""ShadowConfig.filter → glsl/shadow_sampling.glsl's SHADOW_FILTER."""


@dataclass
class LightingInputs:
    """What the deferred pass needs besides the G-buffer (all linear, radiometric units)."""

    sun_direction: np.ndarray      # (3,) unit, towards the sun
    sun_irradiance: np.ndarray     # (3,) W m^-2
    sun_radiance: np.ndarray       # (3,) W m^-2 sr^-1 of the disc
    sun_cos_radius: float
    sky_radiance: np.ndarray       # (3,) constant sky placeholder
    ambient_irradiance: np.ndarray  # (3,) constant ambient (baseline); zeros = off
    camera_position: np.ndarray
    view_proj: np.ndarray          # (4,4) world → clip of the main view
    inv_view_proj: np.ndarray
    camera_forward: np.ndarray
    sun_tan_half: float            # tan of the sun's angular radius
    shadow: object                 # ShadowConfig


@dataclass
class LitImage:
    hdr: object     # rgba32f radiance
    direct: object  # rgba32f direct-sun component


class DeferredPass(FullscreenPass):
    """The deferred lighting pass. Its program is compiled per variant (``glsl/deferred.glsl``: main
    view or ray-traced view, traced or mapped sun, contact-shadow steps, upsampling, shadow filter and
    taps), each on first use, because llvmpipe pays for every path a shader has, taken or not."""

    SHADER = "deferred.glsl"
    TARGETS = {"hdr": (4, "f4"), "direct": (4, "f4")}

    def __init__(self, ctx):
        self.ctx = ctx
        self.size = None
        self._variants: dict[tuple, tuple] = {}
        self._split: dict[tuple, object] = {}  # (G-buffer depth, history target) -> our targets + those
        self._vis = None    # (mode, target texture, framebuffer, depth texture) of render_visibility

    def resize(self, width: int, height: int) -> None:
        if self.size != (width, height):
            for fbo in self._split.values():
                fbo.release()
            self._split.clear()
            self._release_visibility()
        super().resize(width, height)

    def _release_visibility(self) -> None:
        if self._vis is not None:
            _, tex, fbo, depth = self._vis
            for obj in (fbo, tex, depth):  # the framebuffer first, then its textures
                obj.release()
            self._vis = None

    def _variant(self, rt_view: bool, traced_sun: bool, contact_steps: int, upsample: int, shadow_cfg=None,
                 split: int = 0, vis_pass: int = 0, vis_upsample: int = 0, vis_step: int = 0,
                 refine: bool = False):
        """(program, vao) of one variant; ``upsample`` 1 = the low-res indirect light upsampled, 2 = and
        blended with the last frame's; ``split`` 1 = surfaces only, 2 = sky only; ``vis_pass``: the
        sparsely sampled sun visibility (a ``VISIBILITY_MODES`` value) instead of the lighting;
        ``vis_upsample``: the lighting with that visibility; ``vis_step``: the visibility pass's step
        (1: guide and class, 2: the visibility); ``refine``: with ``upsample``, the refined pixels' light
        read from the :class:`~serenity.raster.lowres.IndirectRefinement` (glsl/deferred.glsl, upsample.glsl)."""
        # the shadow filter and its tap counts are compiled in too (glsl/shadow_sampling.glsl)
        filt = None if shadow_cfg is None else (SHADOW_FILTERS[shadow_cfg.filter], int(shadow_cfg.blocker_samples),
                                                int(shadow_cfg.filter_samples))
        key = (rt_view, traced_sun, contact_steps, upsample, filt, split, vis_pass, vis_upsample, vis_step, refine)
        if key not in self._variants:
            defines = {"RT_VIEW": int(rt_view), "TRACED_SUN": int(traced_sun), "CONTACT_STEPS": int(contact_steps),
                       "UPSAMPLE": int(upsample), "SPLIT": int(split), "VIS_PASS": int(vis_pass),
                       "VIS_UPSAMPLE": int(vis_upsample), "VIS_STEP": int(vis_step),
                       "UPSAMPLE_REFINE": int(bool(refine and upsample))}
            if filt is not None:
                defines["SHADOW_FILTER"] = filt[0]
            taps = filt[1:] if filt is not None else (ShadowConfig.blocker_samples, ShadowConfig.filter_samples)
            defines.update(disc_defines(*taps))
            program = load_program(self.ctx, self.SHADER, defines=defines)
            self._variants[key] = (program, fullscreen_vao(self.ctx, program))
        return self._variants[key]

    def _split_fbo(self, depth, history=None):
        """Our targets with the G-buffer's depth attached (read, not written), for the split draw; with
        ``history`` (a texture), that as a third target."""
        key = (depth, history)
        if key not in self._split:
            if len(self._split) > 4:  # (the history alternates between two textures)
                for fbo in self._split.values():
                    fbo.release()
                self._split.clear()
            targets = [self.hdr, self.direct] + ([history] if history is not None else [])
            self._split[key] = self.ctx.framebuffer(color_attachments=targets, depth_attachment=depth)
        return self._split[key]

    def render_visibility(self, gbuffer, shadow, light: LightingInputs, mode: str):
        """The main view's sun visibility — the shadow maps' filter and the contact march, as
        :meth:`render` would compute them — at the pixels that ``mode`` samples ("checkerboard":
        every other pixel of each row and column, "half": one per 2×2 block), each with its guide
        (normal, view depth): the RGBA32F texture :meth:`render` takes as ``visibility``
        (``glsl/visibility_upsample.glsl``). The filter's taps cost 1/2 or 1/4 of the per-pixel pass;
        the upsampling 5 or 4 fetches a pixel."""
        code = VISIBILITY_MODES[mode]
        w, h = self.size
        size = ((w + 1) // 2, h) if mode == "checkerboard" else low_res_size(w, h, 2)
        if self._vis is None or self._vis[0] != code:
            self._release_visibility()
            tex = self.ctx.texture(size, 4, dtype="f4")
            depth = self.ctx.depth_texture(size)
            self._vis = (code, tex, self.ctx.framebuffer(color_attachments=[tex], depth_attachment=depth), depth)
        _, tex, fbo, _ = self._vis
        contact = int(light.shadow.contact_steps)
        steps = (self._variant(False, False, 0, False, None, vis_pass=code, vis_step=1),
                 self._variant(False, False, contact, False, light.shadow, vis_pass=code, vis_step=2))
        ctx = self.ctx
        with ctx.debug_scope("sun visibility"):
            gbuffer.normal.use(location=1)
            gbuffer.position.use(location=2)
            shadow.depth.use(location=4)
            ctx.enable(moderngl.DEPTH_TEST)
            try:
                # step 1: every texel's guide, visibility 0 and class; step 2: the visibility (w only)
                # of the texels on surfaces facing the sun, the others rejected by the depth test
                for (p, vao), func, mask in zip(steps, ("1", ">"), ((True,) * 4, (False, False, False, True)),
                                                strict=True):
                    self._set_uniforms(p, shadow, light, None, True, None, None, contact)
                    ctx.depth_func = func
                    fbo.depth_mask = func == "1"
                    fbo.color_mask = mask
                    fbo.use()  # (moderngl applies the masks when the framebuffer is bound)
                    vao.render(vertices=3)
            finally:
                ctx.disable(moderngl.DEPTH_TEST)
                ctx.depth_func = "<"
                fbo.depth_mask = True
                fbo.color_mask = (True,) * 4
        return tex

    def render(self, gbuffer, shadow, light: LightingInputs, ao=None, rt_view=None, sky=None,
               upsample=None, visibility=None, history=None) -> LitImage:
        """Light ``gbuffer``. ``rt_view`` (an object with ``eye`` and ``ray_dir`` textures) marks a
        ray-traced G-buffer: each pixel's viewer is its ray origin, misses show the sky along the
        ray, untraced pixels are black, and SSAO is not applied. ``shadow`` None (rt views only):
        the sun's visibility is the tracer's shadow ray, ``eye.w``. ``upsample`` (main view only):
        (the frame's :class:`~serenity.raster.indirect.LowResIndirect`, already drawn, and the
        low-res guide texture, and an :class:`~serenity.raster.lowres.IndirectRefinement` already drawn
        or None): its light is upsampled and added in this pass (``glsl/upsample.glsl``).
        ``visibility`` (main view only): the texture of :meth:`render_visibility`, just drawn: the
        sun's visibility is upsampled from it instead of computed per pixel. ``history`` (main view, with
        ``upsample``): (the :class:`~serenity.raster.temporal.IndirectHistory`, the camera, its weight a):
        the upsampled light is blended with the last frame's and written to the history's target.
        The main view is drawn in two halves over the G-buffer's depth: the sky's pixels, then the
        surfaces' (``SPLIT`` in the shader: llvmpipe shades neither half's pixels with the other's code)."""
        if shadow is None and rt_view is None:
            raise ValueError("the main view needs shadow maps")
        main = rt_view is None
        contact = int(light.shadow.contact_steps) if main else 0  # march steps, 0 = no contact shadow
        shadow_cfg = None if shadow is None else light.shadow
        if main:
            vis_up = 0 if visibility is None else self._vis[0]
            up = 0 if upsample is None else (2 if history is not None else 1)
            refine = upsample is not None and upsample[2] is not None
            draws = [self._variant(False, False, 0, 0, None, split=2),
                     self._variant(False, False, 0 if vis_up else contact, up,
                                   None if vis_up else shadow_cfg, split=1, vis_upsample=vis_up, refine=refine)]
        else:
            draws = [self._variant(True, shadow is None, 0, 0, shadow_cfg)]
        ctx = self.ctx
        with ctx.debug_scope("deferred"):
            for i, t in enumerate((gbuffer.albedo, gbuffer.normal, gbuffer.position, gbuffer.material)):
                t.use(location=i)
            if shadow is not None:
                shadow.depth.use(location=4)
            if not main:
                rt_view.eye.use(location=6)
                rt_view.ray_dir.use(location=7)
            elif ao is not None:
                ao.use(location=5)
            if main and upsample is not None:
                lo, guide, refined = upsample
                for loc, tex in enumerate((lo.irr, lo.gloss, guide), start=UPSAMPLE_UNIT):
                    tex.use(location=loc)
                if refined is not None:
                    refined.irr.use(location=REFINE_UNIT)
                    refined.gloss.use(location=REFINE_UNIT + 1)
            if main and visibility is not None:
                visibility.use(location=VISIBILITY_UNIT)
            for p, _ in draws:
                self._set_uniforms(p, shadow, light, ao, main, upsample, sky, contact)
                if main and visibility is not None:
                    self._set(p, "u_vis", VISIBILITY_UNIT)
            if not main:
                self.fbo.use()
                draw_fullscreen(ctx, draws[0][1], rt_view.rects)
                return LitImage(self.hdr, self.direct)
            if history is not None:
                hist, camera, alpha = history
                hist.begin()
                hist.set_uniforms(draws[1][0], HISTORY_UNIT, camera, alpha, light.view_proj)
            # the sky's half draws into ours only; the surfaces' into the history's target too
            fbos = (self._split_fbo(gbuffer.depth),
                    self._split_fbo(gbuffer.depth, None if history is None else history[0].target))
            ctx.enable(moderngl.DEPTH_TEST)
            try:
                for (_, vao), test, fbo in zip(draws, ("<=", ">"), fbos, strict=True):  # sky: depth 1; surfaces: < 1
                    fbo.use()
                    fbo.depth_mask = False
                    ctx.depth_func = test
                    finish(ctx)  # the inputs drawn before: wait with the GIL released (context.finish)
                    vao.render(vertices=3)
            finally:
                ctx.disable(moderngl.DEPTH_TEST)
                ctx.depth_func = "<"
                for fbo in fbos:
                    fbo.depth_mask = True
            if history is not None:
                history[0].end(light.view_proj, history[1])
        return LitImage(self.hdr, self.direct)

    def _set_uniforms(self, p, shadow, light: LightingInputs, ao, main: bool, upsample, sky, contact: int) -> None:
        """Every uniform program ``p`` has (texture units as bound by ``render``)."""
        for name, loc in (("g_albedo", 0), ("g_normal", 1), ("g_position", 2), ("g_material", 3)):
            self._set(p, name, loc)
        if shadow is not None:
            self._set(p, "u_shadow_map", 4)
            self._set_shadow_uniforms(p, shadow, light)
        self._set(p, "u_use_ao", ao is not None and main)
        if not main:
            self._set(p, "g_eye", 6)
            self._set(p, "g_ray_dir", 7)
        elif ao is not None:
            self._set(p, "u_ao", 5)
        if main and upsample is not None:
            for loc, name in enumerate(("u_irr", "u_gloss", "u_guide"), start=UPSAMPLE_UNIT):
                self._set(p, name, loc)
            self._set(p, "u_scale", upsample[0].scale)
            self._set(p, "u_refine_irr", REFINE_UNIT)
            self._set(p, "u_refine_gloss", REFINE_UNIT + 1)
            upsample[0].layout.set_uniforms(p)
        self._set(p, "u_use_sky_map", sky is not None)
        if sky is not None:
            sky.bind(p, 8)  # units 8..15: the sky map (and the volume, unused here)
        if (u := uniform(p, "u_inv_view_proj")) is not None:
            u.write(light.inv_view_proj.T.astype(np.float32).tobytes())
        if contact and (u := uniform(p, "u_view_proj")) is not None:
            u.write(light.view_proj.T.astype(np.float32).tobytes())
        self._set(p, "u_contact_pixels", light.shadow.contact_pixels)
        self._set(p, "u_contact_texels", light.shadow.contact_texels)
        self._set(p, "u_sun_dir", light.sun_direction)
        self._set(p, "u_sun_irradiance", light.sun_irradiance)
        self._set(p, "u_sun_radiance", light.sun_radiance)
        self._set(p, "u_sun_cos_radius", light.sun_cos_radius)
        self._set(p, "u_camera_pos", light.camera_position)
        self._set(p, "u_camera_forward", light.camera_forward)
        self._set(p, "u_sky_radiance", light.sky_radiance)
        self._set(p, "u_ambient_irradiance", light.ambient_irradiance)

    def _set_shadow_uniforms(self, p, shadow, light: LightingInputs) -> None:
        if uniform(p, "u_tile_vp") is None:  # a variant that samples no shadow map (the sky's half)
            return
        cfg = light.shadow
        cs = shadow.cascades
        n = len(cs)
        for name, value in shadow.tile_uniforms().items():  # the tiles, their atlas slots and cross-fades
            if (u := uniform(p, name)) is not None:
                u.write(value)

        def vec4(vals):
            return tuple(float(v) for v in list(vals) + [vals[-1]] * (4 - len(vals)))

        p["u_cascade_count"].value = n
        p["u_atlas_tiles"].value = float(shadow.depth.width // shadow.tile_size)
        p["u_cascade_far"].value = vec4([c.far for c in cs])
        self._set(p, "u_cascade_texel", vec4([c.texel_world for c in cs]))  # dropped where nothing reads it
        for name, v in (("u_shadow_bias", cfg.bias), ("u_normal_offset", cfg.normal_offset),
                        ("u_pcf_radius", cfg.pcf_radius), ("u_sun_tan_half", light.sun_tan_half),
                        ("u_pcss_max_blocker", cfg.pcss_max_blocker), ("u_cascade_blend", cfg.cascade_blend)):
            self._set(p, name, v)

    @staticmethod
    def _set(p, name, value):
        """Set uniform ``name`` if this variant has it (a variant leaves out what it never reads):
        bools and ints as they are (switches, texture units), other scalars as float, arrays as a
        tuple of floats."""
        u = uniform(p, name)
        if u is None:
            return
        if isinstance(value, (bool, int)):
            u.value = value
        elif np.ndim(value) == 0:
            u.value = float(value)
        else:
            u.value = tuple(float(x) for x in np.asarray(value).reshape(-1))

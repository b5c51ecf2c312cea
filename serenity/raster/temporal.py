"""Temporal hysteresis of the main view's upsampled indirect light (``RenderConfig.indirect_history``;
``glsl/indirect_history.glsl``).

With ``indirect_scale`` > 1 the sky volume's and the LPV's light (and SSAO) are computed once per
low-res texel, at the G-buffer pixel the texel stands for, and upsampled. When the camera moves by a
fraction of a pixel those points slide over the surfaces and the upsampled light slides with them:
the LPV's light, which varies within a cell (its leak guard and damping), stepped by a few per cent a
frame in blocks of pixels (``lpv-fast``'s 99th-percentile pixel step 3.6 % under a camera moving
5 cm a frame, ``docs/stability.md``). Here, in one full-resolution pass before the deferred pass,
each pixel's upsampled light is blended with what the last frame showed at the same surface point
(reprojected; where that point was hidden or on another surface, this frame's light alone), and
the deferred pass reads the result per pixel (one tap instead of its upsampling). A moving light lags by
(1 − a)/a frames. Its cost: a full-resolution pass of its own, holding the upsampling the deferred
pass did, plus per pixel a reprojection and 4 taps of the last frame's light.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from serenity.raster.context import LowResLayout, fullscreen_vao, load_program


@dataclass
class BlendedIndirect:
    """What the deferred pass upsamples (as it would a ``LowResIndirect``): here the blended light
    albedo · E + G per pixel in ``irr`` (``scale`` 0: ``glsl/upsample.glsl`` reads it as it is)."""

    irr: object
    gloss: object
    scale: int
    layout: LowResLayout


class IndirectHistory:
    """Two full-resolution targets (this frame's output, the last frame's) and the last frame's camera."""

    def __init__(self, ctx, scale: int):
        self.ctx = ctx
        self.scale = max(1, int(scale))
        self.program = load_program(ctx, "indirect_history.glsl")
        self.vao = fullscreen_vao(ctx, self.program)
        self.size = None
        self._sets: list[tuple] = []
        self._prev: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # view_proj, position, forward
        self._turn = 0

    def resize(self, width: int, height: int) -> None:
        if self.size == (width, height):
            return
        for targets in self._sets:
            for o in targets:
                o.release()
        self.layout = LowResLayout((width, height))
        self._sets = []
        for _ in range(2):
            light = self.ctx.texture((width, height), 4, dtype="f4")  # rgb = the light, a = view depth
            self._sets.append((light, self.ctx.framebuffer(color_attachments=[light])))
        self.size = (width, height)
        self._prev = None

    def reset(self) -> None:
        """Forget the last frame (the next one shows its own light only)."""
        self._prev = None

    def render(self, lowres, guide, gbuffer, view_proj: np.ndarray, camera, alpha: float) -> BlendedIndirect:
        """Upsample ``lowres`` (the frame's :class:`~serenity.raster.indirect.LowResIndirect`, drawn, with
        its ``guide``) and blend it with the last frame's output at weight ``alpha`` for this frame's
        light; returns the blended light for the deferred pass's ``upsample`` (with the same guide)."""
        ctx, p = self.ctx, self.program
        light, fbo = self._sets[self._turn]
        prev = self._sets[1 - self._turn][0]
        with ctx.debug_scope("indirect history"):
            fbo.use()
            textures = (lowres.irr, lowres.gloss, guide, gbuffer.position, gbuffer.normal, gbuffer.albedo, prev)
            names = ("u_irr", "u_gloss", "u_guide", "g_position", "g_normal", "g_albedo", "u_prev_irr")
            for loc, (tex, name) in enumerate(zip(textures, names, strict=True)):
                tex.use(location=loc)
                p[name].value = loc
            p["u_scale"].value = self.scale
            lowres.layout.set_uniforms(p)
            p["u_camera_pos"].value = tuple(float(v) for v in camera.position)
            p["u_camera_forward"].value = tuple(float(v) for v in camera.forward)
            p["u_alpha"].value = float(alpha)
            p["u_pixel_angle"].value = math.radians(camera.fov_y_deg) / self.size[1]
            p["u_has_prev"].value = self._prev is not None
            if self._prev is not None:
                vp, pos, fwd = self._prev
                p["u_prev_view_proj"].write(vp.T.astype(np.float32).tobytes())
                p["u_prev_camera_pos"].value = tuple(float(v) for v in pos)
                p["u_prev_camera_forward"].value = tuple(float(v) for v in fwd)
            self.vao.render(vertices=3)
        self._prev = (np.asarray(view_proj, np.float64).copy(), np.asarray(camera.position, np.float64).copy(),
                      np.asarray(camera.forward, np.float64).copy())
        self._turn = 1 - self._turn
        return BlendedIndirect(light, light, 0, self.layout)

"""Temporal hysteresis of the main view's upsampled indirect light (``IndirectConfig.history``;
``glsl/indirect_history.glsl``).

With ``IndirectConfig.scale`` > 1 the sky volume's and the LPV's light (and SSAO) are computed once per
low-res texel, at the G-buffer pixel the texel stands for, and upsampled. When the camera moves by a
fraction of a pixel those points slide over the surfaces and the upsampled light slides with them:
the LPV's light, which varies within a cell (its leak guard and damping), stepped by a few per cent a
frame in blocks of pixels (``lpv-fast``'s 99th-percentile pixel step 3.6 % under a camera moving
5 cm a frame, ``docs/stability.md``). The deferred pass, as it upsamples, blends each pixel's light
with what the last frame showed at the same surface point (reprojected; where that point was hidden
or on another surface, this frame's light alone) and writes the result to a third target, which the
next frame reads. A moving light lags by (1 − a)/a frames. Its cost, inside the deferred pass: per
pixel a reprojection, one bilinear fetch of the last frame's light and one more target written.

Why not at the low resolution, before the upsampling (a sixteenth of the pixels at scale 4): the
upsampling's weights follow the texels' representative pixels, which slide on and off thin and curved
surfaces (pillars, capitals) as the camera moves, and those steps come after such a blend; at 160×90
``lpv-fast``'s camera pan kept a 99th-percentile step of 3.5 % with it (3.0 % even at a = 0.05),
against 2.1 % here.
"""

from __future__ import annotations

import math

import moderngl
import numpy as np

from serenity.raster.context import uniform


class HistoryTargets:
    """Two full-resolution RGBA32F targets, this frame's output and the last frame's (rgb = the
    image, a = view depth), and the camera the last one was drawn from: the history that
    ``glsl/reproject.glsl`` reads (the indirect light's below, the anti-aliasing's ``raster/taa.py``)."""

    def __init__(self, ctx, linear: bool = False):
        self.ctx = ctx
        self.linear = linear  # bilinear reads of the textures (else nearest)
        self.size = None
        self._sets: list[tuple] = []
        #: the last frame's (view_proj, camera position, forward, fov_y_deg), None: no last frame
        self.prev: tuple | None = None
        self._turn = 0

    def resize(self, width: int, height: int) -> None:
        """(Re)allocate for a width×height view; a new size forgets the last frame."""
        if self.size == (width, height):
            return
        self.release()
        for _ in range(2):
            tex = self.ctx.texture((width, height), 4, dtype="f4")
            if self.linear:
                tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
                tex.repeat_x = tex.repeat_y = False
            self._sets.append((tex, self.ctx.framebuffer(color_attachments=[tex])))
        self.size = (width, height)
        self.prev = None

    def release(self) -> None:
        for targets in self._sets:
            for o in targets:
                o.release()
        self._sets = []

    @property
    def target(self):
        """This frame's output texture."""
        return self._sets[self._turn][0]

    @property
    def fbo(self):
        """This frame's output framebuffer."""
        return self._sets[self._turn][1]

    @property
    def last(self):
        """The last frame's output texture."""
        return self._sets[1 - self._turn][0]

    def set_reproject_uniforms(self, p, camera) -> None:
        """``glsl/reproject.glsl``'s uniforms in program ``p``: the last frame's camera, and this one's
        pixel angle."""
        values = {"u_has_prev": self.prev is not None, "u_pixel_angle": math.radians(camera.fov_y_deg) / self.size[1]}
        if self.prev is not None:
            vp, pos, fwd, _ = self.prev
            values.update(u_prev_camera_pos=tuple(float(v) for v in pos),
                          u_prev_camera_forward=tuple(float(v) for v in fwd))
            if (u := uniform(p, "u_prev_view_proj")) is not None:
                u.write(vp.T.astype(np.float32).tobytes())
        for name, value in values.items():
            if (u := uniform(p, name)) is not None:
                u.value = value

    def end(self, view_proj: np.ndarray, camera) -> None:
        """This frame is drawn: it becomes the last frame."""
        self.prev = (np.asarray(view_proj, np.float64).copy(), np.asarray(camera.position, np.float64).copy(),
                     np.asarray(camera.forward, np.float64).copy(), float(camera.fov_y_deg))
        self._turn = 1 - self._turn


class IndirectHistory(HistoryTargets):
    """The indirect light's history: this frame's target is the deferred pass's third target; the last
    frame's is read with the texture's bilinear filter (``glsl/indirect_history.glsl``)."""

    def __init__(self, ctx):
        super().__init__(ctx, linear=True)

    def begin(self) -> None:
        """Clear this frame's target to 'no surface' (view depth −1): the sky's pixels keep that."""
        self.fbo.clear(0.0, 0.0, 0.0, -1.0)

    def set_uniforms(self, p, unit: int, camera, alpha: float, view_proj: np.ndarray) -> None:
        """The uniforms of ``glsl/indirect_history.glsl`` in program ``p``, the last frame's output
        bound to texture unit ``unit``; ``view_proj``: this frame's world → clip. Drawn from the last
        frame's view exactly, the last frame is read by its nearest texel, the pixel itself (the
        bilinear filter's weights at a texel's centre may miss 1 and 0 by a rounding, and an unchanged
        view would then drift by that every frame), else bilinearly."""
        still = self.prev is not None and np.array_equal(self.prev[0], np.asarray(view_proj, np.float64))
        self.last.filter = (moderngl.NEAREST, moderngl.NEAREST) if still else (moderngl.LINEAR, moderngl.LINEAR)
        self.last.use(location=unit)
        self.set_reproject_uniforms(p, camera)
        for name, value in (("u_prev_irr", unit), ("u_history_alpha", float(alpha))):
            if (u := uniform(p, name)) is not None:
                u.value = value

"""Temporal hysteresis of the main view's upsampled indirect light (``RenderConfig.indirect_history``;
``glsl/indirect_history.glsl``).

With ``indirect_scale`` > 1 the sky volume's and the LPV's light (and SSAO) are computed once per
low-res texel, at the G-buffer pixel the texel stands for, and upsampled. When the camera moves by a
fraction of a pixel those points slide over the surfaces and the upsampled light slides with them:
the LPV's light, which varies within a cell (its leak guard and damping), stepped by a few per cent a
frame in blocks of pixels (``lpv-fast``'s 99th-percentile pixel step 3.6 % under a camera moving
5 cm a frame, ``docs/stability.md``). The deferred pass, as it upsamples, blends each pixel's light
with what the last frame showed at the same surface point (reprojected; where that point was hidden
or on another surface, this frame's light alone) and writes the result to a third target, which the
next frame reads. A moving light lags by (1 − a)/a frames. Its cost, inside the deferred pass: per
pixel a reprojection, 4 taps of the last frame's light and one more target written.
"""

from __future__ import annotations

import math

import numpy as np

from serenity.raster.context import uniform


class IndirectHistory:
    """Two full-resolution targets (this frame's output, the last frame's) and the last frame's camera."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.size = None
        self._sets: list[tuple] = []
        self._prev: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # view_proj, position, forward
        self._turn = 0

    def resize(self, width: int, height: int) -> None:
        if self.size == (width, height):
            return
        self.release()
        for _ in range(2):
            light = self.ctx.texture((width, height), 4, dtype="f4")  # rgb = the light, a = view depth
            self._sets.append((light, self.ctx.framebuffer(color_attachments=[light])))
        self.size = (width, height)
        self._prev = None

    def release(self) -> None:
        for targets in self._sets:
            for o in targets:
                o.release()
        self._sets = []

    @property
    def target(self):
        """This frame's output texture (the deferred pass's third target), cleared by :meth:`begin`."""
        return self._sets[self._turn][0]

    def begin(self) -> None:
        """Clear this frame's target to 'no surface' (view depth −1): the sky's pixels keep that."""
        self._sets[self._turn][1].clear(0.0, 0.0, 0.0, -1.0)

    def set_uniforms(self, p, unit: int, camera, alpha: float) -> None:
        """The uniforms of ``glsl/indirect_history.glsl`` in program ``p``, the last frame's output
        bound to texture unit ``unit``."""
        values = {"u_prev_irr": unit, "u_history_alpha": float(alpha), "u_has_prev": self._prev is not None,
                  "u_pixel_angle": math.radians(camera.fov_y_deg) / self.size[1]}
        if self._prev is not None:
            vp, pos, fwd = self._prev
            values.update(u_prev_camera_pos=tuple(float(v) for v in pos),
                          u_prev_camera_forward=tuple(float(v) for v in fwd))
            if (u := uniform(p, "u_prev_view_proj")) is not None:
                u.write(vp.T.astype(np.float32).tobytes())
        self._sets[1 - self._turn][0].use(location=unit)
        for name, value in values.items():
            if (u := uniform(p, name)) is not None:
                u.value = value

    def end(self, view_proj: np.ndarray, camera) -> None:
        """This frame is drawn: it becomes the last frame."""
        self._prev = (np.asarray(view_proj, np.float64).copy(), np.asarray(camera.position, np.float64).copy(),
                      np.asarray(camera.forward, np.float64).copy())
        self._turn = 1 - self._turn

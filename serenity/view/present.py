"""GL passes that put the renderer's textures on the window (``glsl/view_present.glsl``,
``glsl/view_lines.glsl``) — nothing is read back to draw a frame.

``PresentPass.draw(fbo, viewport, a, mode_a, b=None, mode_b=0, split=2.0, exposure=...)`` draws
texture ``a`` (and ``b`` right of the ``split`` x in [0, 1]) into ``viewport`` (x, y, w, h, GL
pixels) of ``fbo`` with nearest-texel sampling: at the render's own size a pixel is copied exactly.
Modes (see the shader): DISPLAY, HDR (exposure + Reinhard + sRGB, as ``TonemapPass``), SIGNED
(0.5 + 0.5·v), LINEAR (sRGB-encoded), SCALAR (red channel as grey).

``AccumulatePass.add(hdr, samples)`` (``glsl/view_accumulate.glsl``) keeps the running mean of a
still view's jittered HDR frames in ``AccumulatePass.mean`` (RGBA32F, render size): temporal
anti-aliasing, drawn with the HDR mode.

``LinesPass.draw(fbo, viewport, view_proj, boxes)`` draws axis-aligned boxes ((min, max, rgb))
as world-space wireframes over the image (the LPV cascades' bounds).
"""

from __future__ import annotations

import moderngl
import numpy as np

from serenity.config import DEFAULT_EXPOSURE
from serenity.raster.context import FullscreenPass, fullscreen_vao, load_program

DISPLAY, HDR, SIGNED, LINEAR, SCALAR = range(5)

_EDGES = [(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7)]


class PresentPass:
    def __init__(self, ctx):
        self.ctx = ctx
        self.program = load_program(ctx, "view_present.glsl")
        self.vao = fullscreen_vao(ctx, self.program)

    def draw(self, fbo, viewport, a, mode_a: int, b=None, mode_b: int = DISPLAY, split: float = 2.0,
             exposure: float = DEFAULT_EXPOSURE, block: int = 1, render_size=None) -> None:
        """Draw ``a`` (and ``b`` right of ``split``) into ``viewport``. ``block`` > 1: ``a`` is a
        1/block-resolution image of a ``render_size`` (w, h) render (SSAO), each texel shown over its
        block×block pixels (texel = pixel // block, as ``Renderer`` writes such an AOV; the texture
        is ⌈size / block⌉ texels, so a plain stretch would not line up)."""
        p = self.program
        fbo.use()
        fbo.viewport = tuple(int(v) for v in viewport)
        a.use(location=0)
        (b if b is not None else a).use(location=1)
        p["u_a"].value, p["u_b"].value = 0, 1
        p["u_mode_a"].value, p["u_mode_b"].value = int(mode_a), int(mode_b)
        p["u_exposure"].value = float(exposure)
        p["u_split"].value = float(split) if b is not None else 2.0
        p["u_line_px"].value = 1.0 / max(1, int(viewport[2]))
        p["u_block_a"].value = max(1, int(block))
        rs = render_size if render_size is not None else a.size
        p["u_render_size"].value = (int(rs[0]), int(rs[1]))
        self.vao.render(vertices=3)


class AccumulatePass(FullscreenPass):
    SHADER = "view_accumulate.glsl"
    TARGETS = {"mean": (4, "f4")}

    def add(self, hdr, samples: int) -> None:
        """Fold ``hdr`` (a texture of the render's size) into the mean as its ``samples``-th frame
        (1 = start afresh: the mean becomes ``hdr``)."""
        ctx, p = self.ctx, self.program
        self.fbo.use()
        ctx.enable_only(moderngl.BLEND)
        ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        ctx.blend_equation = moderngl.FUNC_ADD
        try:
            hdr.use(location=0)
            p["u_frame"].value = 0
            p["u_weight"].value = 1.0 / float(samples)
            self.vao.render(vertices=3)
        finally:
            ctx.enable_only(moderngl.NOTHING)


def box_segments(lo, hi) -> np.ndarray:
    """(24, 3) float32 endpoints of the 12 edges of the box [lo, hi]."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    corners = np.array([[(hi if (i >> k) & 1 else lo)[k] for k in range(3)] for i in range(8)])
    return corners[np.array(_EDGES).reshape(-1)].astype(np.float32)


class LinesPass:
    def __init__(self, ctx):
        self.ctx = ctx
        self.program = load_program(ctx, "view_lines.glsl")
        self.vbo = ctx.buffer(reserve=24 * 6 * 4 * 8)
        self.vao = ctx.vertex_array(self.program, [(self.vbo, "3f 3f", "in_position", "in_color")])

    def draw(self, fbo, viewport, view_proj: np.ndarray, boxes) -> None:
        if not boxes:
            return
        data = np.concatenate([np.hstack([box_segments(lo, hi), np.tile(np.asarray(rgb, np.float32), (24, 1))])
                               for lo, hi, rgb in boxes]).astype(np.float32)
        if data.nbytes > self.vbo.size:
            self.vbo.orphan(data.nbytes)
        self.vbo.write(data.tobytes())
        fbo.use()
        fbo.viewport = tuple(int(v) for v in viewport)
        self.program["u_view_proj"].write(np.asarray(view_proj).T.astype(np.float32).tobytes())
        self.vao.render(moderngl.LINES, vertices=len(data))

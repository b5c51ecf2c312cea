"""FXAA post pass on the linear HDR frame, before the tone map (``glsl/fxaa.glsl``).

A deferred renderer has no MSAA to lean on (the G-buffer holds one surface per pixel), so edges are
anti-aliased in image space: 5 luma taps find the local contrast and the edge direction, and up to 4
bilinear taps along the edge blend it (Lottes 2009). One fullscreen pass of 9 texture taps; flat and
textured areas below the contrast threshold are passed through. The blend is done on linear
radiance (what the reference's pixel filter averages), the edge detection on a display-like luma.
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl

from serenity.errors import SerenityError
from serenity.raster.context import FullscreenPass


@dataclass(frozen=True)
class FXAAConfig:
    edge_min: float = 1.0 / 24.0
    """Luma contrast (display-like luma in [0, 1]) below which a pixel is left alone (FXAA 3.11's
    ``edgeThresholdMin`` "high quality" value)."""
    edge_rel: float = 1.0 / 8.0
    """... and below this fraction of the local luma maximum (``edgeThreshold``, "high quality")."""
    span_max: float = 8.0
    """Longest blend along an edge, pixels."""

    def __post_init__(self):
        if not (0 <= self.edge_min < 1 and 0 <= self.edge_rel < 1 and 1 <= self.span_max <= 32):
            raise SerenityError(f"FXAAConfig: need 0 <= edge_min, edge_rel < 1 and 1 <= span_max <= 32, got {self}")


class FXAAPass(FullscreenPass):
    SHADER = "fxaa.glsl"
    TARGETS = {"hdr": (4, "f4")}

    def __init__(self, ctx, config: FXAAConfig | None = None):
        super().__init__(ctx)
        self.config = config or FXAAConfig()

    def render(self, hdr_texture, exposure: float):
        """The anti-aliased copy of ``hdr_texture`` (same size), in this pass's own ``hdr`` target."""
        cfg, p = self.config, self.program
        with self.ctx.debug_scope("fxaa"):
            old = hdr_texture.filter
            hdr_texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
            hdr_texture.repeat_x = hdr_texture.repeat_y = False
            try:
                self.fbo.use()
                hdr_texture.use(location=0)
                p["u_hdr"].value = 0
                p["u_exposure"].value = float(exposure)
                p["u_edge_min"].value = float(cfg.edge_min)
                p["u_edge_rel"].value = float(cfg.edge_rel)
                p["u_span_max"].value = float(cfg.span_max)
                self.vao.render(vertices=3)
            finally:
                hdr_texture.filter = old
        return self.hdr

"""How the main view computes its indirect light: ``IndirectConfig`` (reduced resolution, the
upsampling's refinement and its temporal history)."""

from __future__ import annotations

from dataclasses import dataclass

from serenity.errors import ConfigError


@dataclass(frozen=True)
class IndirectConfig:
    """How the main view's indirect light (the sky volume's and the LPV's, diffuse and glossy) and
    its SSAO are computed: at a fraction of the view's resolution, joint-bilaterally upsampled,
    refined at full resolution where the upsampling finds no like texel, and blended with the last
    frame's (``serenity/raster/lowres.py``, ``raster/temporal.py``). What light there is comes from
    ``RenderConfig.sky`` and ``RenderConfig.lpv``."""

    scale: int = 2
    """The main view's SSAO and indirect light are computed at 1/scale of the view per axis and
    joint-bilaterally upsampled (1 = full resolution, the paper's)."""
    history: float = 0.2
    """With ``scale`` > 1: the weight of this frame's upsampled indirect light against the last
    frame's at the same surface point (reprojected per pixel; disocclusions take this frame's
    alone), 1 = none of the last frame's. Against the light that slid over the surfaces with the
    low-res points as the camera moved (``raster/temporal.py``; ``docs/stability.md``)."""
    refine_below: float = 0.0
    """With ``scale`` > 1: pixels whose most alike low-res texel (the upsampling's guide similarity:
    depth and normal, ``glsl/lowres.glsl``) is below this have their indirect light computed at full
    resolution instead of upsampled (``raster/lowres.IndirectRefinement``): surfaces narrower than
    the low-res grid and the far sides of silhouettes, which otherwise take a neighbouring surface's
    light. 0 = none: the LPV presets' light is smooth enough that refining moved FLIP by at most
    0.0007 (courtyard, Cornell box) for 9–15 % of their frame; the ``traced-probes`` preset sets
    0.05 (docs/techniques.md)."""
    tile_balance: bool = True
    """Lay the reduced-resolution images out centred on the GL rasteriser's 64-pixel tiles
    (``raster/context.LowResLayout``): llvmpipe shades each tile on one thread, and at 320×180 a
    quarter-resolution row of 80 texels fell into tiles of 64 and 16. The same image either way
    (within float rounding); False: the images at their targets' origin."""

    def __post_init__(self):
        if not (isinstance(self.scale, int) and 1 <= self.scale <= 8):
            raise ConfigError(f"IndirectConfig.scale must be an int in 1..8, got {self.scale!r}")
        if not (isinstance(self.history, (int, float)) and 0.0 < self.history <= 1.0):
            raise ConfigError(f"IndirectConfig.history must be in (0, 1], got {self.history!r}")
        if not (isinstance(self.refine_below, (int, float)) and 0.0 <= self.refine_below <= 1.0):
            raise ConfigError(f"IndirectConfig.refine_below must be in [0, 1], got {self.refine_below!r}")

"""Sun shadows: ``ShadowConfig`` (cascaded shadow maps + PCSS, paper §6)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from serenity.config.image import MAX_IMAGE_SIZE
from serenity.errors import ConfigError


@dataclass(frozen=True)
class ShadowConfig:
    """Sun shadows: cascaded shadow maps + PCSS (paper §6). See ``serenity/raster/shadow.py``."""

    size: int = 2048
    """Resolution of one cascade (texels per side); the atlas holds 2×2 tiles. With
    ``texels_per_pixel`` the most it may be."""
    texels_per_pixel: float = 0.0
    """> 0: size each cascade to this many texels per pixel of the image's longer side (multiples of
    64, at least 512, at most ``size``; ``size_for``), so a small image does not draw and clear
    shadow maps far finer than its pixels can show; 0: always ``size``. The paper's 2048² at
    1280×720 is 1.6 texels per pixel."""
    cascades: int = 4
    """Number of cascades, 1–4."""
    split_lambda: float = 0.75
    """Practical split scheme blend: 0 uniform, 1 logarithmic."""
    max_distance: float = 200.0
    """Farthest view depth (m) that receives cascaded shadows (also clamped to the scene)."""
    cascade_blend: float = 0.1
    """Fraction of each cascade's depth range cross-faded into the next (hides the seam)."""
    filter: str = "pcss"
    """"hard" (1 tap), "pcf" (fixed radius), or "pcss" (penumbra from the sun's angular size)."""
    pcf_radius: float = 2.0
    """PCF filter radius in texels ("pcf" mode)."""
    blocker_samples: int = 16
    """PCSS blocker-search taps."""
    filter_samples: int = 32
    """PCF / PCSS filter taps."""
    pcss_max_blocker: float = 20.0
    """Farthest blocker (m above the receiver) the PCSS blocker search is sized for."""
    bias: float = 1.0
    """Constant depth bias, in shadow-map texels (converted to depth units in the shader), below the
    receiver's plane that each tap compares with (``serenity/raster/shadow.py``)."""
    normal_offset: float = 0.0
    """Normal offset of the lookup point, in texels, scaled by the slope tan θ (clamped 1–4). 0: the
    receiver-plane comparison (``bias``) already keeps surfaces from shadowing themselves, and an
    offset of 1 texel cuts the eaves' shadows on walls short under a grazing sun (~0.3 m in the
    courtyard at 320×180)."""
    stagger: bool = False
    """Redraw the cascades after the first in turn, one per frame, while each still covers its slice
    (tiles fitted 10 % larger to leave room), instead of every cascade whose light matrix moved: with
    the sun moving every frame, 2 tiles are drawn per frame instead of 4 and the far cascades' shadows
    lag the sun by up to 3 frames. A redrawn tile is faded in over those frames, pixel by pixel,
    from its version before (a second slot per tile in the atlas), instead of switched at once. The
    same for the overlapped shadow maps. A still frame is unchanged apart from the 10 % coarser
    tiles (``ShadowPass.render``)."""
    contact_steps: int = 6
    """Steps of the screen-space contact-shadow march towards the sun (main view; 0 = off): a
    receiver touching a blocker closer than the map's texels (``glsl/deferred.glsl``). 6: the
    receiver-plane comparison finds the longer contact shadows itself, and 12 steps give the same
    FLIP and relMSE within 0.001 in both test scenes."""
    contact_pixels: float = 12.0
    """Length of the contact-shadow march, in pixel footprints at the receiver ..."""
    contact_texels: float = 32.0
    """... and at most this many shadow-map texels of the receiver's cascade."""
    visibility: str = "pixel"
    """Where the main view's sun visibility (the filter above and the contact march) is computed:
    "pixel" = at every pixel, in the lighting pass; "checkerboard" = at every other pixel of each
    row and column, in a pass of its own, the others from their 4 neighbours; "half" = once per 2×2
    block, upsampled bilaterally (``glsl/visibility_upsample.glsl``)."""

    def __post_init__(self):
        if not 16 <= self.size <= MAX_IMAGE_SIZE:
            raise ConfigError(f"ShadowConfig.size must be in 16..{MAX_IMAGE_SIZE}, got {self.size}")
        if not 1 <= self.cascades <= 4:
            raise ConfigError(f"ShadowConfig.cascades must be 1..4, got {self.cascades}")
        if not (isinstance(self.texels_per_pixel, (int, float)) and math.isfinite(self.texels_per_pixel)
                and 0.0 <= self.texels_per_pixel <= 16.0):
            raise ConfigError(f"ShadowConfig.texels_per_pixel must be in 0..16, got {self.texels_per_pixel!r}")
        if self.filter not in ("hard", "pcf", "pcss"):
            raise ConfigError(f"ShadowConfig.filter must be hard, pcf or pcss, got {self.filter!r}")
        if not 1 <= self.blocker_samples <= 128:
            raise ConfigError(f"ShadowConfig.blocker_samples must be in 1..128, got {self.blocker_samples}")
        if not 1 <= self.filter_samples <= 256:
            raise ConfigError(f"ShadowConfig.filter_samples must be in 1..256, got {self.filter_samples}")
        if not 0 <= self.contact_steps <= 64:
            raise ConfigError(f"ShadowConfig.contact_steps must be in 0..64, got {self.contact_steps}")
        if not self.contact_pixels > 0:
            raise ConfigError(f"ShadowConfig.contact_pixels must be > 0, got {self.contact_pixels}")
        if not self.contact_texels > 0:
            raise ConfigError(f"ShadowConfig.contact_texels must be > 0, got {self.contact_texels}")
        if self.visibility not in ("pixel", "checkerboard", "half"):
            raise ConfigError(f"ShadowConfig.visibility must be pixel, checkerboard or half, got {self.visibility!r}")

    def size_for(self, width: int, height: int) -> int:
        """Texels per side of one cascade for a ``width``×``height`` image (``texels_per_pixel``)."""
        if self.texels_per_pixel <= 0.0:
            return self.size
        want = 64 * math.ceil(self.texels_per_pixel * max(width, height) / 64.0)
        return int(min(self.size, max(512, want)))

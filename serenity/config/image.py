"""The image's limits and tone mapping: the largest image or shadow-map side, and the exposure that
radiance is scaled by before the tone map."""

from __future__ import annotations

from serenity.errors import SerenityError

MAX_IMAGE_SIZE = 8192
"""Largest image or shadow-map side, pixels (the texture size every OpenGL 4.3 implementation here supports)."""
DEFAULT_EXPOSURE = 0.02
"""Multiplier applied to radiance (W·m⁻²·sr⁻¹) before Reinhard; 0.02 maps a white wall in noon
sun (≈300) to about 0.86 display luminance. The CLI's and the metrics' default too."""


def check_image_size(width, height, what: str = "image size") -> tuple[int, int]:
    """(width, height) as ints, or a ``SerenityError`` naming ``what`` when a side is outside
    1..``MAX_IMAGE_SIZE``."""
    if not (1 <= int(width) <= MAX_IMAGE_SIZE and 1 <= int(height) <= MAX_IMAGE_SIZE):
        raise SerenityError(f"{what} must be within 1..{MAX_IMAGE_SIZE} pixels per side, got {width}x{height}")
    return int(width), int(height)

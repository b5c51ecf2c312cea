"""8-bit sRGB PNG files through Pillow. Row 0 is the top of the image."""

from __future__ import annotations

import numpy as np
from PIL import Image, UnidentifiedImageError

from serenity.errors import SerenityError


def write_png(path: str, image: np.ndarray) -> None:
    """Write an (H, W, 3|4) uint8 image (already tone-mapped and sRGB-encoded)."""
    a = np.asarray(image)
    if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] not in (3, 4):
        raise SerenityError(f"{path}: expected an (H, W, 3|4) uint8 image, got {a.dtype} {a.shape}")
    try:
        Image.fromarray(np.ascontiguousarray(a)).save(path)
    except OSError as exc:
        raise SerenityError(f"{path}: cannot write PNG ({exc})") from exc


def read_png(path: str) -> np.ndarray:
    """Read a PNG as (H, W, 3) uint8 RGB."""
    try:
        with Image.open(path) as im:
            return np.asarray(im.convert("RGB"))
    except FileNotFoundError as exc:
        raise SerenityError(f"{path}: no such PNG file") from exc
    except (UnidentifiedImageError, OSError) as exc:
        raise SerenityError(f"{path}: not a readable image ({exc})") from exc

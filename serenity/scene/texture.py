"""Albedo textures: sRGB decoding, the mip chain, and loading images into :class:`Texture`.

- sRGB decoding and encoding use :mod:`serenity.colour` (IEC 61966-2-1).
- ``build_mips(img)``: level k+1 is the 2×2 box filter of level k, down to 1×1. Level sizes follow
  OpenGL (``max(1, floor(n / 2))`` per axis), so the chain can be uploaded level by level as is.
  Texel (i, j) of level k+1 averages texels (2i..2i+1, 2j..2j+1) of level k with the indices
  *clamped* to the level's last row/column: where an axis has size 1 the texel is averaged with
  itself (a pure 1-D box filter along the other axis); where an axis has odd size the last
  row/column of that level is not covered by the next level (as in GL's box-filter rule).
- Images are stored top row first (row 0 = top of the picture). Texture coordinates follow the
  OpenGL convention used by trimesh and the GL passes: u right, v **up**, (0, 0) at the bottom-left;
  coordinates outside [0, 1] repeat (glTF's default wrap mode).
- Colour channels are decoded from sRGB when ``srgb=True``; an alpha channel is always linear.
"""

from __future__ import annotations

import os

import numpy as np
from PIL import Image, UnidentifiedImageError

from serenity.colour import linear_to_srgb, srgb_to_linear
from serenity.errors import SceneError
from serenity.scene.model import Texture

__all__ = [
    "build_mips",
    "load_texture",
    "texture_from_array",
    "texture_from_image",
    "texture_to_srgb8",
]

def _box_down(a: np.ndarray) -> np.ndarray:
    """One 2×2 box-filter step (see the module docstring for sizes and clamping), summed in float64."""
    h, w = a.shape[:2]
    rows = (slice(0, 1), slice(0, 1)) if h == 1 else (slice(0, h // 2 * 2, 2), slice(1, h // 2 * 2, 2))
    cols = (slice(0, 1), slice(0, 1)) if w == 1 else (slice(0, w // 2 * 2, 2), slice(1, w // 2 * 2, 2))
    s = a[rows[0], cols[0]].astype(np.float64)  # views, not copies: a 2048² level is 100 MB in float64
    s += a[rows[0], cols[1]]
    s += a[rows[1], cols[0]]
    s += a[rows[1], cols[1]]
    return s * 0.25


def build_mips(img) -> list[np.ndarray]:
    """The full mip chain of an (H, W, C) image: ``[img, ½, ¼, ..., 1×1]``, float32 each.

    A 2-D (H, W) image is treated as one channel. Each level is the 2×2 box filter of the previous
    one (sizes and odd/1-pixel handling as in the module docstring).
    """
    a = np.asarray(img, dtype=np.float32)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[0] < 1 or a.shape[1] < 1:
        raise SceneError(f"a texture must be an (H, W, C) array, got shape {a.shape}")
    mips = [np.ascontiguousarray(a)]
    while mips[-1].shape[0] > 1 or mips[-1].shape[1] > 1:
        mips.append(np.ascontiguousarray(_box_down(mips[-1]).astype(np.float32)))
    return mips


def texture_from_array(array, name: str = "array", srgb: bool = False) -> Texture:
    """A :class:`Texture` from an (H, W), (H, W, 1), (H, W, 3) or (H, W, 4) array.

    uint8 data is scaled by 1/255, uint16 by 1/65535; floats are taken as they are. With
    ``srgb=True`` the colour channels are decoded sRGB → linear (alpha stays linear). One channel
    becomes grey RGB, two channels grey + alpha. Row 0 is the top of the image.
    """
    a = np.asarray(array)
    if a.dtype == np.uint8 and a.ndim == 3 and a.shape[2] in (3, 4) and a.shape[0] >= 1 and a.shape[1] >= 1:
        # 8-bit colour: decoded through a table of the 256 values (the same float64 arithmetic, once
        # per value instead of once per texel: a second of a 2048² texture)
        lut = (srgb_to_linear(np.arange(256) / 255.0) if srgb else np.arange(256) / 255.0).astype(np.float32)
        out = lut[a]
        if a.shape[2] == 4:
            out[:, :, 3] = (np.arange(256) / 255.0).astype(np.float32)[a[:, :, 3]]
        return Texture(name=name, mips=build_mips(out))
    if a.dtype == np.uint8:
        a = a.astype(np.float64) / 255.0
    elif a.dtype == np.uint16:
        a = a.astype(np.float64) / 65535.0
    elif np.issubdtype(a.dtype, np.integer) or a.dtype == bool:
        raise SceneError(f"texture {name!r}: unsupported integer pixel type {a.dtype}")
    else:
        a = a.astype(np.float64)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[2] not in (1, 2, 3, 4) or a.shape[0] < 1 or a.shape[1] < 1:
        raise SceneError(f"texture {name!r}: expected an (H, W[, 1|2|3|4]) image, got shape {np.shape(array)}")
    if not np.all(np.isfinite(a)):
        raise SceneError(f"texture {name!r}: contains NaN or infinite values")
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    elif a.shape[2] == 2:
        a = np.concatenate([np.repeat(a[:, :, :1], 3, axis=2), a[:, :, 1:]], axis=2)
    if srgb:
        a = a.copy()
        a[:, :, :3] = srgb_to_linear(a[:, :, :3])
    return Texture(name=name, mips=build_mips(a.astype(np.float32)))


def texture_from_image(image, name: str, srgb: bool = True) -> Texture:
    """A :class:`Texture` from a PIL image (palette, grey, 16-bit and CMYK images are converted)."""
    mode = image.mode
    if mode in ("RGBA", "LA", "PA") or (mode == "P" and "transparency" in image.info):
        image = image.convert("RGBA")
    elif mode in ("I;16", "I;16B", "I;16L", "I"):
        arr = np.asarray(image, dtype=np.float64) / (65535.0 if mode.startswith("I;16") else 2.0**31 - 1)
        return texture_from_array(np.clip(arr, 0, 1), name=name, srgb=srgb)
    elif mode == "F":
        return texture_from_array(np.asarray(image, dtype=np.float32), name=name, srgb=srgb)
    elif mode != "RGB":
        image = image.convert("RGB")
    return texture_from_array(np.asarray(image, dtype=np.uint8), name=name, srgb=srgb)


def load_texture(path, srgb: bool = True) -> Texture:
    """Load an image file (PNG, JPEG, ... anything Pillow decodes) as a linear :class:`Texture`.

    ``srgb=True`` (albedo maps) decodes the colour channels from sRGB. A missing file or one that
    does not decode raises :class:`SceneError` naming the file and the problem.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise SceneError(f"{path}: texture file not found")
    try:
        with Image.open(path) as im:
            im.load()
            return texture_from_image(im, name=path, srgb=srgb)
    except SceneError:
        raise
    except UnidentifiedImageError:
        raise SceneError(f"{path}: not an image Pillow can decode") from None
    except (OSError, ValueError, SyntaxError) as e:
        raise SceneError(f"{path}: cannot decode image ({_one_line(e)})") from None


def texture_to_srgb8(texture: Texture) -> np.ndarray:
    """Level 0 of a texture encoded back to (H, W, C) uint8 sRGB (alpha linear) — for export."""
    a = np.asarray(texture.mips[0], dtype=np.float64).copy()
    a[:, :, :3] = linear_to_srgb(a[:, :, :3])
    return np.clip(np.rint(a * 255.0), 0, 255).astype(np.uint8)


def _one_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return (text[0] if text else type(e).__name__)[:200]

"""GL textures ⇄ arrays. The only place where CPU and CUDA data paths would differ.

Today both paths go through host memory (``Texture.read`` / ``Texture.write``): Warp arrays on
CUDA are copied to numpy first. (CUDA–GL interop via ``wp.RegisteredGLBuffer`` would avoid the
copy on a GPU machine; it is not used because the EGL context here may sit on llvmpipe.)

GL's row 0 is the bottom of an image; arrays here use row 0 = top, so reads and writes flip.
"""

from __future__ import annotations

import moderngl
import numpy as np

from serenity.errors import SerenityError
from serenity.raster.context import finish

_DTYPES = {"f4": np.float32, "f2": np.float16, "f1": np.uint8}


def read_texture(tex, components: int | None = None) -> np.ndarray:
    """(H, W, C) array of a 2-D texture (top row first); float targets come back as float32."""
    finish(tex.ctx)  # the read waits for the rendering with the GIL held; this waits without it
    c = tex.components
    data = np.frombuffer(tex.read(), dtype=_DTYPES[tex.dtype]).reshape(tex.height, tex.width, c)
    data = data[::-1]
    if components is not None:
        data = data[..., :components]
    return np.ascontiguousarray(data.astype(np.float32) if tex.dtype != "f1" else data)


def read_depth(tex) -> np.ndarray:
    """(H, W) float32 window-space depth in [0, 1] (top row first)."""
    finish(tex.ctx)
    data = np.frombuffer(tex.read(), dtype=np.float32).reshape(tex.height, tex.width)
    return np.ascontiguousarray(data[::-1])


def upload_texture(ctx, arr: np.ndarray, dtype: str = "f4", mips: list[np.ndarray] | None = None,
                       repeat: bool = True, anisotropy: float = 8.0):
    """A 2-D texture from (H, W, C) data (top row first). ``mips`` (level 0 first) are written as
    given, so GL samples exactly the CPU ray tracer's box-filtered chain; with mips, trilinear
    filtering plus ``anisotropy``."""
    a = np.asarray(arr)
    h, w, c = a.shape
    np_dtype = _DTYPES[dtype]
    tex = ctx.texture((w, h), c, np.ascontiguousarray(a[::-1]).astype(np_dtype).tobytes(), dtype=dtype)
    if mips and len(mips) > 1:
        tex.build_mipmaps(0, len(mips) - 1)
        for level, m in enumerate(mips[1:], start=1):
            tex.write(np.ascontiguousarray(np.asarray(m)[::-1]).astype(np_dtype).tobytes(), level=level)
        tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        tex.anisotropy = float(anisotropy)
    tex.repeat_x = tex.repeat_y = repeat
    return tex


def upload_texture3d(ctx, arr: np.ndarray, dtype: str = "f4"):
    """A 3-D texture from (D, H, W, C) data (no flip: volumes are indexed as stored)."""
    a = np.ascontiguousarray(arr, dtype=_DTYPES[dtype])
    d, h, w, c = a.shape
    limit = int(ctx.info.get("GL_MAX_3D_TEXTURE_SIZE", 0) or 0)
    if limit and max(w, h, d) > limit:  # GL would fail later, at an unrelated call, with a bare 0x501
        raise SerenityError(f"a volume of {w} x {h} x {d} texels does not fit this GL's 3D textures "
                            f"(at most {limit} per axis); use a coarser grid")
    tex = ctx.texture3d((w, h, d), c, a.tobytes(), dtype=dtype)
    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    tex.repeat_x = tex.repeat_y = tex.repeat_z = False
    return tex

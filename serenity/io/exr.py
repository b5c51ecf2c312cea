"""Multi-layer OpenEXR files (float32, ZIP compression) through the ``OpenEXR`` package.

Layer naming follows the usual compositor convention: the layer called ``beauty`` is written as the
default, unprefixed ``R, G, B`` channels (what any viewer shows first); every other layer ``name``
becomes ``name.R, name.G, name.B`` (3 channels), ``name.R … name.A`` (4) or ``name.Y`` (1).
``read_exr`` inverts this: it returns ``{"beauty": (H,W,3), "albedo": (H,W,3), "depth": (H,W,1), ...}``.
Row 0 is the top of the image, as in :class:`serenity.frame.Frame`.
"""

from __future__ import annotations

import os

import numpy as np
import OpenEXR

from serenity.errors import SerenityError

_SUFFIXES = {1: ("Y",), 2: ("R", "G"), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}
_ORDER = {"R": 0, "G": 1, "B": 2, "A": 3, "Y": 0, "Z": 0}


def write_exr(path: str, layers: dict[str, np.ndarray]) -> None:
    """Write ``layers`` (each (H, W) or (H, W, C), C in 1..4, all the same H, W) as one EXR file."""
    if not layers:
        raise SerenityError(f"{path}: nothing to write (no layers)")
    channels: dict[str, np.ndarray] = {}
    shape = None
    for name, img in layers.items():
        a = np.asarray(img, dtype=np.float32)
        if a.ndim == 2:
            a = a[..., None]
        if a.ndim != 3 or a.shape[2] not in _SUFFIXES:
            raise SerenityError(f"{path}: layer {name!r} has shape {a.shape}; expected (H, W) or (H, W, 1..4)")
        if shape is None:
            shape = a.shape[:2]
        elif a.shape[:2] != shape:
            raise SerenityError(f"{path}: layer {name!r} is {a.shape[:2]}, other layers are {shape} (shape mismatch)")
        for c, suffix in enumerate(_SUFFIXES[a.shape[2]]):
            key = suffix if name == "beauty" else f"{name}.{suffix}"
            channels[key] = np.ascontiguousarray(a[..., c])
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    try:
        with OpenEXR.File(header, channels) as f:
            f.write(path)
    except Exception as exc:  # OpenEXR raises plain RuntimeError/OSError with C++ messages
        raise SerenityError(f"{path}: cannot write EXR ({exc})") from exc


def read_exr(path: str) -> dict[str, np.ndarray]:
    """Read every layer of an EXR file as float32 (H, W, C) arrays (see the module doc for names)."""
    if not os.path.isfile(path):
        raise SerenityError(f"{path}: no such EXR file")
    try:
        with OpenEXR.File(path, separate_channels=True) as f:
            raw = {k: np.asarray(v.pixels, dtype=np.float32) for k, v in f.channels().items()}
    except Exception as exc:
        raise SerenityError(f"{path}: not a readable EXR file ({exc})") from exc
    groups: dict[str, list[tuple[str, np.ndarray]]] = {}
    for key, px in raw.items():
        layer, _, suffix = key.rpartition(".")
        groups.setdefault(layer or "beauty", []).append((suffix, px))
    out = {}
    for layer, chans in groups.items():
        chans.sort(key=lambda c: _ORDER.get(c[0], 9))
        out[layer] = np.stack([c[1] for c in chans], axis=-1)
    return out


def read_rgb_layer(path: str, name: str = "beauty") -> np.ndarray:
    """Layer ``name`` of an EXR file as (H, W, 3) float32 (a one-channel layer repeated as grey); a
    missing layer is a ``SerenityError`` listing the file's layers."""
    layers = read_exr(path)
    if name not in layers:
        raise SerenityError(f"{path}: no layer {name!r} (layers: {', '.join(layers)})")
    img = layers[name]
    if img.shape[-1] == 1:
        img = np.repeat(img, 3, axis=-1)
    return img[..., :3]

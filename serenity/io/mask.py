"""Pixel masks for comparisons (``serenity compare --mask``): which pixels a metric counts."""

from __future__ import annotations

import numpy as np

from serenity.errors import SerenityError
from serenity.io.exr import read_exr
from serenity.io.png import read_png


def read_mask(path: str, shape: tuple[int, int]) -> np.ndarray:
    """(H, W) bool from a PNG (red > 127 = counted) or an EXR (layer ``mask``, else ``beauty``, else
    the first layer; channel 0 > 0.5 = counted); a mask whose size is not ``shape`` (H, W) is a
    ``SerenityError``."""
    if path.lower().endswith(".exr"):
        layers = read_exr(path)
        m = layers.get("mask", layers.get("beauty", next(iter(layers.values()))))
        m = np.asarray(m)[..., 0] > 0.5
    else:
        m = read_png(path)[..., 0] > 127
    if m.shape != tuple(shape):
        raise SerenityError(f"{path}: mask is {m.shape[1]}x{m.shape[0]}, images are {shape[1]}x{shape[0]}")
    return m

"""LPV inputs from the G-buffer and the RSM (numpy, host side): VPLs and occluding surfels.

VPLs: (positions (N,3) m, normals (N,3) unit, flux (N,3) W per RGB channel). Surfels: (positions
(M,3) m, normals (M,3), areas (M,) m²). ``sky_vpls_from_gbuffer`` (paper Fig. 11) and
``gbuffer_surfels`` take one sample per stride×stride block of the G-buffer through the same
``sample_gbuffer``; ``rsm_surfels`` turns the sun's RSM VPLs into surfels.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np


def pixel_areas(positions, normals, camera_position, camera_forward, fov_y_deg: float, height: int,
                min_cos: float = 0.2) -> np.ndarray:
    """Surface area (m²) each pixel of a pinhole camera's G-buffer covers, (H, W) float32.

    A pixel spans h = 2·tan(fov_y/2)/height on the image plane at unit depth; at view depth z
    its cross-section perpendicular to the optical axis is (h·z)², perpendicular to its ray
    (h·z)²·cos α (α: ray to axis), and on the surface (h·z)²·cos α / |n·v| (v: the ray), with
    |n·v| clamped to ``min_cos`` (grazing pixels would otherwise claim unbounded area).
    """
    p = np.asarray(positions, np.float32)[..., :3]
    n = np.asarray(normals, np.float32)[..., :3]
    cam = np.asarray(camera_position, np.float32).reshape(3)
    fwd = np.asarray(camera_forward, np.float32).reshape(3)
    fwd = fwd / max(float(np.linalg.norm(fwd)), 1e-12)
    d = p - cam
    r = np.maximum(np.linalg.norm(d, axis=-1), 1e-9)
    z = np.maximum(d @ fwd, 0.0)
    h = 2.0 * math.tan(math.radians(fov_y_deg) / 2.0) / float(height)
    nn = np.maximum(np.linalg.norm(n, axis=-1), 1e-12)
    cos_nv = np.abs(np.einsum("...k,...k->...", n, d)) / (nn * r)
    return ((h * z) ** 2 * (z / r) / np.maximum(cos_nv, min_cos)).astype(np.float32)


class GBufferSamples(NamedTuple):
    """One sample per stride×stride block of a G-buffer (its centre pixel), shapes (H', W', …)."""

    position: np.ndarray
    """(H', W', 3|4) m, as given (w = 0 marks an empty pixel when present)."""
    normal: np.ndarray
    """(H', W', 3)."""
    valid: np.ndarray
    """(H', W') bool: covered (``valid`` given and w ≠ 0)."""
    area: np.ndarray
    """(H', W') m²: the surface area the block covers (``pixel_areas`` of the centre × its pixel count)."""
    pixels: tuple
    """Index of the centre pixels into an (H, W, …) image (``np.ix_``), to sample other G-buffer targets."""


def sample_gbuffer(position, normal, camera_position, camera_forward, fov_y_deg: float, stride: int = 4,
                   valid=None) -> GBufferSamples:
    """The centre pixel of each ``stride``×``stride`` block of a G-buffer (edge blocks may be partial)
    with the surface area its block covers. position (H,W,3|4) m, normal (H,W,3|4), valid (H,W) bool."""
    pos = np.asarray(position, np.float32)
    h, w = pos.shape[:2]
    y0, x0 = np.arange(0, h, stride), np.arange(0, w, stride)
    ys, xs = np.minimum(y0 + stride // 2, h - 1), np.minimum(x0 + stride // 2, w - 1)
    counts = (np.minimum(stride, h - y0)[:, None] * np.minimum(stride, w - x0)[None, :]).astype(np.float32)
    sel = np.ix_(ys, xs)
    p = pos[sel]
    n = np.asarray(normal, np.float32)[sel][..., :3]
    ok = np.ones(p.shape[:2], bool) if valid is None else np.asarray(valid, bool)[sel]
    if p.shape[-1] == 4:
        ok &= p[..., 3] != 0
    area = pixel_areas(p, n, camera_position, camera_forward, fov_y_deg, h) * counts
    return GBufferSamples(p, n, ok, area, sel)


def sky_vpls_from_gbuffer(position, normal, albedo, sky_irradiance, camera_position, camera_forward,
                          fov_y_deg: float, stride: int = 4, valid=None):
    """Sky-light VPLs (paper Fig. 11): the G-buffer, lit by the sky, used as a reflective shadow map.

    position (H,W,3|4) m (w = 0 marks an empty pixel when present), normal (H,W,3|4), albedo
    (H,W,3|4) linear, sky_irradiance (H,W,3) W/m² (the caller's sky lighting at each pixel, with
    whatever visibility it applies), camera position/forward and vertical fov (degrees). One VPL
    per ``stride``×``stride`` block (its centre pixel), flux = albedo·E_sky·A with A the block's
    surface area (``sample_gbuffer``). Returns (positions (N,3), normals (N,3), flux (N,3)) float32,
    only VPLs with positive flux.
    """
    s = sample_gbuffer(position, normal, camera_position, camera_forward, fov_y_deg, stride, valid)
    return sky_vpls_from_samples(s, albedo, sky_irradiance)


def sky_vpls_from_samples(s: GBufferSamples, albedo, sky_irradiance):
    """``sky_vpls_from_gbuffer`` from its ``sample_gbuffer`` samples (shared with ``surfels_from_samples``)."""
    rho = np.asarray(albedo, np.float32)[s.pixels][..., :3]
    e = np.asarray(sky_irradiance, np.float32)[s.pixels][..., :3]
    flux = rho * e * s.area[..., None]
    ok = s.valid & np.all(np.isfinite(flux), axis=-1) & (flux.max(axis=-1) > 0)
    return (np.ascontiguousarray(s.position[ok][:, :3]), np.ascontiguousarray(s.normal[ok]),
            np.ascontiguousarray(flux[ok]))


def gbuffer_surfels(position, normal, camera_position, camera_forward, fov_y_deg: float, stride: int = 4,
                    valid=None):
    """Occluding surfels for the geometry volume from a G-buffer: (positions, normals, areas (M,))."""
    return surfels_from_samples(sample_gbuffer(position, normal, camera_position, camera_forward, fov_y_deg,
                                               stride, valid))


def surfels_from_samples(s: GBufferSamples):
    """``gbuffer_surfels`` from its ``sample_gbuffer`` samples."""
    ok = s.valid & np.isfinite(s.area) & (s.area > 0)
    return (np.ascontiguousarray(s.position[ok][:, :3]), np.ascontiguousarray(s.normal[ok]),
            np.ascontiguousarray(s.area[ok]))


def rsm_surfels(vpls, sun_direction, min_cos: float = 0.2):
    """Occluding surfels from RSM VPLs (``positions``, ``normals``, ``texel_area`` m² perpendicular
    to the sun): area on the surface = texel_area / max(n·l, min_cos)."""
    n = np.asarray(vpls.normals, np.float32)
    l_dir = np.asarray(sun_direction, np.float32).reshape(3)
    cos = np.maximum(np.abs(n @ l_dir) / np.maximum(np.linalg.norm(n, axis=-1), 1e-12), min_cos)
    area = (float(vpls.texel_area) / cos).astype(np.float32)
    return np.asarray(vpls.positions, np.float32), n, area


"""Ray-traced ground truth for the raster approximations: sun-disc visibility (what CSM + PCSS
estimate) and ambient occlusion (what SSAO estimates), by tracing the scene's kd-tree from
G-buffer points. Used by ``benchmarks/experiments/bench_shadows.py``; the analytic-box twins in
``tests/raster/exact.py`` share the sun-disc sampling."""

from __future__ import annotations

import math

import numpy as np


def tangent_frame(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (t, b) orthogonal to each of the unit vectors n (N, 3)."""
    n = np.asarray(n, np.float64)
    a = np.where(np.abs(n[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    t = np.cross(n, a)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return t, np.cross(n, t)


def sun_disc_directions(sun_dir, angular_diameter_deg: float, n: int = 1024, seed: int = 0) -> np.ndarray:
    """(k², 3) unit directions uniformly over the sun's disc (k = ⌊√n⌋, stratified in area)."""
    rng = np.random.default_rng(seed)
    k = int(math.sqrt(n))
    u = (np.arange(k)[:, None] + rng.random((k, k))) / k
    v = (np.arange(k)[None, :] + rng.random((k, k))) / k
    r = np.sqrt(u.ravel()) * math.tan(math.radians(angular_diameter_deg) / 2)
    phi = 2 * math.pi * v.ravel()
    s = np.asarray(sun_dir, np.float64)
    t, b = tangent_frame(s[None])
    d = s[None] + r[:, None] * (np.cos(phi)[:, None] * t + np.sin(phi)[:, None] * b)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def exact_sun_visibility(tree, points, normals, sun_dir, diameter_deg, n=1024, seed=0) -> np.ndarray:
    """Fraction of the sun disc visible from each point (the same stratified disc samples per point),
    traced with ``tree`` (a :class:`~serenity.kernels.kdtree.KdTree`)."""
    origins = points + normals * 1e-3
    vis = np.zeros(len(points))
    dirs = sun_disc_directions(sun_dir, diameter_deg, n, seed)
    for d in dirs:
        vis += ~tree.occluded(origins, np.broadcast_to(d, origins.shape).astype(np.float32))
    return vis / len(dirs)


def exact_ao(tree, points, normals, radius, n=256, seed=0) -> np.ndarray:
    """1 − cosine-weighted fraction of hemisphere rays hitting within ``radius`` (1 = open)."""
    rng = np.random.default_rng(seed)
    t, b = tangent_frame(normals)
    origins = (points + normals * 1e-3).astype(np.float32)
    hits = np.zeros(len(points))
    for _ in range(n):
        u1, u2 = rng.random(len(points)), rng.random(len(points))
        r, phi = np.sqrt(u1), 2 * np.pi * u2
        d = r[:, None] * (np.cos(phi)[:, None] * t + np.sin(phi)[:, None] * b) + np.sqrt(1 - u1)[:, None] * normals
        hits += tree.occluded(origins, d.astype(np.float32), radius)
    return 1.0 - hits / n

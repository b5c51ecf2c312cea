"""Exact (ray-traced, numpy) visibility for the analytic test scenes: a ground plane y=0 and
axis-aligned boxes. Used as the reference for PCSS penumbrae and SSAO."""

import math

import numpy as np

from serenity.eval.exact import sun_disc_directions, tangent_frame


def ray_aabb(o, d, lo, hi, tmax):
    """(N,) bool: rays o + t d, 0 < t < tmax, hit the box [lo, hi]."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t0 = (lo - o) * inv
        t1 = (hi - o) * inv
    tn = np.nanmax(np.minimum(t0, t1), axis=-1)
    tf = np.nanmin(np.maximum(t0, t1), axis=-1)
    return (tn <= tf) & (tf > 1e-6) & (tn < tmax)


def sun_visibility(points, sun_dir, angular_diameter_deg, boxes, n=4096):
    """(P,) fraction of the sun disc visible from each point."""
    dirs = sun_disc_directions(sun_dir, angular_diameter_deg, n)
    vis = np.empty(len(points))
    for i, p in enumerate(points):
        o = np.broadcast_to(p, dirs.shape)
        blocked = np.zeros(len(dirs), bool)
        for lo, hi in boxes:
            blocked |= ray_aabb(o, dirs, np.asarray(lo), np.asarray(hi), np.inf)
        vis[i] = 1.0 - blocked.mean()
    return vis


def ambient_occlusion(points, normals, radius, boxes, n=256, seed=0):
    """(P,) 1 - fraction of cosine-distributed rays blocked within ``radius`` (plane y=0 included)."""
    rng = np.random.default_rng(seed)
    out = np.empty(len(points))
    u1, u2 = rng.random(n), rng.random(n)
    r, phi = np.sqrt(u1), 2 * math.pi * u2
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0, 1 - u1))], axis=1)
    for i, (p, nn) in enumerate(zip(points, normals, strict=True)):
        t, b = tangent_frame(np.asarray(nn)[None])
        d = local @ np.stack([t[0], b[0], nn])
        o = np.broadcast_to(p + nn * 1e-4, d.shape)
        blocked = np.zeros(n, bool)
        for lo, hi in boxes:
            blocked |= ray_aabb(o, d, np.asarray(lo), np.asarray(hi), radius)
        with np.errstate(divide="ignore", invalid="ignore"):
            tg = -o[:, 1] / d[:, 1]
        blocked |= (tg > 1e-6) & (tg < radius)
        out[i] = 1.0 - blocked.mean()
    return out

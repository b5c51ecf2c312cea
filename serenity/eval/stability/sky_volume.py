"""Where the sky irradiance volume fails: light leaking through a wall thinner than a cell into the
gathered probes (``SkyConfig.method = "gather"``), SH ringing under a low bright sun, and occlusion
quads that fit a height field badly; each against a brute-force integral.
"""

from __future__ import annotations

import math
import time

import numpy as np

from serenity.config import SkyConfig
from serenity.eval.stability.harness import Case, brute_sky_irradiance, timed
from serenity.kernels import sh
from serenity.kernels.kdtree import KdTree
from serenity.kernels.sampling import fibonacci_sphere
from serenity.kernels.skyvolume import SkyVolume
from serenity.scene import load
from serenity.scene.model import Camera, Sky, Sun, direction_from_angles
from serenity.scene.procedural import SceneBuilder, plane_scene

# ----------------------------------------------------------------------------------------------
# the sky volume's probes lit by gathering (SkyConfig.method = "gather")
# ----------------------------------------------------------------------------------------------


def gather_thin_wall(frac: float, visibility: bool, device=None, rays: int = 256) -> tuple[float, float]:
    """A 5 cm wall in a grid of 1 m cells, its centre at x = ``frac`` of a cell, lit on its −x face by
    the sun 35° high, a lit floor in front of that face only, a black sky: returns (E on the dark
    face, E on the lit face) of the gathered volume at mid-height, each facing out of the wall
    (W/m²). Exact dark face: 0 — nothing lies on its side. ``visibility``: ``SkyConfig.gather_visibility``
    (else plain trilinear; both with the default lookup offset of half a cell along the normal)."""
    b = SceneBuilder()
    b.material("wall", albedo=(0.8, 0.8, 0.8))
    b.material("floor", albedo=(0.5, 0.5, 0.5))
    x0 = float(frac)
    b.box("wall", (x0 - 0.025, 0.0, -3.0), (x0 + 0.025, 4.0, 3.0))
    b.rect("floor", (x0 - 4.025, 0.0, 0.0), (4.0, 0.0, 0.0), (0.0, 0.0, -3.0))
    b.material("black", albedo=(0.0, 0.0, 0.0))
    b.box("black", (x0 + 3.9, 0.0, -0.05), (x0 + 4.0, 0.1, 0.05))  # reflects nothing: the grid spans the dark side
    el = math.radians(35.0)
    sun = Sun(np.array([-math.cos(el), math.sin(el), 0.0]), irradiance=(1000.0,) * 3)
    camera = Camera(position=(x0 - 6.0, 2.0, 0.0), target=(x0, 2.0, 0.0))
    scene = b.scene("gather-thin-wall", camera, sun, Sky(radiance=(0.0, 0.0, 0.0), model="constant"), [], None)
    cfg = SkyConfig(method="gather", cell_size=1.0, gather_rays=rays, gather_visibility=visibility,
                    ground_albedo=0.0)
    vol = SkyVolume(scene, cfg, device=device)
    vol.grid_origin = np.array([-9.0, 0.5, -3.0])  # probes at integer x: the wall sits ``frac`` into a cell
    vol.rebuild()
    q = np.array([[x0 + 0.025, 2.0, 0.3], [x0 - 0.025, 2.0, 0.3]])
    e = vol.irradiance(q, np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]))[:, 0]
    return float(e[0]), float(e[1])


def gather_thin_wall_case(fracs=(0.1, 0.3, 0.5, 0.7, 0.9), device=None) -> Case:
    """Light leaking through a wall thinner than a cell into the gathered probes' lookup, for wall
    positions across a cell: worst E_dark/E_lit (exact 0) with plain trilinear interpolation (the
    probes on the lit side, which see the lit face, weigh in on the dark side) vs the probes weighed by
    their visibility (``SkyConfig.gather_visibility``). Image: E_dark/E_lit per wall position, without
    (top) and with (bottom)."""
    without, with_, t0, t1 = [], [], 0.0, 0.0
    for f in fracs:
        (d0, l0), ms0 = timed(gather_thin_wall, f, False, device)
        (d1, l1), ms1 = timed(gather_thin_wall, f, True, device)
        without.append(d0 / l0)
        with_.append(d1 / l1)
        t0 += ms0
        t1 += ms1
    img = np.array([without, with_])
    return Case("gathered probes, thin wall (5 cm, 1 m cells)", "sky volume (gather)",
                "max E_dark/E_lit over wall positions in a cell", "probe visibility (depth moments)",
                max(without), max(with_), t0 / len(fracs), t1 / len(fracs), exact=0.0,
                images={"exact": np.zeros_like(img), "without": img[:1], "with": img[1:], "error": img},
                extra={"fracs": list(fracs), "without": without, "with": with_})


# ----------------------------------------------------------------------------------------------
# sky irradiance volume, lit by layers
# ----------------------------------------------------------------------------------------------


def sky_ringing(elevation: float = 3.0, window: str = "none", rays: int = 4096, device=None, normals: int = 128):
    """SH ringing under a low, bright sun: the plane scene under the atmosphere (sun ``elevation``°),
    a 2×2×2 volume without occluders, ``rays`` per probe. Against the brute-force cosine integral
    of the same sky map at ``normals`` Fibonacci normals, at every probe: returns (max |E − E_exact|
    over max E_exact, min of the unclamped SH irradiance over max E_exact, E (probes, normals) of
    the green channel, exact (normals,), ms of the build)."""
    scene = plane_scene(elevation_deg=elevation, azimuth_deg=250.0)
    scene.sky = Sky()  # the atmosphere
    scene.sun.direction = direction_from_angles(elevation, 250.0)
    cfg = SkyConfig(rays_per_probe=rays, resolution=(2, 2, 2), auto_quads=False, normal_offset=0.0, window=window)
    vol = SkyVolume(scene, cfg, device=device)
    vol.rebuild()
    t0 = time.perf_counter()
    vol.rebuild()
    ms = (time.perf_counter() - t0) * 1e3
    n = fibonacci_sphere(normals)
    exact = brute_sky_irradiance(vol.sky_map(), vol.ground_radiance, n)
    peak = float(exact.max())
    pos = vol.probe_positions()
    coeffs = vol.coefficients().reshape(len(pos), 9, 3)
    errs, raws, img = [], [], []
    for i, p in enumerate(pos):
        e = vol.irradiance(np.repeat(p[None], len(n), 0), n)
        raw = sh.sh_basis(n) @ coeffs[i]
        errs.append(np.abs(e - exact).max() / peak)
        raws.append(raw.min() / peak)
        img.append(e[:, 1])
    return float(max(errs)), float(min(raws)), np.array(img), exact[:, 1], ms


def sky_ringing_case(elevation: float = 3.0, rays: int = 4096, device=None) -> Case:
    """SH ringing under a bright low sun: no window vs the "nonneg" window (non-negative by
    construction). Images: irradiance over 128 normals (columns) at each probe (rows)."""
    a = sky_ringing(elevation, "none", rays, device)
    b = sky_ringing(elevation, "nonneg", rays, device)
    ex = np.tile(a[3][None], (a[2].shape[0], 1))
    return Case(f"sky volume SH ringing (sun {elevation} deg)", "sky volume",
                "max abs(E - E_exact) / max E_exact over probes and normals", 'SH window "nonneg"', a[0], b[0],
                a[4], b[4], exact=0.0,
                images={"exact": ex, "without": a[2], "with": b[2], "error": np.abs(b[2] - ex) / ex.max()},
                extra={"min_unclamped_over_peak_none": a[1], "min_unclamped_over_peak_nonneg": b[1]})


def terrain_sky_points(scene, count: int, seed: int = 0, height: float = 0.05):
    """``count`` random surface points of ``scene`` (area-weighted, away from the border) lifted
    ``height`` m along their face normals, and the face normals (facing up)."""
    pos, _, _, faces, _ = scene.merged()
    p = pos.astype(np.float64)
    a, b, c = p[faces[:, 0]], p[faces[:, 1]], p[faces[:, 2]]
    cr = np.cross(b - a, c - a)
    area = np.linalg.norm(cr, axis=1)
    nrm = cr / area[:, None]
    nrm *= np.sign(nrm[:, 1:2])
    cen = (a + b + c) / 3
    lo, hi = scene.bounds
    inner = np.all(np.abs(cen[:, [0, 2]] - (lo + hi)[[0, 2]] / 2) < 0.7 * (hi - lo)[[0, 2]] / 2, axis=1)
    w = area * inner
    rng = np.random.default_rng(seed)
    f = rng.choice(len(faces), count, p=w / w.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    pts = a[f] + u[:, None] * (b[f] - a[f]) + v[:, None] * (c[f] - a[f])
    return pts + height * nrm[f], nrm[f]


def terrain_sky_visibility(scene="terrain", count: int = 48, rays: int = 256, n_dirs: int = 4096, device=None):
    """Occlusion quads that fit a height field badly: sky irradiance at ``count`` terrain points
    (on the surface, facing out) from the sky volume (default cell) with no quads, the scene's
    hand-placed quads and the automatic fit (``quadfit``), against the brute-force cosine integral
    with the terrain's exact visibility (its kd-tree; occluded rays black, as the volume treats
    quads). Returns {config: (mean relative error (green), E (count,), ms of the build)}, the
    exact E, the points and the build ms."""
    base = load(scene) if isinstance(scene, str) else scene
    pts, nrm = terrain_sky_points(base, count)
    pos, _, _, faces, _ = base.merged()
    tree = KdTree.build(pos, faces)
    d = fibonacci_sphere(n_dirs).astype(np.float32)
    out, exact, sky_map, ground = {}, None, None, None
    for label, quads, auto in (("no quads", [], False), ("hand-placed quads", base.occlusion_quads, False),
                               ("automatic fit", [], True)):
        s = load(base.name) if isinstance(scene, str) else base
        s.occlusion_quads = list(quads)
        cfg = SkyConfig(rays_per_probe=rays, auto_quads=auto)
        t0 = time.perf_counter()
        vol = SkyVolume(s, cfg, device=device)
        vol.rebuild()
        ms = (time.perf_counter() - t0) * 1e3
        if exact is None:
            sky_map, ground = vol.sky_map(), vol.ground_radiance
            exact = np.empty((count, 3))
            for i, (p, n) in enumerate(zip(pts, nrm, strict=True)):
                o = np.broadcast_to((p + 1e-3 * n).astype(np.float32), d.shape)
                vis = ~tree.occluded(o, d, device=device)
                exact[i] = brute_sky_irradiance(sky_map, ground, n[None], vis, n_dirs)[0]
        e = vol.irradiance(pts, nrm)
        out[label] = (float(np.mean(np.abs(e[:, 1] - exact[:, 1]) / exact[:, 1])), e[:, 1], ms)
    return out, exact[:, 1], pts


def terrain_sky_case(count: int = 48, rays: int = 256, device=None) -> Case:
    """Occlusion quads on a height field: sky irradiance error at terrain points, no quads vs the
    automatic quad fit (the hand-placed quads are in ``extra``). Images: E at the points, sorted by
    the exact value (a 1-row strip)."""
    out, exact, _ = terrain_sky_visibility(count=count, rays=rays, device=device)
    order = np.argsort(exact)
    a, b = out["no quads"], out["automatic fit"]
    err_img = np.abs(b[1] - exact)[order][None] / exact.max()
    return Case("sky volume on terrain (quads fit badly)", "sky volume",
                "mean abs(E - E_exact) / E_exact at terrain points", "automatic quad fit", a[0], b[0], a[2], b[2],
                exact=None, images={"exact": exact[order][None], "without": a[1][order][None],
                                    "with": b[1][order][None], "error": err_img},
                extra={"hand_placed_quads_error": out["hand-placed quads"][0], "points": count})

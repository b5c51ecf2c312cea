"""Stability cases: where each technique fails, measured against an exact answer or a reference.

Each ``*_case`` function sets up one known failure of one technique, renders or evaluates it with
the technique's mitigation off and on, and returns a :class:`Case`: the error of both against the
exact answer (the metric is named in ``metric``), the milliseconds each took, and small images for
the gallery (exact, without, with, and the error map). ``tests/stability/`` calls them at tiny
sizes and asserts bounds; ``benchmarks/bench_stability.py`` calls them at gallery sizes and writes
the PNG grid + JSON that docs/stability.md shows.

Units: irradiance W·m⁻², radiance W·m⁻²·sr⁻¹, lengths m, angles degrees; images (H, W) float.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from serenity.bench import camera_path
from serenity.colour import luminance, reinhard
from serenity.config import LPVConfig, RenderConfig, ShadowConfig, SkyConfig, SSAOConfig
from serenity.eval.exact import exact_sun_visibility
from serenity.frame import Renderer
from serenity.kernels import sh
from serenity.kernels.atmosphere import bake_sky_map, horizontal_irradiance, sample_sky_map_np, scene_sun_irradiance
from serenity.kernels.kdtree import KdTree
from serenity.kernels.lpv import LightPropagationVolume
from serenity.kernels.raytrace import RayTracer
from serenity.kernels.sampling import fibonacci_sphere
from serenity.kernels.skyvolume import SkyVolume
from serenity.raster.interop import read_texture
from serenity.raster.shadow import fit_shadow_cascades
from serenity.scene import load
from serenity.scene.model import Camera, Sky, Sun, direction_from_angles
from serenity.scene.procedural import SceneBuilder, plane_scene


def format_error(x) -> str:
    """A stability case's error as its tables print it: "-" for none, 3 significant digits, or
    scientific notation below 1e-3 and from 1e3."""
    if x is None:
        return "-"
    x = float(x)
    if x == 0:
        return "0"
    return f"{x:.2e}" if abs(x) < 1e-3 or abs(x) >= 1e3 else f"{x:.3g}"


UP = np.array([0.0, 1.0, 0.0])


@dataclass
class Case:
    """One failure case: ``error_without`` / ``error_with`` its mitigation, against the exact answer.

    ``metric`` says what the error is; ``exact`` the exact answer's value where it is one number;
    ``ms_without`` / ``ms_with`` the cost of the evaluated technique without / with the mitigation
    (wall clock, one run after a warm-up where stated); ``images`` name → (H, W) or (H, W, 3) float
    arrays for the gallery (``exact``, ``without``, ``with``, ``error``); ``extra`` further numbers."""
    name: str
    technique: str
    metric: str
    mitigation: str
    error_without: float
    error_with: float
    ms_without: float = 0.0
    ms_with: float = 0.0
    exact: float | None = None
    images: dict[str, np.ndarray] = field(default_factory=dict)
    extra: dict = field(default_factory=dict)

    def row(self) -> dict:
        """The JSON row (no images)."""
        return {"case": self.name, "technique": self.technique, "metric": self.metric,
                "mitigation": self.mitigation, "exact": self.exact, "error_without": self.error_without,
                "error_with": self.error_with, "ms_without": self.ms_without, "ms_with": self.ms_with,
                **({"extra": self.extra} if self.extra else {})}


def _timed(fn, *args, **kw):
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    return out, (time.perf_counter() - t0) * 1e3


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
        (d0, l0), ms0 = _timed(gather_thin_wall, f, False, device)
        (d1, l1), ms1 = _timed(gather_thin_wall, f, True, device)
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
# light propagation volumes
# ----------------------------------------------------------------------------------------------


def _unit_lpv(res: int, cell: float, iterations: int, device=None, **kw):
    """One cascade of ``res``³ cells of ``cell`` m with its origin at (−cell, −cell, −cell) (the cell
    size as given: no scene-fitted coarsening)."""
    kw.setdefault("cross_scene", False)
    kw.setdefault("scene_cells", 0.0)
    cfg = LPVConfig(resolution=res, cascades=1, iterations=iterations, early_stop=0.0, **kw)
    v = LightPropagationVolume(cfg, device=device)
    bounds = np.array([[0.0] * 3, [(res - 2) * cell] * 3])
    v.fit((bounds.mean(axis=0), np.array([0.0, 0.0, 1.0])), bounds)
    v.clear()
    return v


def lpv_thin_wall(frac: float, geometry_volume: bool, leak_guard: bool, device=None,
                  **lpv) -> tuple[float, float]:
    """A 5 cm wall (a twentieth of a 1 m cell) at x = 6 + ``frac`` lit on its −x face (VPLs of
    100 W/m² exitance on the lit face, a lit floor in front), surfels on both faces. Returns
    (E on the dark face, E on the lit face), W/m², each facing out of the wall. Exact dark face: 0
    (nothing lies on its side). ``lpv``: other LPVConfig fields."""
    v = _unit_lpv(16, 1.0, 8, device, geometry_volume=geometry_volume, leak_guard=leak_guard, **lpv)
    x0 = 6.0 + frac
    ys, zs = np.meshgrid(np.arange(2.0, 12.0, 0.25) + 0.125, np.arange(2.0, 12.0, 0.25) + 0.125)
    m = ys.size
    lit = np.stack([np.full(m, x0 - 0.025), ys.ravel(), zs.ravel()], 1)
    dark = np.stack([np.full(m, x0 + 0.025), ys.ravel(), zs.ravel()], 1)
    west, east = np.tile([-1.0, 0, 0], (m, 1)), np.tile([1.0, 0, 0], (m, 1))
    v.inject(lit, west, np.full((m, 3), 0.0625 * 100.0))
    v.inject_geometry(np.concatenate([lit, dark]), np.concatenate([west, east]), np.full(2 * m, 0.0625))
    xs, zs2 = np.meshgrid(np.arange(0.0, x0 - 0.1, 0.25) + 0.125, np.arange(2.0, 12.0, 0.25) + 0.125)
    floor = np.stack([xs.ravel(), np.full(xs.size, 2.0), zs2.ravel()], 1)
    v.inject(floor, np.tile(UP, (xs.size, 1)), np.full((xs.size, 3), 0.0625 * 30.0))
    v.propagate()
    q = np.array([[x0 + 0.025, 5.0, 7.0], [x0 - 0.025, 5.0, 7.0]])
    e = v.irradiance(q, np.array([[1.0, 0, 0], [-1.0, 0, 0]]))[:, 0]
    return float(e[0]), float(e[1])


def lpv_thin_wall_case(fracs=(0.1, 0.3, 0.5, 0.7, 0.9), device=None) -> Case:
    """Light leaking through a wall thinner than a cell, for wall positions across a cell: worst
    E_dark/E_lit (exact 0) of the plain volume (no geometry volume, leak guard or self-illumination
    damping) vs the default mitigations (geometry volume + leak guard + damping). Image:
    E_dark/E_lit per wall position (columns), plain (top) vs mitigated (bottom)."""
    plain, both, t_plain, t_both = [], [], 0.0, 0.0
    lpv_thin_wall(fracs[0], False, False, device, self_damping=0.0)  # compile both variants outside the timing
    lpv_thin_wall(fracs[0], True, True, device)
    for f in fracs:
        (d0, l0), ms0 = _timed(lpv_thin_wall, f, False, False, device, self_damping=0.0)
        (d1, l1), ms1 = _timed(lpv_thin_wall, f, True, True, device)
        plain.append(d0 / l0)
        both.append(d1 / l1)
        t_plain += ms0
        t_both += ms1
    img = np.array([plain, both])
    return Case("LPV thin wall (5 cm, 1 m cells)", "lpv", "max E_dark/E_lit over wall positions in a cell",
                "geometry volume + leak guard + damping", max(plain), max(both), t_plain / len(fracs),
                t_both / len(fracs),
                exact=0.0, images={"exact": np.zeros_like(img), "without": img[:1], "with": img[1:],
                                   "error": img},
                extra={"wall_position_in_cell": list(fracs), "ratio_plain": plain, "ratio_mitigated": both})


def lpv_self_illumination(y0: float, leak_guard: bool = True, device=None, surfels: bool = False,
                          **lpv) -> float:
    """A plane of exitance M = 50 W/m² at height ``y0`` (1 m cells, 8 iterations); returns the
    irradiance it receives from its own VPLs over M. Exact: 0 (a plane cannot see itself).
    ``surfels``: the plane's surfels go into the geometry volume too; ``lpv``: other LPVConfig fields."""
    v = _unit_lpv(16, 1.0, 8, device, leak_guard=leak_guard, **lpv)
    xs, zs = np.meshgrid(np.arange(0, 14, 0.25) + 0.125, np.arange(0, 14, 0.25) + 0.125)
    p = np.stack([xs.ravel(), np.full(xs.size, y0), zs.ravel()], 1)
    nrm = np.tile(UP, (xs.size, 1))
    v.inject(p, nrm, np.full((xs.size, 3), 0.0625 * 50.0))
    if surfels:
        v.inject_geometry(p, nrm, np.full(xs.size, 0.0625))
    v.propagate()
    return float(v.irradiance(np.array([[7.0, y0, 7.0]]), UP[None])[0, 0]) / 50.0


def lpv_self_illumination_case(heights=(3.01, 3.3, 3.6, 3.9), device=None) -> Case:
    """The LPV's known bias: a lit plane lights itself through its VPLs' wide L1 lobes. Worst E/M
    over plane heights within a cell, with its surfels in the geometry volume as in a frame, without
    and with the self-illumination damping (``LPVConfig.self_damping``, on by default)."""
    lpv_self_illumination(heights[0], True, device, surfels=True, self_damping=0.0)  # compile outside the timing
    lpv_self_illumination(heights[0], True, device, surfels=True)
    off, t_off = zip(*[_timed(lpv_self_illumination, y, True, device, surfels=True, self_damping=0.0)
                       for y in heights], strict=True)
    on, t_on = zip(*[_timed(lpv_self_illumination, y, True, device, surfels=True) for y in heights], strict=True)
    img = np.array([off, on])
    return Case("LPV self-illumination of a lit plane", "lpv", "max E_self/M over plane heights in a cell",
                "self-illumination damping (2.5 cells)", max(off), max(on), float(np.mean(t_off)),
                float(np.mean(t_on)), exact=0.0,
                images={"exact": np.zeros_like(img), "without": img[:1], "with": img[1:], "error": img},
                extra={"plane_height_m": list(heights), "ratio_undamped": list(off), "ratio_damped": list(on)})


NEAR_FIELD_HALF = 4.0
"""Half-width (m) of the floor square over which the near-field error is integrated."""


def near_field_exact(x, z, h, phi):
    """Irradiance (W/m²) on the floor at (x, z) from a downward-facing Lambertian point emitter of
    flux ``phi`` W at height ``h`` above the origin: E = Φ·h²/(π·(r² + h²)²)."""
    r2 = x * x + z * z + h * h
    return phi * h * h / (math.pi * r2 * r2)


def lpv_near_field(h: float, cell: float = 1.0, step: float = 0.05, device=None):
    """A bright small light (one VPL, Φ = 100 W, facing down) ``h`` m above a floor (surfels
    included), in a single cascade of ``cell``-metre cells (16 m across, 16 iterations: the whole
    floor square is in reach). Returns (relative L1 error ∫|E − E_exact| dA / ∫E_exact dA over
    the floor square of half-width NEAR_FIELD_HALF, the LPV's captured flux over the exact one,
    E map, exact map, ms of inject + propagate). The exact map averages 4×4 sub-samples per sample
    square (its peak, Φ/(π h²), is narrower than a sample at small h)."""
    res = int(round(16.0 / cell))
    v = _unit_lpv(res, cell, 16, device)
    c = np.array([7.0, 3.0, 7.0])
    phi = 100.0
    t0 = time.perf_counter()
    v.inject((c + [0.0, h, 0.0])[None], -UP[None], np.array([[phi] * 3]))
    gx, gz = np.meshgrid(np.arange(0, 14, 0.25) + 0.125, np.arange(0, 14, 0.25) + 0.125)
    v.inject_geometry(np.stack([gx.ravel(), np.full(gx.size, c[1]), gz.ravel()], 1), np.tile(UP, (gx.size, 1)),
                      np.full(gx.size, 0.0625))
    v.propagate()
    ms = (time.perf_counter() - t0) * 1e3
    s = np.arange(-NEAR_FIELD_HALF, NEAR_FIELD_HALF, step) + step / 2
    x, z = np.meshgrid(s, s)
    pts = np.stack([x.ravel() + c[0], np.full(x.size, c[1]), z.ravel() + c[2]], 1)
    e = v.irradiance(pts, np.tile(UP, (len(pts), 1)))[:, 0].reshape(x.shape).astype(np.float64)
    sub = (np.arange(4) + 0.5) / 4 * step - step / 2
    ex = np.mean([near_field_exact(x + a, z + b, h, phi) for a in sub for b in sub], axis=0)
    l1 = float(np.abs(e - ex).sum() / ex.sum())
    return l1, float(e.sum() / ex.sum()), e, ex, ms


def lpv_near_field_case(h: float = 0.25, step: float = 0.05, device=None) -> Case:
    """Near-field over-lighting: a small light ``h`` m above a floor; 1 m cells (the default
    cascade's scale) vs 0.5 m cells (the mitigation: a finer cascade, 8× the cells)."""
    lpv_near_field(h, 1.0, step, device)  # compile outside the timing
    lpv_near_field(h, 0.5, step, device)
    a = lpv_near_field(h, 1.0, step, device)
    b = lpv_near_field(h, 0.5, step, device)
    return Case(f"LPV near field (light {h} m above a floor)", "lpv",
                "relative L1 error of floor irradiance", "finer cells (0.5 m instead of 1 m)", a[0], b[0], a[4], b[4],
                exact=0.0, images={"exact": a[3], "without": a[2], "with": b[2], "error": np.abs(b[2] - b[3])},
                extra={"height_m": h, "flux_ratio_1m": a[1], "flux_ratio_half_m": b[1]})


# ----------------------------------------------------------------------------------------------
# sky irradiance volume
# ----------------------------------------------------------------------------------------------


def _brute_sky_irradiance(sky_map, ground_radiance, normals, visible=None, n_dirs: int = 16384):
    """(N, 3) W/m²: ∫ L(ω)·V(ω)·max(0, n·ω) dω over a Fibonacci sphere of ``n_dirs`` directions, L
    the sky map above the horizon and ``ground_radiance`` below (the sky volume's model), V the
    (n_dirs,) bool visibility (None: all visible)."""
    d = fibonacci_sphere(n_dirs)
    rad = np.where((d[:, 1] >= 0)[:, None], sample_sky_map_np(sky_map, d), np.asarray(ground_radiance)[None])
    if visible is not None:
        rad = rad * visible[:, None]
    return np.maximum(np.asarray(normals) @ d.T, 0.0) @ rad * (4 * math.pi / len(d))


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
    exact = _brute_sky_irradiance(vol.sky_map(), vol.ground_radiance, n)
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
                exact[i] = _brute_sky_irradiance(sky_map, ground, n[None], vis, n_dirs)[0]
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


# ----------------------------------------------------------------------------------------------
# sun shadows (cascaded shadow maps + PCSS)
# ----------------------------------------------------------------------------------------------


def shadow_scene(elevation: float, azimuth: float = 90.0, wall: bool = False, box: bool = False,
                 raised: bool = False):
    """A 40 × 40 m grey plane (albedo 0.5) under a sun of 1000 W/m² (black sky), optionally a 2 m
    high, 0.2 m thick wall along z at x ∈ [−0.1, 0.1], z ∈ [−19, 15] and a 2 m cube at the origin
    (x, z ∈ [−1, 1]). The camera looks down −z from (−3, 1.7, 18). ``raised``: a 1 m square 1 m
    under the plane's centre, hidden by it, so the plane is not the scene's bottom plane, which the
    shadow maps leave out (``raster/scene_gl.bottom_plane_triangles``), but a caster like any other."""
    b = SceneBuilder()
    b.material("plane", albedo=(0.5, 0.5, 0.5))
    b.material("block", albedo=(0.5, 0.5, 0.5))
    b.rect("plane", (0.0, 0.0, 0.0), (20.0, 0.0, 0.0), (0.0, 0.0, -20.0))
    if raised:
        b.rect("block", (0.0, -1.0, 0.0), (0.5, 0.0, 0.0), (0.0, 0.0, -0.5))
    if wall:
        b.box("block", (-0.1, 0.0, -19.0), (0.1, 2.0, 15.0), skip=("-y",))
    if box:
        b.box("block", (-1.0, 0.0, -1.0), (1.0, 2.0, 1.0), skip=("-y",))
    cam = Camera(position=(-3.0, 1.7, 18.0), target=(-3.0, 0.3, 0.0), fov_y_deg=50.0, near=0.1, far=100.0)
    sun = Sun(direction_from_angles(elevation, azimuth), irradiance=(1000.0,) * 3)
    return b.scene("shadow-test", cam, sun, Sky(radiance=(0.0, 0.0, 0.0), model="constant"))


def render_sun_visibility(scene, width: int, height: int, shadow, sky: bool = False):
    """Render ``scene`` (direct light only: no LPV, SSAO, sky lighting) and return (visibility
    (H, W) = direct / unshadowed direct on the ground (NaN elsewhere), positions (H, W, 3), the
    ground mask, ms of the frame)."""
    cfg = RenderConfig(lpv=LPVConfig(enabled=False), sky=SkyConfig(enabled=sky), ssao=SSAOConfig(enabled=False),
                       shadow=shadow)
    r = Renderer(scene, width, height, config=cfg)
    r.render()
    t0 = time.perf_counter()
    f = r.render()
    ms = (time.perf_counter() - t0) * 1e3
    r.close()
    pos, nrm = f.aovs["position"], f.aovs["normal"]
    ground = np.isfinite(f.aovs["depth"][..., 0]) & (nrm[..., 1] > 0.99) & (pos[..., 1] < 1e-3)
    unshadowed = 0.5 / math.pi * 1000.0 * max(float(scene.sun.direction[1]), 0.0)
    vis = np.where(ground, f.aovs["direct"][..., 1] / unshadowed, np.nan)
    return vis, pos, ground, ms


def exact_ground_visibility(scene, points, n: int = 256):
    """Exact sun-disc visibility (P,) at ground points (normal +y), traced with the scene's kd-tree."""
    pos, _, _, faces, _ = scene.merged()
    tree = KdTree.build(pos, faces, cache=False)
    return exact_sun_visibility(tree, np.asarray(points, np.float64), np.tile(UP, (len(points), 1)),
                                scene.sun.direction, scene.sun.angular_diameter_deg, n=n)


def shadow_acne_case(elevation: float = 2.0, size=(160, 90)) -> Case:
    """Shadow acne on an open plane under a grazing sun (exact visibility 1 everywhere): fraction of
    ground pixels darker than 0.99 of the unshadowed light, without the constant depth bias (and
    normal offset) vs the defaults; both compare the map with the receiver's plane. Images:
    visibility. The plane is raised over a hidden square (``shadow_scene``):
    as the scene's bottom plane it would be left out of the shadow maps and could not acne at all,
    while any surface above it can (a roof, a terrace, a table)."""
    scene = shadow_scene(elevation, raised=True)
    a = render_sun_visibility(scene, *size, ShadowConfig(bias=0.0, normal_offset=0.0))
    b = render_sun_visibility(scene, *size, ShadowConfig())
    err = [float(np.mean(v[g] < 0.99)) for v, _, g, _ in (a, b)]
    ex = np.where(a[2], 1.0, np.nan)
    return Case(f"shadow acne (sun {elevation} deg, open plane)", "shadows", "fraction of lit ground shadowed",
                "constant depth bias on the receiver's plane", err[0], err[1], a[3], b[3], exact=0.0,
                images={"exact": ex, "without": a[0], "with": b[0], "error": np.abs(b[0] - ex)})


def peter_panning(elevation: float, shadow, size=(160, 90), band: float = 0.25):
    """A 2 m cube on the plane, sun ``elevation``° from the east, the camera looking at the cube's
    shadow side from above: (fraction of ground pixels within ``band`` m of the cube's base on its
    shadow side, in the exact umbra, that come out more than half lit; visibility image; exact
    image; ms)."""
    scene = shadow_scene(elevation, azimuth=90.0, box=True)
    scene.camera = Camera(position=(-3.5, 3.0, 3.0), target=(-1.3, 0.0, 0.0), fov_y_deg=50.0, near=0.05, far=100.0)
    vis, pos, ground, ms = render_sun_visibility(scene, *size, shadow)
    near = ground & (pos[..., 0] < -1.0) & (pos[..., 0] > -1.0 - band) & (np.abs(pos[..., 2]) < 0.8)
    ex_img = np.full(vis.shape, np.nan)
    ex = exact_ground_visibility(scene, pos[near], n=64)
    ex_img[near] = ex
    umbra = ex < 0.01
    return float(np.mean(vis[near][umbra] > 0.5)), vis, ex_img, ms


def peter_panning_case(elevation: float = 10.0, size=(160, 90)) -> Case:
    """Peter-panning: the bias that cures acne detaches shadows from their casters. Fraction of the
    exact umbra within 25 cm of a cube's base rendered more than half lit: no bias vs default bias."""
    a = peter_panning(elevation, ShadowConfig(bias=0.0, normal_offset=0.0), size)
    b = peter_panning(elevation, ShadowConfig(), size)
    return Case(f"peter-panning (sun {elevation} deg, cube contact)", "shadows",
                "fraction of contact umbra rendered lit", "constant depth bias (its cause)", a[0], b[0],
                a[3], b[3], exact=0.0,
                images={"exact": b[2], "without": a[1], "with": b[1], "error": np.abs(b[1] - b[2])})


def contact_leak(shadow, size=(320, 180), band: float = 0.15):
    """The Cornell box's leak in the open: a one-sided 3 m wall (a single quad at x = 0, facing −x)
    on the plane, the sun (70° up, azimuth 170°: 3.4° off the wall's plane) behind it, so the wall
    shadows a 19 cm strip at its foot on the camera's side while nothing is drawn beyond it. The
    shadow maps see the wall almost edge-on; a PCSS/PCF footprint at its foot reaches the texels past
    its edge, which are open. Returns (fraction of ground pixels within ``band`` m of the wall, in
    the exact umbra, that come out more than 5 % lit; visibility image; exact image; ms). A leak
    touches only the pixels whose sample falls within a texel of the foot (the Cornell box's
    worst pixel is one, 0.08 mm inside the wall), so the fraction is small but each is a bright
    pixel on a black one.)"""
    b = SceneBuilder()
    b.material("plane", albedo=(0.5, 0.5, 0.5))
    b.material("block", albedo=(0.5, 0.5, 0.5))
    b.rect("plane", (0.0, 0.0, 0.0), (20.0, 0.0, 0.0), (0.0, 0.0, -20.0))
    b.rect("block", (0.0, 1.5, 0.0), (0.0, 0.0, 10.0), (0.0, 1.5, 0.0))
    cam = Camera(position=(-3.0, 1.5, 5.0), target=(0.0, 0.0, 0.0), fov_y_deg=50.0, near=0.05, far=100.0)
    sun = Sun(direction_from_angles(70.0, 170.0), irradiance=(1000.0,) * 3)
    scene = b.scene("contact-test", cam, sun, Sky(radiance=(0.0, 0.0, 0.0), model="constant"))
    vis, pos, ground, ms = render_sun_visibility(scene, *size, shadow)
    near = ground & (pos[..., 0] < 0.0) & (pos[..., 0] > -band) & (np.abs(pos[..., 2]) < 5.0)
    ex_img = np.full(vis.shape, np.nan)
    ex = exact_ground_visibility(scene, pos[near], n=64)
    ex_img[near] = ex
    umbra = ex < 0.01
    return float(np.mean(vis[near][umbra] > 0.05)), vis, ex_img, ms


def contact_leak_case(size=(320, 180)) -> Case:
    """Contact leak: a floor at the foot of a wall nearly parallel to the sun, lit through the
    shadow map's texel edge (``contact_leak``): without vs with the screen-space contact shadow
    (``ShadowConfig.contact_steps``)."""
    a = contact_leak(ShadowConfig(contact_steps=0), size)
    b = contact_leak(ShadowConfig(), size)
    return Case("contact leak (wall 3.4 deg off the sun, open behind)", "shadows",
                "fraction of contact umbra rendered lit", "screen-space contact shadow", a[0], b[0], a[3], b[3],
                exact=0.0, images={"exact": b[2], "without": a[1], "with": b[1], "error": np.abs(b[1] - b[2])})


def cascade_seams(shadow, size=(320, 180), elevation: float = 30.0):
    """A long 2 m wall along the view direction, sun from the east at ``elevation``°: its shadow's
    edge (x = −2/tan(elevation) − 0.1) runs through every cascade split. Returns (max over splits of
    |mean visibility in the 0.5 m of depth past the split − before it| along the edge band, minus
    the exact's; mean |vis − exact| near the edge; visibility image; exact image; ms)."""
    scene = shadow_scene(elevation, azimuth=90.0, wall=True)
    vis, pos, ground, ms = render_sun_visibility(scene, *size, shadow)
    x_edge = -0.1 - 2.0 / math.tan(math.radians(elevation))
    near = ground & (np.abs(pos[..., 0] - x_edge) < 0.4) & (pos[..., 2] > -18) & (pos[..., 2] < 14)
    ex_img = np.full(vis.shape, np.nan)
    ex = exact_ground_visibility(scene, pos[near], n=64)
    ex_img[near] = ex
    cam = scene.camera
    depth = (pos[near] - cam.position) @ cam.forward
    cascades = fit_shadow_cascades(cam, size[0] / size[1], scene.sun.direction, scene.bounds, shadow.cascades,
                                   shadow.size_for(*size), shadow.split_lambda, shadow.max_distance)
    jumps = []
    v = vis[near]
    for c in cascades[:-1]:
        d = c.far
        lo, hi = (depth > d - 0.5) & (depth < d), (depth >= d) & (depth < d + 0.5)
        if lo.sum() < 4 or hi.sum() < 4:
            continue
        jumps.append(abs(v[hi].mean() - v[lo].mean()) - abs(ex[hi].mean() - ex[lo].mean()))
    return max(jumps) if jumps else 0.0, float(np.mean(np.abs(v - ex))), vis, ex_img, ms, len(jumps)


def cascade_seam_case(size=(320, 180)) -> Case:
    """Cascade seams: the step in the shadow term across each CSM split along a shadow edge that
    runs through all of them, without the cross-fade band (cascade_blend 0) vs the default 0.1."""
    a = cascade_seams(ShadowConfig(cascade_blend=0.0), size)
    b = cascade_seams(ShadowConfig(), size)
    return Case("CSM cascade seams (shadow edge across splits)", "shadows",
                "max step of mean visibility across a split, beyond the exact step", "cascade cross-fade band",
                a[0], b[0], a[4], b[4], exact=0.0,
                images={"exact": b[3], "without": a[2], "with": b[2], "error": np.abs(b[2] - b[3])},
                extra={"mean_abs_error_near_edge_without": a[1], "mean_abs_error_near_edge_with": b[1],
                       "splits_measured": b[5]})


def penumbra(elevation: float, shadow, size=(256, 256)):
    """The shadow of a 2 m cube's top edge under the 0.53° sun at ``elevation``° from the east, seen
    from straight above: (mean |vis − exact| over ground pixels within max(0.3 m, 1.5 exact
    penumbra widths) of the edge, rendered
    10–90 % width / exact width, visibility image, exact image, ms)."""
    scene = shadow_scene(elevation, azimuth=90.0, box=True)
    x_edge = -1.0 - 2.0 / math.tan(math.radians(elevation))
    width_exact = 2.0 * math.radians(scene.sun.angular_diameter_deg) / math.sin(math.radians(elevation)) ** 2
    band = max(0.3, 1.5 * width_exact)
    scene.camera = Camera(position=(x_edge, 1.3 * band / 0.3, 0.0), target=(x_edge, 0.0, 0.0), up=(0.0, 0.0, -1.0),
                          fov_y_deg=30.0, near=0.05, far=60.0)
    vis, pos, ground, ms = render_sun_visibility(scene, *size, shadow)
    near = ground & (np.abs(pos[..., 0] - x_edge) < band) & (np.abs(pos[..., 2]) < 0.1 * band / 0.3)
    ex = exact_ground_visibility(scene, pos[near], n=256)
    ex_img = np.full(vis.shape, np.nan)
    ex_img[near] = ex
    x, v = pos[near][:, 0], vis[near]

    def width(val):
        inside = (val > 0.1) & (val < 0.9)
        return float(np.ptp(x[inside])) if inside.sum() > 1 else 0.0

    return float(np.mean(np.abs(v - ex))), width(v) / max(width(ex), 1e-9), vis, ex_img, ms


def penumbra_case(elevation: float = 10.0, size=(256, 256)) -> Case:
    """PCSS penumbra vs the exact sun-disc visibility at a cube's shadow edge: hard shadows vs PCSS."""
    a = penumbra(elevation, ShadowConfig(filter="hard"), size)
    b = penumbra(elevation, ShadowConfig(filter="pcss"), size)
    return Case(f"penumbra width (sun {elevation} deg)", "shadows", "mean abs(vis - exact) across the penumbra",
                "PCSS (vs hard)", a[0], b[0], a[4], b[4], exact=0.0,
                images={"exact": b[3], "without": a[2], "with": b[2], "error": np.abs(b[2] - b[3])},
                extra={"width_ratio_hard": a[1], "width_ratio_pcss": b[1]})


# ----------------------------------------------------------------------------------------------
# ray tracing
# ----------------------------------------------------------------------------------------------

GLASS_SLAB = (np.array([-2.6, 0.0, -0.25]), np.array([-1.0, 1.2, 0.25]))
"""The ``glass`` scene's slab (m) and its index of refraction is the glass material's (1.5)."""


def _refract(d, n, eta):
    """Snell refraction of unit rows d at unit normals n facing against d, eta = n1/n2."""
    c = -np.sum(d * n, axis=1, keepdims=True)
    k = 1 - eta * eta * (1 - c * c)
    return eta * d + (eta * c - np.sqrt(np.maximum(k, 0))) * n


def glass_slab_rays(count: int = 64, seed: int = 0):
    """Rays from in front of the glass slab through its +z face, out of its −z face and onto the floor
    (exact path by Snell's law, checked to cross the two big faces and reach the floor before the
    boxes behind): (origins, directions, exact floor hits)."""
    rng = np.random.default_rng(seed)
    lo, hi = GLASS_SLAB
    ior = 1.5
    o, d, hit = [], [], []
    while len(o) < count:
        entry = np.array([rng.uniform(lo[0] + 0.3, hi[0] - 0.3), rng.uniform(0.5, 1.0), hi[2]])
        src = entry + np.array([rng.uniform(-0.8, 0.8), rng.uniform(0.3, 1.0), 1.5])
        di = (entry - src) / np.linalg.norm(entry - src)
        dt = _refract(di[None], np.array([[0.0, 0.0, 1.0]]), 1 / ior)[0]
        exit_ = entry + dt * ((lo[2] - hi[2]) / dt[2])
        if not (lo[0] < exit_[0] < hi[0] and lo[1] < exit_[1] < hi[1]):
            continue
        do = _refract(dt[None], np.array([[0.0, 0.0, 1.0]]), ior)[0]
        floor = exit_ + do * (-exit_[1] / do[1])
        if floor[2] < -1.85 or abs(floor[0]) > 9:
            continue
        o.append(src)
        d.append(di)
        hit.append(floor)
    return np.array(o), np.array(d), np.array(hit)


def glass_slab_case(count: int = 64, device=None) -> Case:
    """Refraction through the ``glass`` scene's slab (two interfaces): distance of the reported hit
    from the exact floor hit, the paper's single refraction (transmissions 0: the slab's own back
    face) vs bending through up to 4 interfaces. Images: hit distance errors per ray (1 row)."""
    tracer = RayTracer(load("glass"), device=device)
    o, d, exact = glass_slab_rays(count)
    out = {}
    for k in (0, 4):
        g, ms = _timed(tracer.trace, o, d, transmissions=k)
        g, ms = _timed(tracer.trace, o, d, transmissions=k)
        err = np.linalg.norm(g["position"][:, :3] - exact, axis=1)
        err = np.where(g["position"][:, 3] > 0, err, np.inf)
        out[k] = (err, ms)
    a, b = out[0], out[4]
    return Case("glass slab refraction (2 interfaces)", "ray tracing", "max distance of hit from exact floor hit (m)",
                "transmissions = 4 (vs the paper's 1)", float(a[0].max()), float(b[0].max()), a[1], b[1], exact=0.0,
                images={"exact": np.zeros((1, count)), "without": a[0][None], "with": b[0][None],
                        "error": b[0][None]})


def mirror_shadow_case(size=(160, 90), device=None, rt_sun_shadows: str = "traced") -> Case:
    """Off-screen geometry seen in the ``mirror-box`` mirror (behind the camera, outside the main view's
    shadow cascades): is it shadowed? For the reflection rays, the exact sun-disc visibility at their
    hits (the kd-tree) vs the answer the RT direct-lighting pass uses (its direct term over the
    unshadowed one): the tracer's shadow ray by default, ``rt_sun_shadows="osm"`` the overlapped
    shadow maps. Error: fraction of hits whose shadow state (exact
    visibility < 0.5) differs; "without" lights every hit as unshadowed."""
    scene = load("mirror-box")
    cfg = RenderConfig(lpv=LPVConfig(enabled=False), sky=SkyConfig(enabled=False), ssao=SSAOConfig(enabled=False),
                       overlap=False, rt_sun_shadows=rt_sun_shadows)
    r = Renderer(scene, *size, device=device, config=cfg)
    r.render()
    f, ms = _timed(r.render)
    w, h = size
    rcb = r.raycast_pass.read()
    sel = rcb.reflection_rays()
    g = r.tracer.trace(rcb.origins[sel], rcb.reflect_dirs[sel], rcb.cone_width[sel], rcb.cone_spread[sel])
    pix = rcb.pixels[sel]
    texel = np.arange(len(pix))  # packed RT G-buffer: the k-th reflection ray is texel k (rt_gbuffer doc)
    hit = g["position"][:, 3] > 0
    p, n = g["position"][hit, :3].astype(np.float64), g["normal"][hit, :3].astype(np.float64)
    alb = g["albedo"][hit, :3].astype(np.float64)
    sun = scene.sun.direction
    cos = n @ sun
    lit_side = cos > 0.2
    p, n, alb, cos = p[lit_side], n[lit_side], alb[lit_side], cos[lit_side]
    pix, texel = pix[hit][lit_side], texel[hit][lit_side]
    vis = exact_sun_visibility(r.tracer.tree, p, n, sun, scene.sun.angular_diameter_deg, n=64)
    direct = read_texture(r.rt_deferred.direct, 3)[::-1].reshape(-1, 3)  # GL row order: texel k = (k mod W, k div W)

    e = scene_sun_irradiance(scene)
    ours = direct[texel, 1] / np.maximum(alb[:, 1] / math.pi * e[1] * cos, 1e-9)
    r.close()
    shadowed = vis < 0.5
    err_with = float(np.mean((ours < 0.5) != shadowed))
    err_without = float(np.mean(shadowed))
    img = np.full(h * w, np.nan)
    ex_img = np.full(h * w, np.nan)
    img[pix] = np.clip(ours, 0, 1.5)
    ex_img[pix] = vis
    shadows = "overlapped shadow maps" if rt_sun_shadows == "osm" else "traced sun shadow rays"
    return Case("mirror: off-screen geometry in shadow", "ray tracing",
                "fraction of reflected hits with the wrong shadow state", f"{shadows} (vs unshadowed)",
                err_without, err_with, 0.0, f.timings.get("shadow maps (OSM)", 0.0), exact=0.0,
                images={"exact": ex_img.reshape(h, w), "without": np.where(np.isnan(img), np.nan, 1.0).reshape(h, w),
                        "with": img.reshape(h, w), "error": np.abs(img - ex_img).reshape(h, w)},
                extra={"reflected_hits": int(len(vis)), "exact_shadowed_fraction": err_without})


# ----------------------------------------------------------------------------------------------
# sky and sun near and below the horizon
# ----------------------------------------------------------------------------------------------


def horizon_scene(elevation: float):
    """A 4 × 3 m grey block (albedo 0.5) on a grey plane under the atmosphere, the sun ``elevation``°
    in the west (azimuth 270°); the camera looks at the block's sunlit west face."""
    b = SceneBuilder()
    b.material("ground", albedo=(0.5, 0.5, 0.5))
    b.material("block", albedo=(0.5, 0.5, 0.5))
    b.rect("ground", (0.0, 0.0, 0.0), (30.0, 0.0, 0.0), (0.0, 0.0, -30.0))
    b.box("block", (0.0, 0.0, -2.0), (3.0, 4.0, 2.0), skip=("-y",))
    cam = Camera(position=(-8.0, 2.0, 3.0), target=(0.0, 1.5, 0.0), fov_y_deg=50.0, near=0.1, far=200.0)
    return b.scene("horizon", cam, Sun(direction_from_angles(elevation, 270.0)), Sky())


def horizon_sweep(elevations, size=(48, 27), device=None, rebuild_angle_deg: float = 0.5,
                  probes: tuple[int, int, int] | None = None, rays: int = 256) -> dict:
    """Render ``horizon_scene`` at each elevation (one renderer, the sky volume rebuilt every step so the image is
    converged for that sun; no LPV/SSAO, no history of the indirect light) and compare the mean radiance (red)
    of the west wall's pixels with the exact ρ/π·(E_sun·max(0, n·s) + E_sky(n)) — E_sun the model's sun
    (:func:`~serenity.kernels.atmosphere.scene_sun_irradiance`), E_sky(n) the brute-force cosine integral of a
    sky map baked for this step's sun (the renderer's cached map is rebaked only when the sun moved more than
    ``rebuild_angle_deg``) and the volume's ground model. Returns per-step rows, whether every image was finite,
    the smallest radiance, and the largest step excess (|Δours| − |Δexact|) over the larger exact value of the
    two steps. ``probes`` / ``rays``: the sky volume's resolution (None: its default) and rays per probe."""
    scene = horizon_scene(float(elevations[0]))
    cfg = RenderConfig(lpv=LPVConfig(enabled=False), ssao=SSAOConfig(enabled=False), sky_layers_per_frame=1 << 10,
                       sky=SkyConfig(rebuild_angle_deg=rebuild_angle_deg, resolution=probes, rays_per_probe=rays),
                       indirect_history=1.0)  # each step converged: no light carried over from the last
    r = Renderer(scene, *size, device=device, config=cfg)
    n_wall = np.array([-1.0, 0.0, 0.0])
    rows, finite, lo, ours, exact, images = [], True, np.inf, [], [], []
    ms = []
    for el in elevations:
        scene.sun.direction = direction_from_angles(float(el), 270.0)
        t0 = time.perf_counter()
        f = r.render()
        ms.append((time.perf_counter() - t0) * 1e3)
        finite &= bool(np.all(np.isfinite(f.hdr)))
        lo = min(lo, float(f.hdr.min()))
        wall = np.isfinite(f.aovs["depth"][..., 0]) & (f.aovs["normal"][..., 0] < -0.99)
        sky = bake_sky_map(scene.sun.direction, size=64, device=device)  # this step's sky, not the cached one
        ground = r.sky_volume.config.ground_albedo / math.pi * horizontal_irradiance(sky)
        e_sky = _brute_sky_irradiance(sky, ground, n_wall[None], n_dirs=8192)[0]
        e_sun = scene_sun_irradiance(scene) * max(0.0, float(n_wall @ scene.sun.direction))
        ex = 0.5 / math.pi * (e_sun + e_sky)
        ours.append(float(f.hdr[wall][:, 0].mean()))
        exact.append(float(ex[0]))
        images.append(f.hdr[..., 0])
    r.close()
    ours, exact = np.array(ours), np.array(exact)
    big = np.maximum(exact[1:], exact[:-1])
    excess = (np.abs(np.diff(ours)) - np.abs(np.diff(exact))) / big
    for k, el in enumerate(elevations):
        rows.append({"elevation": float(el), "ours": float(ours[k]), "exact": float(exact[k]),
                     "step_excess": float(excess[k - 1]) if k else 0.0})
    return {"steps": rows, "finite": finite, "min_radiance": lo, "max_excess_step": float(excess.max()),
            "max_rel_error": float(np.max(np.abs(ours - exact) / np.maximum(exact, 1e-6))),
            "ms": float(np.median(ms[1:] or ms)), "images": images}


def nested_glass_error(count: int = 32, transmissions: int = 4, seed: int = 1, device=None):
    """A glass block (x ∈ [−1, 1], y ∈ [0, 2], z ∈ [−0.5, 0.5]) holding a smaller block of the same
    glass (x ∈ [−0.5, 0.5], y ∈ [0.5, 1.5], z ∈ [−0.25, 0.25]) in front of a wall at z = −3. Exact:
    the inner faces separate glass from the same glass, so rays bend only at the outer faces and
    leave parallel to where they came from. Returns the distances (m) of the traced wall hits from
    the exact ones (inf where the ray did not reach the wall)."""
    b = SceneBuilder()
    b.material("glass", albedo=(0.95,) * 3, transparency=0.95, ior=1.5)
    b.material("wall", albedo=(0.5,) * 3)
    b.box("glass", (-1.0, 0.0, -0.5), (1.0, 2.0, 0.5))
    b.box("glass", (-0.5, 0.5, -0.25), (0.5, 1.5, 0.25))
    b.rect("wall", (0.0, 1.0, -3.0), (6.0, 0.0, 0.0), (0.0, 4.0, 0.0))
    scene = b.scene("nested-glass", Camera((0.0, 1.0, 4.0), (0.0, 1.0, 0.0)), Sun((0.3, 1.0, 0.2)))
    tracer = RayTracer(scene, device=device, cache=False)
    rng = np.random.default_rng(seed)
    entry = np.stack([rng.uniform(-0.3, 0.3, count), rng.uniform(0.8, 1.2, count), np.full(count, 0.5)], 1)
    src = entry + np.stack([rng.uniform(-0.6, 0.6, count), rng.uniform(-0.3, 0.3, count), np.full(count, 2.0)], 1)
    d = (entry - src) / np.linalg.norm(entry - src, axis=1, keepdims=True)
    z = np.array([[0.0, 0.0, 1.0]])
    dt = _refract(d, np.repeat(z, count, 0), 1 / 1.5)
    exit_ = entry + dt * ((-0.5 - 0.5) / dt[:, 2:3])
    do = _refract(dt, np.repeat(z, count, 0), 1.5)
    exact = exit_ + do * ((-3.0 - exit_[:, 2:3]) / do[:, 2:3])
    g = tracer.trace(src, d, transmissions=transmissions)
    err = np.linalg.norm(g["position"][:, :3] - exact, axis=1)
    on_wall = (g["position"][:, 3] > 0) & (np.abs(g["position"][:, 2] + 3.0) < 1e-3)
    return np.where(on_wall, err, np.inf)


# ----------------------------------------------------------------------------------------------
# frame to frame
# ----------------------------------------------------------------------------------------------


def _luma(img):
    return img @ np.array([0.2126, 0.7152, 0.0722], np.float32)


def sun_motion_sequence(frames: int = 60, step_deg: float = 0.05, size=(64, 36), scene_name: str = "thin-wall",
                        rebuild_angle_deg: float = 0.5, start_elevation: float = 12.0, device=None,
                        probes: tuple[int, int, int] | None = None, rays: int = 256, gi: dict | None = None,
                        sky_map_size: int = 256) -> dict:
    """Camera still, the sun sinking ``step_deg`` per frame from ``start_elevation``: the renderer as a
    real-time app runs it (one sky layer per frame, the sky map rebaked every ``rebuild_angle_deg``)
    beside a converged one (every layer and the sky map redone each frame). Per frame k:
    change c_k = mean|I_k − I_{k−1}|/mean I (luminance), the converged change r_k likewise, and lag
    e_k = mean|I_k − R_k|/mean R_k. Returns the arrays, the largest step excess max(c_k − r_k)
    ("pop"), the largest lag, the mean ms per frame of both, the first/last images and the
    per-pixel error of the worst-lag frame. ``probes`` / ``rays``: the sky volume's resolution (None:
    its default), rays per probe and sky map size; ``gi``: further RenderConfig fields (e.g.
    ``lpv=LPVConfig(enabled=False)``)."""
    runs = {}
    for label, layers, angle in (("ours", 1, rebuild_angle_deg), ("converged", 1 << 10, 0.0)):
        scene = load(scene_name)
        az = float(scene.sun.azimuth_deg)
        cfg = RenderConfig(sky_layers_per_frame=layers, **(gi or {}),
                           sky=SkyConfig(rebuild_angle_deg=angle, resolution=probes, rays_per_probe=rays,
                                         sky_map_size=sky_map_size))
        if label == "converged":  # nothing carried over from the last frame either
            cfg = dataclasses.replace(cfg, indirect_history=1.0, lpv=dataclasses.replace(cfg.lpv, temporal_blend=1.0))
        r = Renderer(scene, *size, device=device, config=cfg)
        imgs, ms = [], []
        for k in range(frames + 1):
            scene.sun.direction = direction_from_angles(start_elevation - step_deg * k, az)
            t0 = time.perf_counter()
            f = r.render()
            if k:
                ms.append((time.perf_counter() - t0) * 1e3)
            imgs.append(_luma(f.hdr))
        r.close()
        runs[label] = (np.array(imgs), float(np.mean(ms)))
    ours, ref = runs["ours"][0], runs["converged"][0]
    mean = np.maximum(ref.mean(axis=(1, 2)), 1e-9)
    c = np.abs(np.diff(ours, axis=0)).mean(axis=(1, 2)) / mean[1:]
    rr = np.abs(np.diff(ref, axis=0)).mean(axis=(1, 2)) / mean[1:]
    lag = np.abs(ours - ref).mean(axis=(1, 2)) / mean
    worst = int(np.argmax(lag))
    return {"change": c, "reference_change": rr, "lag": lag, "pop": float(np.max(c - rr)),
            "max_lag": float(lag.max()), "ms": runs["ours"][1], "ms_converged": runs["converged"][1],
            "finite": bool(np.all(np.isfinite(ours))), "min": float(ours.min()),
            "images": {"exact": ref[worst], "ours": ours[worst], "error": np.abs(ours[worst] - ref[worst])}}


def sun_motion_case(frames: int = 60, size=(96, 54), device=None) -> Case:
    """Frame-to-frame with the sun moving 0.05°/frame: the largest per-frame change beyond the converged
    reference's own change, with the default sky-map cache (rebaked every 0.5°) vs rebaked every 0.1°.
    Images: the frame lagging most behind the converged render (of each run; the error map: 0.1°)."""
    a = sun_motion_sequence(frames, 0.05, size, rebuild_angle_deg=0.5, device=device)
    b = sun_motion_sequence(frames, 0.05, size, rebuild_angle_deg=0.1, device=device)
    return Case(f"sun moving 0.05 deg/frame, {frames} frames (thin-wall)", "frame to frame",
                "max per-frame change beyond the converged render's (of mean luminance)",
                "sky map rebaked every 0.1 deg (vs 0.5)", a["pop"], b["pop"], a["ms"], b["ms"], exact=0.0,
                images={"exact": a["images"]["exact"], "without": a["images"]["ours"], "with": b["images"]["ours"],
                        "error": b["images"]["error"]},
                extra={"max_lag_default": a["max_lag"], "max_lag_0.1deg": b["max_lag"],
                       "ms_converged_every_frame": a["ms_converged"]})


def camera_path_sequence(frames: int = 60, size=(96, 54), scene_name: str = "thin-wall", gi: bool | dict = True,
                         device=None, tolerance: float = 0.01) -> dict:
    """Sun still, the camera along ``serenity bench``'s path (orbit ±12°, dolly ±10 %). Every surface of
    the scene is diffuse, so the exact outgoing radiance of a world point does not change with the
    camera: for each pixel of frame k whose surface point reappears in frame k−1 (reprojected to the
    the previous frame's luminance interpolated bilinearly there, all 4 taps on the same surface: same
    normal, within ``tolerance`` m of its plane), the change |I_k − I_{k−1}| over the mean. ``gi=False``
    renders direct light only (no LPV, sky volume, SSAO) — the floor the nearest-pixel reprojection
    itself leaves; a dict gives RenderConfig fields (e.g. {"lpv": LPVConfig(enabled=False)}). Returns per-frame flicker,
    its max and mean, ms per frame, and the fewest points matched in a frame (``matched``). The
    interpolation itself errs across shadow edges, so points whose 4 taps differ by more than 5 % are
    left out; the direct-only run measures what error remains from the reprojection."""
    scene = load(scene_name)
    base = scene.camera
    if isinstance(gi, dict):
        cfg = RenderConfig(**gi)
    else:
        cfg = RenderConfig() if gi else RenderConfig(lpv=LPVConfig(enabled=False), sky=SkyConfig(enabled=False),
                                                     ssao=SSAOConfig(enabled=False))
    r = Renderer(scene, *size, device=device, config=cfg)
    w, h = size
    prev, flicker, ms, matched = None, [], [], []
    worst = (0.0, None)
    for k in range(frames + 1):
        scene.camera = camera_path(base, k / frames)
        t0 = time.perf_counter()
        f = r.render()
        if k:
            ms.append((time.perf_counter() - t0) * 1e3)
        lum, pos = _luma(f.hdr), f.aovs["position"]
        covered = np.isfinite(f.aovs["depth"][..., 0])
        cam = scene.camera
        vp = cam.projection_matrix(w / h) @ cam.view_matrix()
        if prev is not None:
            plum, ppos, pcov, pvp, pnrm = prev
            p, n = pos[covered], f.aovs["normal"][covered]
            c = np.concatenate([p, np.ones((len(p), 1))], 1) @ pvp.T
            ndc = c[:, :3] / c[:, 3:4]
            x = (ndc[:, 0] * 0.5 + 0.5) * w - 0.5
            y = (1 - (ndc[:, 1] * 0.5 + 0.5)) * h - 0.5
            x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
            ok = (x0 >= 0) & (x0 < w - 1) & (y0 >= 0) & (y0 < h - 1)
            x0, y0 = np.clip(x0, 0, w - 2), np.clip(y0, 0, h - 2)
            fx, fy = x - x0, y - y0
            val_prev = np.zeros(len(p))
            t_lo, t_hi = np.full(len(p), np.inf), np.full(len(p), -np.inf)
            for dy, dx, wt in ((0, 0, (1 - fx) * (1 - fy)), (0, 1, fx * (1 - fy)), (1, 0, (1 - fx) * fy),
                               (1, 1, fx * fy)):
                rr, cc = y0 + dy, x0 + dx
                # the same surface at all 4 taps: covered, same normal, within ``tolerance`` of its plane
                ok &= pcov[rr, cc] & (np.sum(pnrm[rr, cc] * n, axis=1) > 0.999)
                ok &= np.abs(np.sum((ppos[rr, cc] - p) * n, axis=1)) < tolerance
                val_prev += wt * plum[rr, cc]
                t_lo, t_hi = np.minimum(t_lo, plum[rr, cc]), np.maximum(t_hi, plum[rr, cc])
            ok &= t_hi - t_lo <= 0.05 * np.maximum(val_prev, 1e-9)  # smooth there: not across a shadow edge
            d = np.abs(lum[covered][ok] - val_prev[ok])
            val = float(d.mean() / max(lum[covered][ok].mean(), 1e-9)) if ok.any() else 0.0
            flicker.append(val)
            matched.append(int(ok.sum()))
            if val >= worst[0]:
                img = np.full((h, w), np.nan)
                sub = np.full(int(covered.sum()), np.nan)
                sub[ok] = d
                img[covered] = sub
                worst = (val, img)
        prev = (lum, pos, covered, vp, f.aovs["normal"])
    r.close()
    return {"flicker": np.array(flicker), "max": float(np.max(flicker)), "mean": float(np.mean(flicker)),
            "ms": float(np.mean(ms)), "worst_image": worst[1], "last": lum, "matched": int(np.min(matched))}


def camera_path_case(frames: int = 60, size=(96, 54), device=None) -> Case:
    """Frame-to-frame with the camera on the bench path (diffuse scene: exact change 0). No switch to
    compare: the column "without" is direct light only (the reprojection floor), "with" the full
    renderer (LPV, sky volume, SSAO)."""
    a = camera_path_sequence(frames, size, gi=False, device=device)
    b = camera_path_sequence(frames, size, gi=True, device=device)

    c = camera_path_sequence(frames, size, gi={"lpv": LPVConfig(enabled=False)}, device=device)
    return Case(f"camera on the bench path, {frames} frames (thin-wall)", "frame to frame",
                "max over frames of mean abs(change) of reprojected diffuse points (of mean luminance)",
                "none to switch: direct only (floor) vs full GI", a["max"], b["max"], a["ms"], b["ms"], exact=0.0,
                images={"exact": np.where(np.isnan(b["worst_image"]), np.nan, 0.0), "without": a["last"],
                        "with": b["last"], "error": b["worst_image"]},
                extra={"mean_direct_only": a["mean"], "mean_full": b["mean"], "fewest_points_matched": b["matched"],
                       "max_without_lpv": c["max"], "mean_without_lpv": c["mean"]})


def horizon_case(size=(48, 27), device=None) -> Case:
    """Sunset on a west-facing wall, sun from +1° to −1.5° in 0.25° steps: the largest step of the
    wall's mean radiance beyond the exact step (of the larger exact value), the default sky-map cache
    (rebaked past 0.5°) vs rebaked past 0.1°. Images: the wall's red radiance per step (a strip:
    exact, default, 0.1°)."""
    els = np.arange(1.0, -1.51, -0.25)
    a = horizon_sweep(els, size, device, rebuild_angle_deg=0.5)
    b = horizon_sweep(els, size, device, rebuild_angle_deg=0.1)
    ex = np.array([[r["exact"] for r in a["steps"]]])
    wa = np.array([[r["ours"] for r in a["steps"]]])
    wb = np.array([[r["ours"] for r in b["steps"]]])
    return Case("sunset: sun +1 to -1.5 deg (west wall)", "sky & sun at the horizon",
                "max radiance step beyond the exact step (of the exact value)", "sky map rebaked every 0.1 deg",
                a["max_excess_step"], b["max_excess_step"], a["ms"], b["ms"], exact=0.0,
                images={"exact": ex, "without": wa, "with": wb, "error": np.abs(wa - ex) / ex.max()},
                extra={"elevations": els.tolist(), "max_rel_error_default": a["max_rel_error"],
                       "max_rel_error_0.1deg": b["max_rel_error"], "finite": a["finite"] and b["finite"],
                       "min_radiance": min(a["min_radiance"], b["min_radiance"])})


# ----------------------------------------------------------------------------------------------
# temporal stability of every preset: a slowly moving sun, a slowly moving camera
# ----------------------------------------------------------------------------------------------

TEMPORAL_PRESETS = ("traced-probes", "lpv", "lpv-fast", "paper")
"""The quality presets the temporal-stability measurements cover."""
MEAN_STEP_BOUND = 0.01
"""Goal for the worst frame-to-frame step of the mean display luminance (relative)."""
P99_STEP_BOUND = 0.03
"""Goal for the worst frame-to-frame 99th-percentile pixel step of the display luminance (relative)."""
DISPLAY_FLOOR = 0.01
"""Display luminance (of 1) under which a pixel's step is taken relative to this instead of to the
pixel's own luminance (a step of a nearly black pixel is not a visible pop)."""
SUN_STEP_DEG = 0.05
"""The sun sweep's step: degrees of elevation per frame (the azimuth is kept)."""
CAMERA_STEP_M = 0.05
"""The camera pan's step: metres per frame along the camera's right vector."""


def display_luminance(hdr: np.ndarray, exposure: float) -> np.ndarray:
    """(H, W) the luminance of the renderer's tone map before the sRGB encoding (Reinhard,
    ``serenity.colour.reinhard``), in [0, 1): what the frame-to-frame steps are measured on."""
    return luminance(reinhard(np.asarray(hdr, np.float32), exposure))


def frame_step(prev: np.ndarray, cur: np.ndarray, mask: np.ndarray | None = None) -> tuple[float, float]:
    """(mean-luminance step, 99th-percentile pixel step) from display luminance ``prev`` to ``cur``
    ((H, W) each), over the pixels of ``mask`` (all when None):

        mean step = |mean(cur) − mean(prev)| / mean(prev)
        pixel step = |cur − prev| / max(prev, DISPLAY_FLOOR), and its 99th percentile over the pixels."""
    prev, cur = np.asarray(prev, np.float64), np.asarray(cur, np.float64)
    if mask is not None:
        prev, cur = prev[mask], cur[mask]
    if prev.size == 0:
        return 0.0, 0.0
    m = float(prev.mean())
    pixel = np.abs(cur - prev) / np.maximum(prev, DISPLAY_FLOOR)
    return abs(float(cur.mean()) - m) / max(m, DISPLAY_FLOOR), float(np.percentile(pixel, 99))


def preset_config(quality: str, overrides: dict | None = None) -> RenderConfig:
    """``RenderConfig.preset(quality)`` with ``overrides``: RenderConfig fields by name, or a
    sub-config's field as "sub.field" (e.g. ``{"lpv.temporal_blend": 1.0, "shadow.stagger": False}``)."""
    cfg = RenderConfig.preset(quality)
    for key, value in (overrides or {}).items():
        if "." in key:
            sub, name = key.split(".", 1)
            cfg = dataclasses.replace(cfg, **{sub: dataclasses.replace(getattr(cfg, sub), **{name: value})})
        else:
            cfg = dataclasses.replace(cfg, **{key: value})
    return cfg


def _component_p99(hdr_prev: np.ndarray, part_prev: np.ndarray, part_cur: np.ndarray, mask=None) -> float:
    """99th percentile over pixels of |Δ part| / the pixel's HDR luminance: how much of a pixel's
    step one part of its light makes (linear, before the tone map)."""
    lum = luminance(hdr_prev)
    d = np.abs(luminance(part_cur) - luminance(part_prev)) / np.maximum(lum, 1e-6 * max(float(lum.max()), 1e-12))
    if mask is not None:
        d = d[mask]
    return float(np.percentile(d, 99)) if d.size else 0.0


def _summary(mean: list[float], p99: list[float], parts: dict[str, list[float]], **extra) -> dict:
    mean_a, p99_a = np.array(mean), np.array(p99)
    out = {"mean_step": mean_a.tolist(), "p99_step": p99_a.tolist(),
           "worst_mean_step": float(mean_a.max(initial=0.0)), "worst_p99_step": float(p99_a.max(initial=0.0)),
           "worst_frame": int(np.argmax(p99_a)) + 1 if p99_a.size else 0,
           "parts_p99": {k: np.array(v).tolist() for k, v in parts.items()},
           "worst_parts_p99": {k: float(np.max(v, initial=0.0)) for k, v in parts.items()}}
    out.update(extra)
    return out


def sun_sweep(quality: str, frames: int = 40, size=(160, 90), step_deg: float = SUN_STEP_DEG, start_frame: int = 0,
              warmup: int = 0, scene_name: str = "courtyard", overrides: dict | None = None, device=None) -> dict:
    """The camera still, the sun's elevation sinking ``step_deg`` per frame from the scene's (its
    azimuth kept), rendered as an application renders it (one ``Renderer``, frame after frame). Frame k
    has the sun at elevation e0 − k·step_deg; the renderer starts at k = ``start_frame`` − ``warmup``
    and the ``frames`` steps from k = ``start_frame`` on are measured (``frame_step`` on the display
    luminance). Returns per step the mean-luminance step and the 99th-percentile pixel step, their worst
    and the step (1-based from ``start_frame``) of the worst pixel step; ``parts_p99``: per step, the
    99th percentile of the step of the direct sun light ("direct") and of everything else ("indirect":
    the sky volume's and the LPV's light, reflections and refractions), each over the pixel's HDR
    luminance; ``finite``: no NaN or infinite pixel."""
    scene = load(scene_name)
    el0, az = float(scene.sun.elevation_deg), float(scene.sun.azimuth_deg)
    cfg = preset_config(quality, overrides)
    r = Renderer(scene, *size, device=device, config=cfg)
    mean, p99, parts = [], [], {"direct": [], "indirect": []}
    prev = None
    finite = True
    try:
        for k in range(start_frame - warmup, start_frame + frames + 1):
            scene.sun.direction = direction_from_angles(el0 - step_deg * k, az)
            f = r.render(read_back=("hdr", "aovs"))
            finite &= bool(np.all(np.isfinite(f.hdr)))
            cur = (f.hdr, f.aovs["direct"], display_luminance(f.hdr, cfg.exposure))
            if prev is not None and k > start_frame:
                m, p = frame_step(prev[2], cur[2])
                mean.append(m)
                p99.append(p)
                parts["direct"].append(_component_p99(prev[0], prev[1], cur[1]))
                parts["indirect"].append(_component_p99(prev[0], prev[0] - prev[1], cur[0] - cur[1]))
            prev = cur
    finally:
        r.close()
    return _summary(mean, p99, parts, finite=finite, quality=quality, frames=frames, size=list(size),
                    step_deg=step_deg, start_frame=start_frame, start_elevation_deg=el0 - step_deg * start_frame)


def pan_camera(base: Camera, offset_m: float) -> Camera:
    """``base`` and its target moved ``offset_m`` metres along its right vector (a truck: the view
    direction kept)."""
    right = np.cross(base.forward, base.up)
    d = float(offset_m) * right / np.linalg.norm(right)
    return Camera(position=np.asarray(base.position) + d, target=np.asarray(base.target) + d, up=base.up,
                  fov_y_deg=base.fov_y_deg, near=base.near, far=base.far)


def reprojected(prev_lum, prev_position, prev_normal, prev_view_proj, position, normal, covered,
                tolerance_m: float = 0.05, smooth: float = 0.05):
    """Frame k−1's display luminance at the points frame k shows: each covered pixel's world point
    (``position`` (H, W, 3), ``normal``) projected with frame k−1's ``prev_view_proj`` and ``prev_lum``
    interpolated bilinearly there. Returns (values (H, W), mask): the mask keeps the pixels whose 4 taps
    lie in the image and show the same surface — the taps' normals (``prev_normal``) within 2.6° of the
    point's and their points (``prev_position``) within ``tolerance_m`` of its plane (elsewhere the point
    was hidden in frame k−1 or sits on an edge: a disocclusion) — and whose taps differ by at most
    ``smooth`` of their mean: across a sharp edge (of a shadow, a texture) a point-sampled pixel steps
    by itself as the edge crosses its centre, whatever the renderer does."""
    h, w = prev_lum.shape
    p = np.asarray(position, np.float64).reshape(-1, 3)
    n = np.asarray(normal, np.float64).reshape(-1, 3)
    clip = np.concatenate([p, np.ones((len(p), 1))], 1) @ np.asarray(prev_view_proj, np.float64).T
    wc = np.where(clip[:, 3] > 1e-9, clip[:, 3], 1e-9)
    x = (clip[:, 0] / wc * 0.5 + 0.5) * w - 0.5
    y = (1.0 - (clip[:, 1] / wc * 0.5 + 0.5)) * h - 0.5
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    ok = covered.reshape(-1) & (x0 >= 0) & (y0 >= 0) & (x0 < w - 1) & (y0 < h - 1) & (clip[:, 3] > 1e-9)
    x0, y0 = np.clip(x0, 0, w - 2), np.clip(y0, 0, h - 2)
    fx, fy = x - x0, y - y0
    val = np.zeros(len(p))
    lo, hi = np.full(len(p), np.inf), np.full(len(p), -np.inf)
    for dy, dx, wt in ((0, 0, (1 - fx) * (1 - fy)), (0, 1, fx * (1 - fy)), (1, 0, (1 - fx) * fy), (1, 1, fx * fy)):
        rr, cc = y0 + dy, x0 + dx
        ok &= np.sum(prev_normal[rr, cc] * n, axis=1) > 0.999
        ok &= np.abs(np.sum((prev_position[rr, cc] - p) * n, axis=1)) <= tolerance_m
        tap = prev_lum[rr, cc]
        val += wt * tap
        lo, hi = np.minimum(lo, tap), np.maximum(hi, tap)
    ok &= hi - lo <= smooth * np.maximum(val, DISPLAY_FLOOR)
    return val.reshape(h, w), ok.reshape(h, w)


def camera_pan(quality: str, frames: int = 40, size=(160, 90), step_m: float = CAMERA_STEP_M, start_frame: int = 0,
               warmup: int = 0, scene_name: str = "courtyard", overrides: dict | None = None, device=None,
               tolerance_m: float = 0.05) -> dict:
    """The sun still, the camera (and its target) moved ``step_m`` per frame along its right vector
    (``pan_camera``; frame k at k·step_m, started and measured as in ``sun_sweep``). A diffuse point's
    radiance does not depend on the camera, so frame k is compared with frame k−1 reprojected
    (``reprojected``: bilinear; left out the pixels whose reprojected surface disagrees — disocclusions
    and edges — or whose neighbourhood in frame k−1 has a sharp edge, and the pixels either frame
    ray-traced, mirrors and glass, whose radiance moves with the camera). The steps are
    ``frame_step``'s over the pixels kept, ``matched`` the fewest kept in a step (a fraction of the
    image); ``parts_p99`` as in ``sun_sweep``, over the same pixels."""
    scene = load(scene_name)
    base = scene.camera
    cfg = preset_config(quality, overrides)
    r = Renderer(scene, *size, device=device, config=cfg)
    w, h = size
    mean, p99, parts, matched = [], [], {"direct": [], "indirect": []}, []
    prev = None
    finite = True
    try:
        for k in range(start_frame - warmup, start_frame + frames + 1):
            scene.camera = cam = pan_camera(base, step_m * k)
            f = r.render(read_back=("hdr", "aovs"))
            finite &= bool(np.all(np.isfinite(f.hdr)))
            covered = np.isfinite(f.aovs["depth"][..., 0])
            traced = f.aovs["rt_mask"][..., 0] > 0 if "rt_mask" in f.aovs else np.zeros_like(covered)
            vp = cam.projection_matrix(w / h) @ cam.view_matrix()
            lum = display_luminance(f.hdr, cfg.exposure)
            cur = {"lum": lum, "hdr": f.hdr, "direct": f.aovs["direct"], "position": f.aovs["position"],
                   "normal": f.aovs["normal"], "vp": vp, "traced": traced}
            if prev is not None and k > start_frame:
                ok = covered & ~traced
                geo = (prev["position"], prev["normal"], prev["vp"], f.aovs["position"], f.aovs["normal"], ok,
                       tolerance_m)
                before, keep = reprojected(prev["lum"], *geo)
                back, _ = reprojected(prev["traced"].astype(np.float64), *geo, smooth=np.inf)
                keep &= back == 0.0  # no tap ray-traced in frame k−1 either
                m, p = frame_step(before, lum, keep)
                mean.append(m)
                p99.append(p)
                matched.append(float(keep.mean()))
                parts_prev = {}
                for name, img in (("hdr", prev["hdr"]), ("direct", prev["direct"])):
                    chans = [reprojected(img[..., c], *geo, smooth=np.inf)[0] for c in range(3)]
                    parts_prev[name] = np.stack(chans, axis=-1)
                parts["direct"].append(_component_p99(parts_prev["hdr"], parts_prev["direct"], f.aovs["direct"], keep))
                parts["indirect"].append(_component_p99(parts_prev["hdr"], parts_prev["hdr"] - parts_prev["direct"],
                                                        f.hdr - f.aovs["direct"], keep))
            prev = cur
    finally:
        r.close()
    return _summary(mean, p99, parts, finite=finite, quality=quality, frames=frames, size=list(size), step_m=step_m,
                    start_frame=start_frame, matched=float(min(matched, default=0.0)))


TEMPORAL_SWITCHES = (
    ("shadow tiles all redrawn every frame", {"shadow.stagger": False}),
    ("LPV cascades all updated every frame", {"lpv.stagger": False}),
    ("LPV light switched at once", {"lpv.temporal_blend": 1.0}),
    ("indirect light without its history", {"indirect_history": 1.0}),
    ("sky volume all re-lit every frame", {"sky.transfer_layers": 0, "sky_layers_per_frame": 1 << 10}),
    ("no LPV", {"lpv.enabled": False}),
)
"""The switches the temporal-stability breakdown turns, one at a time: (what it does, overrides for
``preset_config``). A switch that does not change a preset's settings is not run for it."""


def switch_applies(quality: str, overrides: dict) -> bool:
    """Whether ``overrides`` change what preset ``quality`` renders: its settings change (False also
    where a field does not exist), not only those of a part it leaves off (an LPV it does not use,
    the history of indirect light it computes at full resolution)."""
    base = RenderConfig.preset(quality)
    for key in overrides:
        if key.startswith("lpv.") and not base.lpv.enabled:
            return False
        if key == "indirect_history" and base.indirect_scale == 1:
            return False
        if key.startswith("sky") and base.sky.method != "layers" and base.sky.transfer_layers == 0:
            return False  # every probe is re-lit every frame already
    try:
        return preset_config(quality, overrides) != base
    except (TypeError, AttributeError):
        return False


def _pct(x: float) -> str:
    return f"{100.0 * float(x):.2f} %"


def temporal_stability_markdown(now: dict, baseline: dict | None = None) -> str:
    """The temporal-stability table of ``docs/stability.md`` from ``benchmarks/results/
    temporal_stability.json`` (``now``) and, beside it, the same measurement of the renderer without
    its temporal mitigations (``temporal_stability_baseline.json``, its commit recorded there): per
    preset, the worst mean-luminance step and the worst 99th-percentile pixel step of the sun sweep and
    of the camera pan."""
    goal = f"goal ≤ {_pct(now['bounds']['mean_step'])} / ≤ {_pct(now['bounds']['p99_step'])}"
    header = ["preset", "sun sweep: worst mean step", "sun sweep: worst p99 pixel step",
              "camera pan: worst mean step", "camera pan: worst p99 pixel step"]
    rows = []
    for q, r in now["presets"].items():
        b = (baseline or {}).get("presets", {}).get(q)
        cells = [f"`{q}`"]
        for case in ("sun", "camera"):
            for key in ("worst_mean_step", "worst_p99_step"):
                text = _pct(r[case][key])
                if b is not None and case in b:
                    text = f"{_pct(b[case][key])} → **{text}**"
                cells.append(text)
        rows.append(cells)
    lines = ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    lines += ["| " + " | ".join(c) + " |" for c in rows]
    note = (f"{now['size'][0]}×{now['size'][1]}, {now['scene']}, {now['frames']} frame-to-frame steps each "
            f"({goal}); " + ("the renderer without its temporal mitigations → **with them**." if baseline
                                else "with the temporal mitigations."))
    return "\n".join(lines) + "\n\n" + note


def temporal_breakdown_markdown(now: dict, baseline: dict | None = None) -> str:
    """Where the sun sweep's pixel steps come from, per preset: the worst 99th-percentile pixel step as
    measured, of the direct sun light and of the rest alone (``parts``), and with each switch of
    ``TEMPORAL_SWITCHES`` that applies turned; without the temporal mitigations → with them where
    both have it."""
    header = ["preset", "what", "worst p99 pixel step"]
    rows = []
    for q, r in now["presets"].items():
        b = (baseline or {}).get("presets", {}).get(q)
        bb = {row["switch"]: row for row in (baseline or {}).get("breakdown", {}).get(q, [])}

        def cell(value, before):
            return _pct(value) if before is None else f"{_pct(before)} → **{_pct(value)}**"

        rows.append([f"`{q}`", "as it renders", cell(r["sun"]["worst_p99_step"], b and b["sun"]["worst_p99_step"])])
        for part, label in (("direct", "the direct sun light's step alone"), ("indirect", "the rest's step alone")):
            rows.append([f"`{q}`", label, cell(r["sun"]["worst_parts_p99"][part],
                                                b and b["sun"]["worst_parts_p99"][part])])
        for row in now.get("breakdown", {}).get(q, []):
            before = bb.get(row["switch"])
            rows.append([f"`{q}`", row["switch"], cell(row["worst_p99_step"], before and before["worst_p99_step"])])
    lines = ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    lines += ["| " + " | ".join(c) + " |" for c in rows]
    return "\n".join(lines) + ("\n\nThe parts are each part's step over the pixel's HDR luminance (before the tone "
                               "map); the switches are turned one at a time.")

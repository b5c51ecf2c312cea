"""The sky lighting irradiance volume (paper §7, Fig. 6–9): L2 SH irradiance probes lit by the sky map
and shadowed by occlusion quads, computed one layer per frame.

Grid: probes at ``grid_origin + (x, y, z)·cell_size`` for x < X, y < Y, z < Z (``resolution`` =
(X, Y, Z)), fitted to the scene's bounds (centred on them). The cell is cubic,
``SkyConfig.cell_size`` metres, or by default chosen from the scene's scale so that the
bounds hold about ``target_probes`` = 32·16·23 probes (the paper's reference volume);
``resolution=(X, Y, Z)`` instead fits exactly that many probes to the bounds (per-axis cells).
A **layer** is one y slice (X·Z probes; the paper's 32×16×23 volume has 16 layers).

Per probe (``integrate_sky_layer_kernel(sequence)``, the sequence compiled in): ``rays_per_probe``
directions ωᵢ over the sphere, a QMC set (:mod:`serenity.kernels.sampling`) — Hammersley with a
per-probe Cranley–Patterson rotation (default) or Owen-scrambled Sobol' with a per-probe seed —
mapped equal-area to the sphere (pdf 1/4π), decorrelated between probes by hashing the probe's
index. Each ray from the probe is tested against every occlusion quad (two-sided rectangle,
``model.OcclusionQuad``, paper Fig. 6); an unoccluded ray gets

    ω.y ≥ 0: the sky map, bilinear in the paraboloid map (``atmosphere.sample_sky_map``);
    ω.y < 0: the ground, a Lambertian plane of albedo ``ground_albedo`` lit by the sky only:
             L_g = ρ_g/π·E_sky↓ (E_sky↓ = the map's irradiance on a horizontal surface). The
             sun's bounce off the ground is left to the light propagation volumes (their RSM
             carries it); ρ_g = 0 gives a black lower hemisphere, ρ_g = 1 with a constant sky is
             the white furnace (E = π·L for every normal).

and is projected onto real L2 SH (:mod:`serenity.kernels.sh`): L_k = 4π/N·Σ L(ωᵢ)Y_k(ωᵢ), then
convolved with the clamped cosine and windowed: E_k = Â_l·w_l·L_k (the **irradiance
coefficients**, W·m⁻²). A constant sky is supported (``Sky.model == "constant"``: the map holds
``Sky.radiance``).

Storage (paper §7: "six RGBA textures and one RGB texture"): 27 float32 per probe, coefficient-
major, flat index f = 3k + c (k the SH index 0..8, c the RGB channel); texture t < 6 holds
f = 4t..4t+3 in RGBA, texture 6 holds f = 24..26 in RGB. ``textures()`` returns them as 7 numpy
arrays (Z, Y, X, 4) ×6 + (Z, Y, X, 3), ready for ``upload_texture3d`` (width X, height Y,
depth Z).

Lookup (``irradiance``; ``serenity/raster/glsl/sky.glsl``'s ``sky_volume_lookup`` is the same
arithmetic, ``interpolate_volume`` its numpy twin, ``probegather.volume_irradiance`` its Warp twin):
    p' = p + normal_offset_m·n;  g = clamp((p' − grid_origin)/cell_size, 0, resolution − 1);
    texture coordinate (g + ½)/resolution, trilinear (GL_LINEAR, clamp to edge) of the 27
    coefficients — for the gathered probes with ``SkyConfig.gather_visibility``, the 8 probes read
    one by one, each weighed by its visibility (``probegather.probe_visibility``); beyond the grid's
    sides and top the coefficients fade to the open sky's (``open_coefficients``) over
    ``OPEN_FADE_CELLS``; E(n) = max(0, Σ_k E_k·Y_k(n)) per channel, W·m⁻², and (``glossy``) the radiance
    around a direction filtered by the Phong lobe from the same coefficients (``glossy_band_factors``).
``normal_offset_m`` = ``normal_offset`` (in cells) × the smallest cell edge: it moves the lookup
off the surface, away from probes behind it. The grid covers the scene's bounds, or with
``SkyConfig.fit = "content"`` what stands on the ground (``Scene.content_bounds``).

Updating: ``update(layers=1)`` — the per-frame path — rebakes the sky map when the sun moved more
than ``rebuild_angle_deg`` (``atmosphere.SkyMapCache``), which restarts the sweep at layer 0, then
integrates the next ``layers`` stale layers; it returns whether anything changed. After a sun step
the volume is fully current after Y calls (Y = layers in the volume). ``rebuild()`` does it all at
once. Probe results are deterministic (fixed per-probe seeds), so a layer-by-layer sweep equals a
rebuild bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from serenity.config import SKY_SEQUENCES, SkyConfig
from serenity.device import resolve_device
from serenity.kernels.atmosphere import (
    SkyMapCache,
    horizontal_irradiance,
    sample_sky_map,
)
from serenity.kernels.atmosphere_ref import (
    angle_between_deg,
    sampling_operator,
    scene_sun_irradiance,
)
from serenity.kernels.factory import kernel_factory
from serenity.kernels.launch import launch
from serenity.kernels.occlusion import intersect_quads, occluded_np, quads_arrays  # noqa: F401 (re-exported)
from serenity.kernels.probegather import (
    OPEN_FADE_CELLS,
    REACH_MARGIN_CELLS,
    VIS_BIAS_CELLS,
    VIS_CRUSH,
    VIS_OCT,
    VIS_TILE,
    ProbeGather,
    direction_sets,
    oct_encode_np,
    reach_key,
    reachable_probes,
    scene_key,
    visibility_atlas,
    volume_irradiance,
)
from serenity.kernels.quadfit import fit_occlusion_quads
from serenity.kernels.raytrace import RayTracer
from serenity.kernels.sampling import cp_rotation, hammersley_np, hash_u32, sample_probe_direction
from serenity.kernels.sh import A_HAT, BAND, eval_sh9, irradiance_scale, sh_basis, vec9
from serenity.kernels.skytransfer import SkyTransfer, project_sky

wp.set_module_options({"enable_backward": False})

# ---------------------------------------------------------------------------------------------
# constants

#: directions (a spherical Fibonacci set) the open sky's coefficients are projected from
OPEN_SKY_DIRECTIONS = 4096

PAPER_RESOLUTION = (32, 16, 23)
SEQUENCES = SKY_SEQUENCES
COEFFS = 27
_FOUR_PI = wp.constant(4.0 * math.pi)


# ---------------------------------------------------------------------------------------------
# funcs


# ---------------------------------------------------------------------------------------------
# kernels


@kernel_factory(sequence=SKY_SEQUENCES)
def integrate_sky_layer_kernel(sequence: str):
    """The probe-integration kernel for one direction ``sequence`` (``SkyConfig.sequence``), compiled
    in: Hammersley points Cranley–Patterson rotated per probe, or Owen-scrambled Sobol' per probe."""
    if sequence not in SEQUENCES:
        raise ValueError(f"sequence must be one of {SEQUENCES}, got {sequence!r}")
    hammersley = sequence == "hammersley"

    @wp.kernel(enable_backward=False, module="unique")
    def integrate_sky_layer(
        # inputs
        origin: wp.vec3,
        cell: wp.vec3,
        res_x: int,
        res_y: int,
        res_z: int,
        first_layer: int,
        centers: wp.array(dtype=wp.vec3),
        ups: wp.array(dtype=wp.vec3),
        rights: wp.array(dtype=wp.vec3),
        halves: wp.array(dtype=wp.vec2),
        quad_count: int,
        sky_map: wp.array2d(dtype=wp.vec3),
        ground: wp.vec3,
        base_points: wp.array(dtype=wp.vec2),
        rays: int,
        salt: wp.uint32,
        scale: vec9,
        # outputs
        coeffs: wp.array2d(dtype=float),
        offset: int,
    ):
        t = wp.tid() + offset
        slab = res_x * res_z
        y = first_layer + t // slab
        rem = t - (t // slab) * slab
        z = rem // res_x
        x = rem - z * res_x
        probe = (z * res_y + y) * res_x + x
        p = origin + wp.vec3(float(x) * cell[0], float(y) * cell[1], float(z) * cell[2])
        seed = hash_u32(wp.uint32(probe) ^ salt)
        rot = cp_rotation(seed)
        acc_r = vec9()
        acc_g = vec9()
        acc_b = vec9()
        for k in range(rays):
            d = sample_probe_direction(k, base_points, rot, seed, wp.static(hammersley))
            if not intersect_quads(p, d, centers, ups, rights, halves, quad_count):
                radiance = ground
                if d[1] >= 0.0:
                    radiance = sample_sky_map(sky_map, d)
                b = eval_sh9(d)
                acc_r += b * radiance[0]
                acc_g += b * radiance[1]
                acc_b += b * radiance[2]
        w = _FOUR_PI / float(rays)
        for k in range(9):
            s = scale[k] * w
            coeffs[probe, 3 * k + 0] = acc_r[k] * s
            coeffs[probe, 3 * k + 1] = acc_g[k] * s
            coeffs[probe, 3 * k + 2] = acc_b[k] * s

    return integrate_sky_layer


@wp.kernel
def lookup_sky_irradiance(
    # inputs
    coeffs: wp.array2d(dtype=float),
    open_sky: wp.array(dtype=float),
    vis: wp.array3d(dtype=wp.vec2),
    offsets: wp.array(dtype=wp.vec3),
    origin: wp.vec3,
    cell: wp.vec3,
    res_x: int,
    res_y: int,
    res_z: int,
    normal_offset: float,
    points: wp.array(dtype=wp.vec3),
    normals: wp.array(dtype=wp.vec3),
    # outputs
    irradiance: wp.array(dtype=wp.vec3),
    offset: int,
):
    """The volume's irradiance at surface points (``eval_volume_irradiance`` and sky.glsl's
    arithmetic): trilinear coefficients at p + offset·n, evaluated at n, clamped at 0."""
    i = wp.tid() + offset
    irradiance[i] = volume_irradiance(coeffs, open_sky, vis, offsets, origin, cell, res_x, res_y, res_z,
                                      normal_offset, points[i], normals[i])


# ---------------------------------------------------------------------------------------------
# host


#: the grid is at least this fraction of its widest side high: a scene that is (or whose contents
#: are) flat, e.g. a ground plane alone, still gets a volume of light above it, not one layer of
#: probes in the plane (which took the plane scene to 256 × 1 × 256 probes, more than asked for)
MIN_HEIGHT_FRACTION = 1.0 / 16.0
#: 3D textures of this size per axis are what every GL 4.x must allow (GL_MAX_3D_TEXTURE_SIZE,
#: llvmpipe's limit too): the gathered probes' visibility atlas holds VIS_TILE texels per probe
#: along x and z, so a grid with visibility has at most this / VIS_TILE probes along them
GL_MIN_MAX_3D_TEXTURE = 2048


def max_axis_probes(config: SkyConfig) -> int:
    """The most probes along one axis of the grid: 255, or fewer where the visibility atlas must fit
    a 3D texture (``GL_MIN_MAX_3D_TEXTURE``)."""
    if config.method == "gather" and config.gather_visibility:
        return min(255, GL_MIN_MAX_3D_TEXTURE // VIS_TILE)
    return 255


def fit_grid(bounds: np.ndarray, config: SkyConfig) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int]]:
    """(origin (3,), cell_size (3,), resolution (X, Y, Z)) of the probe grid for scene bounds (2,3),
    raised to at least ``MIN_HEIGHT_FRACTION`` of its widest side above their floor."""
    lo, hi = np.array(bounds, np.float64)
    hi[1] = max(hi[1], lo[1] + MIN_HEIGHT_FRACTION * float(np.max(hi - lo)))
    extent = np.maximum(hi - lo, 0.0)
    centre = (lo + hi) / 2
    if config.resolution is not None:
        res = np.asarray(config.resolution, np.int64)
        cell = np.where(res > 1, extent / np.maximum(res - 1, 1), max(float(extent.max()), 1e-3))
        cell = np.maximum(cell, 1e-6)
    else:
        c = config.cell_size
        if c is None:
            vol = float(np.prod(np.maximum(extent, 1e-3 * max(float(extent.max()), 1e-3))))
            c = (vol / config.target_probes) ** (1.0 / 3.0)
            c = max(c, float(extent.max()) / (max_axis_probes(config) - 1), 1e-6)
        res = np.maximum(np.ceil(extent / c - 1e-9).astype(np.int64) + 1, 1)
        cell = np.full(3, float(c))
    origin = centre - (res - 1) * cell / 2
    return origin, cell, (int(res[0]), int(res[1]), int(res[2]))


def pack_sh_textures(coeffs: np.ndarray, resolution: tuple[int, int, int]) -> list[np.ndarray]:
    """(P, 27) coefficients → 6 × (Z, Y, X, 4) + 1 × (Z, Y, X, 3) float32 (coefficient-major packing)."""
    x, y, z = resolution
    c = np.asarray(coeffs, np.float32).reshape(z, y, x, COEFFS)
    return [np.ascontiguousarray(c[..., 4 * t:4 * t + 4]) for t in range(6)] + [np.ascontiguousarray(c[..., 24:27])]


def unpack_sh_textures(textures: list[np.ndarray]) -> np.ndarray:
    """Inverse of :func:`pack_sh_textures`: (Z, Y, X, 27)."""
    return np.concatenate([np.asarray(t, np.float32) for t in textures], axis=-1)


def _probe_visibility_np(vis, offsets, idx, cells, grid_pos, p, x, n) -> np.ndarray:
    """(N,) :func:`serenity.kernels.probegather.probe_visibility` on the host, for one corner: probe
    indices ``idx`` (N,), their cells (N, 3) and grid positions (N, 3)."""
    t, o = VIS_TILE, VIS_OCT
    q = grid_pos + offsets[idx]
    to_probe = q - p
    to_probe /= np.maximum(np.linalg.norm(to_probe, axis=1, keepdims=True), 1e-30)
    b = ((to_probe * n).sum(axis=1) + 1.0) * 0.5
    w = b * b + 0.2
    d = x - q
    dist = np.linalg.norm(d, axis=1)
    uv = oct_encode_np(d / np.maximum(dist, 1e-9)[:, None])
    tu = cells[:, 0] * t + 1 + (uv[:, 0] * 0.5 + 0.5) * o - 0.5
    tv = cells[:, 2] * t + 1 + (uv[:, 1] * 0.5 + 0.5) * o - 0.5
    u0, v0 = np.floor(tu).astype(np.int64), np.floor(tv).astype(np.int64)
    fu, fv = (tu - u0)[:, None], (tv - v0)[:, None]
    lu, lv = cells[:, 0] * t, cells[:, 2] * t
    ua, ub = np.clip(u0, lu, lu + t - 1), np.clip(u0 + 1, lu, lu + t - 1)
    va, vb = np.clip(v0, lv, lv + t - 1), np.clip(v0 + 1, lv, lv + t - 1)
    yi = cells[:, 1]
    m = (vis[va, yi, ua] * (1 - fu) + vis[va, yi, ub] * fu) * (1 - fv) + \
        (vis[vb, yi, ua] * (1 - fu) + vis[vb, yi, ub] * fu) * fv
    var = np.abs(m[:, 1] - m[:, 0] ** 2)
    c = var / (var + (dist - m[:, 0]) ** 2 + 1e-12)
    w = np.where(dist > m[:, 0], w * np.maximum(c ** 3, 0.0), w)
    w = np.maximum(w, 1e-6)
    return np.where(w < VIS_CRUSH, w ** 3 / VIS_CRUSH ** 2, w)


def interpolate_volume(coeffs_zyx: np.ndarray, origin, cell, resolution, normal_offset_m: float, points, normals,
                       open_coeffs=None, visibility=None) -> np.ndarray:
    """(N, 9, 3) float64 coefficients the lookup evaluates at each surface point — the shader's
    arithmetic on the host: trilinear at p + offset·n (clamped to the grid) — each probe's weight
    times its visibility when ``visibility`` = (atlas (Z·T, Y, X·T, 2), offsets (P, 3)) is given
    (``probegather.probe_visibility``), the weights renormalised — faded to ``open_coeffs`` ((9, 3), the
    open sky; None = zeros) beyond the grid's sides and top over ``OPEN_FADE_CELLS``."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    res = np.asarray(resolution, np.float64)
    origin = np.asarray(origin, np.float64)
    cell = np.asarray(cell, np.float64)
    x = p + normal_offset_m * n
    gr = (x - origin) / cell
    beyond = np.maximum.reduce([-gr[:, 0], gr[:, 0] - (res[0] - 1), -gr[:, 2], gr[:, 2] - (res[2] - 1),
                                gr[:, 1] - (res[1] - 1)])
    w_open = np.clip(beyond / OPEN_FADE_CELLS, 0.0, 1.0)
    g = np.clip(gr, 0.0, res - 1.0)
    i0 = np.floor(g).astype(np.int64)
    a = g - i0
    ri = np.asarray(resolution, np.int64)
    i1 = np.minimum(i0 + 1, ri - 1)
    c = np.asarray(coeffs_zyx).reshape(-1, COEFFS)
    if visibility is not None:
        x_vis = p + VIS_BIAS_CELLS * float(np.min(cell)) * n
        vis = np.asarray(visibility[0], np.float64)
        offsets = np.asarray(visibility[1], np.float64).reshape(-1, 3)
    # the 8 corners at once: flat cell indices (N, 8) and trilinear weights (N, 8), one gather
    idx = np.empty((len(p), 8), np.int64)
    wts = np.empty((len(p), 8))
    k = 0
    for dz in (0, 1):
        zi, wz = (i1[:, 2], a[:, 2]) if dz else (i0[:, 2], 1 - a[:, 2])
        for dy in (0, 1):
            yi, wy = (i1[:, 1], a[:, 1]) if dy else (i0[:, 1], 1 - a[:, 1])
            for dx in (0, 1):
                xi, wx = (i1[:, 0], a[:, 0]) if dx else (i0[:, 0], 1 - a[:, 0])
                idx[:, k] = (zi * ri[1] + yi) * ri[0] + xi
                wts[:, k] = wx * wy * wz
                if visibility is not None:
                    cells = np.stack([xi, yi, zi], axis=1)
                    wts[:, k] *= _probe_visibility_np(vis, offsets, idx[:, k], cells, origin + cells * cell, p, x_vis,
                                                      n)
                k += 1
    out = np.einsum("nk,nkc->nc", wts, c[idx], dtype=np.float64).reshape(-1, 9, 3)
    if visibility is not None:
        out /= np.maximum(wts.sum(axis=1), 1e-30)[:, None, None]
    if open_coeffs is not None:
        out = out * (1.0 - w_open)[:, None, None] + np.asarray(open_coeffs, np.float64).reshape(1, 9, 3) * \
            w_open[:, None, None]
    else:
        out = out * (1.0 - w_open)[:, None, None]
    return out


def eval_volume_irradiance(coeffs_zyx: np.ndarray, origin, cell, resolution, normal_offset_m: float,
                           points, normals, open_coeffs=None, visibility=None) -> np.ndarray:
    """(N,3) float64 irradiance from (Z, Y, X, 27) coefficients — the shader's arithmetic, on the host."""
    c = interpolate_volume(coeffs_zyx, origin, cell, resolution, normal_offset_m, points, normals, open_coeffs,
                           visibility)
    y = sh_basis(np.asarray(normals, np.float64).reshape(-1, 3))
    return np.maximum(np.einsum("nk,nkc->nc", y, c), 0.0)


def glossy_band_factors(shininess) -> np.ndarray:
    """(N, 9) weights that turn irradiance coefficients E_lm = Â_l·L_lm into the radiance filtered by
    the normalised Phong lobe of exponent m, (m + 1)/(2π)·cos^m: its SH factors are 1, (m + 1)/(m + 2)
    and m/(m + 3) for bands 0, 1, 2 (∫ P_l(x)·(m + 1)·x^m dx over [0, 1]), over Â_l = π, 2π/3, π/4."""
    m = np.asarray(shininess, np.float64).reshape(-1)
    band = np.stack([np.full_like(m, 1.0), (m + 1.0) / (m + 2.0), m / (m + 3.0)], axis=1)
    band /= np.array([A_HAT])
    return band[:, np.asarray(BAND)]


def eval_volume_glossy(coeffs_zyx: np.ndarray, origin, cell, resolution, normal_offset_m: float, points, normals,
                       directions, shininess, open_coeffs=None, visibility=None) -> np.ndarray:
    """(N,3) float64 radiance around ``directions`` filtered by the Phong lobe of exponent ``shininess``
    (scalar or (N,)), from the coefficients looked up at the points and normals — sky.glsl's glossy
    term (``sky_volume_lookup``), on the host."""
    c = interpolate_volume(coeffs_zyx, origin, cell, resolution, normal_offset_m, points, normals, open_coeffs,
                           visibility)
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    m = np.broadcast_to(np.asarray(shininess, np.float64), (len(d),))
    y = sh_basis(d) * glossy_band_factors(m)
    return np.maximum(np.einsum("nk,nkc->nc", y, c), 0.0)


class SkyVolume:
    """The sky lighting irradiance volume of one scene (see the module docstring).

    Attributes for the shader: ``grid_origin`` (3,) m, ``cell_size`` (3,) m, ``resolution``
    (X, Y, Z), ``normal_offset_m``; ``textures()`` the 7 arrays. ``sky`` is the
    :class:`~serenity.kernels.atmosphere.SkyMapCache` (its ``sky_map`` is what the dome samples).
    """

    def __init__(self, scene, config: SkyConfig | None = None, device: str | None = None):
        self.scene = scene
        self.config = cfg = config or SkyConfig()
        self.device = resolve_device(device)
        bounds = scene.content_bounds() if cfg.fit == "content" else scene.bounds
        self.grid_origin, self.cell_size, self.resolution = fit_grid(bounds, cfg)
        self.normal_offset_m = float(cfg.normal_offset * float(np.min(self.cell_size)))
        quads = list(scene.occlusion_quads)
        self.quad_fit = None
        if not quads and cfg.auto_quads and cfg.method != "gather":  # "gather" traces the real geometry
            self.quad_fit = fit_occlusion_quads(scene)
            quads = self.quad_fit.quads
        self.quads = quads
        dev = self.device
        c, u, r, h = quads_arrays(quads)
        self._quads_wp = (wp.array(c, dtype=wp.vec3, device=dev), wp.array(u, dtype=wp.vec3, device=dev),
                          wp.array(r, dtype=wp.vec3, device=dev), wp.array(h, dtype=wp.vec2, device=dev))
        n = cfg.rays_per_probe
        self._base = wp.array(hammersley_np(n) if cfg.sequence == "hammersley" else np.zeros((n, 2), np.float32),
                              dtype=wp.vec2, device=dev)
        self._scale = vec9(*irradiance_scale(cfg.window, cfg.window_size).astype(np.float32).tolist())
        x, y, z = self.resolution
        self.probe_count = x * y * z
        self._coeffs = wp.zeros((self.probe_count, COEFFS), dtype=float, device=dev)
        #: the open sky's coefficients (the lookup fades to them beyond the grid's sides and top)
        self._open = wp.zeros(COEFFS, dtype=float, device=dev)
        self._open_host = np.zeros((9, 3))
        self._open_version = -1
        self._open_dirs = direction_sets(OPEN_SKY_DIRECTIONS, 1)[0]
        self._open_operator = None  # (sky map size, its sampling operator, the lower directions' Σ Y)
        #: "gather" with ``gather_visibility``: (atlas (Z·T, Y, X·T, 2), offsets (P, 3)) of the probes'
        #: depth moments and relocations, weighing each probe by whether it sees the point; else None
        self.visibility = None
        self._vis_wp = (wp.zeros((0, 0, 0), dtype=wp.vec2, device=dev), wp.zeros(0, dtype=wp.vec3, device=dev))
        self._constant_sky = getattr(scene.sky, "model", "atmosphere") == "constant"
        self.sky = SkyMapCache(cfg.sky_map_size, cfg.rebuild_angle_deg, device=dev, steps=cfg.sky_steps,
                              table=cfg.sky_view_table)
        self._constant_map = None
        self.ground_radiance = np.zeros(3)
        #: sky-map version each layer was last integrated against (-1: never)
        self.layer_versions = np.full(y, -1, np.int64)
        self._next_layer = 0
        #: (first layer, count) slabs the last ``update``/``rebuild`` changed, for a partial upload
        self.updated_layers: list[tuple[int, int]] = []
        self._host: np.ndarray | None = None
        self._transfer = None
        self._projected: tuple[int, np.ndarray] | None = None  # (sky version, project_sky's result)
        self._gather = None  # "gather": ProbeGather, made on the first update (it traces the probes' rays)
        self._gather_version = -1  # sky version the gather's miss radiance and sun visibility follow
        self._gather_sun = None  # ... and the sun direction
        #: "gather": passes over the volume still to run for the current sky (each adds a bounce)
        self.gather_passes_left = 0
        #: "gather": the relative change of the volume's light in the last complete pass (None: no pass
        #: since the passes started), and the light at the start of the running pass
        self._last_pass_change: float | None = None
        self._pass_before: np.ndarray | None = None
        self.tracer = None
        if cfg.method == "transfer":
            self._transfer = SkyTransfer(self._quads_wp, len(quads), self._base, n, SEQUENCES.index(cfg.sequence),
                                         cfg.seed, cfg.transfer_bands, dev)

    # -- sky

    @property
    def sky_version(self) -> int:
        """Version of the sky the probes are lit by (the sky map's bake count; 1 for a constant sky)."""
        return 1 if self._constant_sky else self.sky.version

    def _current_sky_map(self, sun_direction):
        """(Warp sky map, changed?) — the atmosphere's cached bake, or the constant sky."""
        cfg = self.config
        if self._constant_sky:
            if self._constant_map is None:
                m = np.broadcast_to(np.asarray(self.scene.sky.radiance, np.float32), (2, 2, 3))
                self._constant_map = wp.array(np.ascontiguousarray(m), dtype=wp.vec3, device=self.device)
                self.ground_radiance = cfg.ground_albedo * np.asarray(self.scene.sky.radiance, np.float64)
                return self._constant_map, True
            return self._constant_map, False
        m, rebaked = self.sky.get(sun_direction)
        if rebaked:
            self.ground_radiance = cfg.ground_albedo / math.pi * horizontal_irradiance(self.sky.sky_map)
        return m, rebaked

    def open_coefficients(self) -> np.ndarray:
        """(9, 3) float64 irradiance coefficients of a probe under the open sky (nothing occludes it:
        the sky map above the horizon, the ground radiance below, as a probe's misses), for the sky
        the volume was last lit by. The lookup fades to them beyond the grid's sides and top
        (``OPEN_FADE_CELLS``), where only open sky is left (``SkyConfig.fit = "content"``)."""
        if not self._constant_sky and self.sky.sky_map is None:  # no sky baked yet: nothing lit either
            return self._open_host
        if self._open_version != self.sky_version:
            d = self._open_dirs
            sky_map = self.sky_map()
            size = sky_map.shape[0]
            if self._open_operator is None or self._open_operator[0] != size:
                # Σ_i Y(d_i) L(d_i): the sky map's bilinear samples at the upper directions and the
                # ground radiance at the lower ones, as one linear map of the sky map per map size
                # (the sky map is rebaked every frame while the sun moves: this is ~50 µs, the
                # samples and their projection were ~1 ms)
                basis = sh_basis(d)
                up = d[:, 1] >= 0
                self._open_operator = (size, sampling_operator(size, d[up], basis[up]), basis[~up].sum(axis=0))
            _, op, ground = self._open_operator
            summed = op @ np.asarray(sky_map, np.float64).reshape(-1, 3) + np.outer(ground, self.ground_radiance)
            scale = irradiance_scale(self.config.window, self.config.window_size)
            self._open_host = scale[:, None] * (4.0 * math.pi / len(d)) * summed
            self._open.assign(self._open_host.reshape(-1).astype(np.float32))
            self._open_version = self.sky_version
        return self._open_host

    def sky_map(self) -> np.ndarray:
        """(S, S, 3) float32 the sky map the probes sample (constant sky: a 2×2 map)."""
        if self._constant_sky:
            return np.broadcast_to(np.asarray(self.scene.sky.radiance, np.float32), (2, 2, 3)).copy()
        return self.sky.sky_map

    # -- integration

    def _integrate(self, sky_map, first: int, count: int) -> None:
        x, y, z = self.resolution
        cfg = self.config
        c, u, r, h = self._quads_wp
        launch(integrate_sky_layer_kernel(cfg.sequence), count * x * z,
               [wp.vec3(*self.grid_origin.astype(np.float32)), wp.vec3(*self.cell_size.astype(np.float32)),
                x, y, z, int(first), c, u, r, h, len(self.quads), sky_map,
                wp.vec3(*self.ground_radiance.astype(np.float32)), self._base, int(cfg.rays_per_probe),
                wp.uint32(cfg.seed & 0xFFFFFFFF), self._scale, self._coeffs],
               device=self.device)
        self._host = None

    def _sun(self, sun_direction):
        return np.asarray(self.scene.sun.direction if sun_direction is None else sun_direction, np.float64)

    def may_change(self, sun_direction=None) -> bool:
        """Whether ``update`` (with ``layers`` > 0) could change a probe now; False only when it surely
        changes none: the sky map needs no rebake and every layer is current. "gather" always says
        True. For a scheduler that decides before the update runs (``Renderer``'s volume worker)."""
        if self.config.method == "gather" or np.any(self.layer_versions < 0):
            return True
        if self._constant_sky:
            return self._constant_map is None or self.pending_layers > 0
        return (self.sky.sky_map is None or self.sky.needs_rebuild(self._sun(sun_direction))
                or self.pending_layers > 0)

    def update(self, layers: int = 1, sun_direction=None) -> bool:
        """Bring the volume towards the current sky; returns whether any probe changed
        (``updated_layers`` then says which y-layers).

        "transfer": after a rebake of the sky map the probes are re-lit from the new sky — every
        probe at once with ``SkyConfig.transfer_layers`` = 0, else that many layers per update in a
        continuous cycle (a volume never lit is lit whole); nothing to do while every layer is current.
        "layers" (the paper): the next ``layers`` layers of a continuous cycle over the volume are
        integrated against the newest sky map, so with the sun moving every frame each layer is at
        most ceil(Y / layers) updates old; once every layer has seen the current sky, nothing is done.
        ``sun_direction`` defaults to ``scene.sun.direction``."""
        sun = self._sun(sun_direction)
        sky_map, changed = self._current_sky_map(sun)
        self.updated_layers = []
        if self.config.method == "gather":
            return self._update_gather(sun, full=False)
        if self._transfer is not None:
            if not self.pending_layers:
                return False
            per_update = self.config.transfer_layers
            if per_update <= 0 or np.any(self.layer_versions < 0):  # all at once, or never lit
                self._apply_transfer()
                return True
            for start, n in self._next_slabs(per_update):
                self._apply_transfer(start, n)
            return True
        if layers <= 0 or self.pending_layers == 0:
            return False
        for start, n in self._next_slabs(layers):
            self._integrate(sky_map, start, n)
            self.layer_versions[start:start + n] = self.sky_version
            self.updated_layers.append((start, n))
        return True

    # -- "gather" (probegather)

    def _ensure_gather(self):
        if self._gather is None:
            cfg = self.config
            if self.tracer is None:
                self.tracer = RayTracer(self.scene, device=self.device)
            size = cfg.gather_surfel_size or 0.4 * float(np.min(self.cell_size))
            glossy = ([m.specular if m.reflectivity == 0 and m.transparency == 0 else 0.0
                       for m in self.scene.materials] if cfg.glossy else None)
            # only the probes a lookup on the scene's surfaces can read are traced and gathered
            pos, _, _, faces, _ = self.scene.merged()
            reach = self.normal_offset_m + REACH_MARGIN_CELLS * float(np.min(self.cell_size))
            grid = (self.grid_origin.copy(), self.cell_size.copy(), self.resolution)
            self._gather = g = ProbeGather(self.tracer, self.probe_positions(), self.cell_size,
                                           cfg.gather_rays, size, self.device, glossy_energy=glossy,
                                           transmissions=cfg.gather_transmissions, cache_key=scene_key(self.scene),
                                           active=lambda: reachable_probes(pos, faces, *grid, reach),
                                           active_key=reach_key(reach, self.resolution),
                                           grid=(self.grid_origin, self.resolution, self.normal_offset_m))
            if cfg.gather_visibility:
                atlas = visibility_atlas(g.moments, self.resolution)
                self.visibility = (atlas, g.offsets)
                self._vis_wp = (wp.array(atlas, dtype=wp.vec2, device=self.device),
                                wp.array(g.offsets, dtype=wp.vec3, device=self.device))
        return self._gather

    def visibility_textures(self) -> tuple[np.ndarray, np.ndarray] | None:
        """For the shader (``SkyTexturesGL.upload_visibility``): the depth-moment atlas (Z·T, Y, X·T, 2)
        and the probes' relocation offsets (Z, Y, X, 3), float32; None without visibility."""
        if self.visibility is None:
            return None
        x, y, z = self.resolution
        return self.visibility[0], np.ascontiguousarray(self.visibility[1].reshape(z, y, x, 3), np.float32)

    def _gather_pass_start(self, sun) -> None:
        """The surfels' radiance from the volume as it is (the start of a pass: one more bounce)."""
        if self.config.gather_tolerance > 0.0:  # the light the pass starts from, for _pass_converged
            self._pass_before = self._coeffs.numpy().copy()
        grid = (self.grid_origin, self.cell_size, self.resolution, self.normal_offset_m)
        self._gather.update_surfels(self._coeffs, self._open_sky(), self._vis_wp, grid, sun,
                                    scene_sun_irradiance(self.scene, sun))

    def _pass_converged(self) -> bool:
        """After a complete pass: whether the passes have converged. Each pass adds the next bounce, so
        successive passes change the volume's light by Δ_k = r·Δ_(k−1), r the share of the light
        the scene passes on; the bounces still missing then sum to about Δ_k·r/(1−r) of the light,
        and the passes stop once that is under ``SkyConfig.gather_tolerance`` (an open courtyard
        after 5 passes, a closed white room after about 20)."""
        tol = self.config.gather_tolerance
        if tol <= 0.0:
            return False
        after = self._coeffs.numpy()
        change = float(np.abs(after - self._pass_before).sum() / max(float(np.abs(after).sum()), 1e-30))
        last, self._last_pass_change = self._last_pass_change, change
        if last is None:
            return False
        if last <= 0.0:
            return True
        r = min(change / last, 0.99)
        return change * r / (1.0 - r) < tol

    def _update_gather(self, sun, full: bool) -> bool:
        """"gather": follow a new sky (miss radiance, surfel shadow rays), then run passes over the
        volume until they converge (:meth:`_pass_converged`; ``gather_bounces`` at most) — all of them
        now when the volume was never lit or ``full``, else ``transfer_layers`` y-layers per call
        (0 = a whole pass)."""
        g = self._ensure_gather()
        cfg = self.config
        y = self.resolution[1]
        moved = self._gather_sun is None or angle_between_deg(self._gather_sun, sun) > cfg.rebuild_angle_deg
        whole = full or np.any(self.layer_versions < 0) or cfg.transfer_layers <= 0
        if self._gather_version != self.sky_version or moved:  # a new sky, or the sun moved (constant skies)
            g.set_sky(self.sky_map(), self.ground_radiance)
            # the surfels' shadow rays: all now for a whole pass, else a slice per update, so that each
            # pass of y updates (one y-layer each) re-traces every surfel once against the newest sun
            g.update_visibility(sun, parts=1 if whole else y)
            self._gather_version = self.sky_version
            self._gather_sun = np.array(sun, np.float64)
            self.gather_passes_left = cfg.gather_bounces
            self._last_pass_change = None
        elif not whole:
            g.refresh_visibility()  # the slices left after the last move of the sun
        if full or np.any(self.layer_versions < 0):
            while g.refresh_visibility():  # a whole pass needs every surfel's visibility current
                pass
            # a first lighting's passes: read back where this scene, sky and sun were lit before
            cached = (g.converged_path(self.sky_map(), self.ground_radiance, sun, scene_sun_irradiance(self.scene, sun),
                                       self.open_coefficients(), self.grid_origin, self.cell_size, self.resolution,
                                       self.normal_offset_m, self.gather_passes_left, self.config.gather_tolerance,
                                       self.visibility is not None, np.asarray(self._scale))
                      if np.all(self.layer_versions < 0) else None)
            if g.load_converged(cached, self._coeffs):
                self.gather_passes_left = 0
            while self.gather_passes_left > 0:
                self._gather_pass_start(sun)
                g.gather(self._coeffs, self._scale, self.resolution, 0, y)
                self.gather_passes_left -= 1
                if self._pass_converged():
                    self.gather_passes_left = 0
                if self.gather_passes_left == 0:
                    g.save_converged(cached, self._coeffs)
            self._next_layer = 0  # a pass starts at layer 0 (``_next_layer`` is where the current one is)
            self._host = None
            self.layer_versions[:] = self.sky_version
            self.updated_layers = [(0, y)]
            return True
        if self.gather_passes_left <= 0:
            return False
        per_update = cfg.transfer_layers if cfg.transfer_layers > 0 else y
        if self._next_layer == 0:
            self._gather_pass_start(sun)
        for start, n in self._next_slabs(min(per_update, y - self._next_layer)):  # never past the pass's end
            g.gather(self._coeffs, self._scale, self.resolution, start, n)
            self.layer_versions[start:start + n] = self.sky_version
            self.updated_layers.append((start, n))
        if self._next_layer == 0:  # the pass is complete
            self.gather_passes_left -= 1
            if self._pass_converged():
                self.gather_passes_left = 0
        self._host = None
        return True

    def _next_slabs(self, count: int) -> list[tuple[int, int]]:
        """The next ``count`` layers of the cycle as contiguous (first, n) slabs (a cycle that
        wraps is two), and the cycle moved on past them."""
        y = self.resolution[1]
        first = self._next_layer
        count = min(int(count), y)
        self._next_layer = (first + count) % y
        return [(start, n) for start, n in ((first, min(count, y - first)), (0, max(0, first + count - y))) if n]

    def _apply_transfer(self, first: int = 0, count: int | None = None) -> None:
        """Re-light y-layers ``first`` .. ``first + count - 1`` (default: all) from the current sky."""
        count = self.resolution[1] - first if count is None else count
        if self._projected is None or self._projected[0] != self.sky_version:
            sky = self.sky_map()
            if self._constant_sky:  # the 2×2 map is too coarse a quadrature for the projection
                sky = np.broadcast_to(sky[:1, :1], (64, 64, 3))
            self._projected = (self.sky_version, project_sky(sky, self.ground_radiance, self._transfer.functions))
        self._transfer.apply(self.grid_origin, self.cell_size, self.resolution, self._projected[1], self._scale,
                             self._coeffs, first, count)
        self._host = None
        self.layer_versions[first:first + count] = self.sky_version
        self.updated_layers.append((first, count))

    def rebuild(self, sun_direction=None) -> None:
        """Bring every layer up to date now (rebakes the sky map only if the sun moved)."""
        sky_map, _ = self._current_sky_map(self._sun(sun_direction))
        self.updated_layers = []
        if self.config.method == "gather":
            if self.gather_passes_left <= 0:
                self.gather_passes_left = self.config.gather_bounces
                self._last_pass_change = None
            self._update_gather(self._sun(sun_direction), full=True)
            return
        if self._transfer is not None:
            self._apply_transfer()
            return
        self._integrate(sky_map, 0, self.resolution[1])
        self.layer_versions[:] = self.sky_version
        self.updated_layers = [(0, self.resolution[1])]
        self._next_layer = 0

    @property
    def pending_layers(self) -> int:
        """Layers not yet integrated against the current sky (0: the volume is current)."""
        return int(np.count_nonzero(self.layer_versions != self.sky_version))

    # -- outputs

    def probe_positions(self) -> np.ndarray:
        """(P, 3) float64 probe positions, in storage order (z, y, x)."""
        x, y, z = self.resolution
        zz, yy, xx = np.meshgrid(np.arange(z), np.arange(y), np.arange(x), indexing="ij")
        g = np.stack([xx, yy, zz], axis=-1).reshape(-1, 3).astype(np.float64)
        return self.grid_origin + g * self.cell_size

    def coefficients(self) -> np.ndarray:
        """(Z, Y, X, 9, 3) float32 irradiance coefficients E_k per channel."""
        if self._host is None:
            x, y, z = self.resolution
            self._host = self._coeffs.numpy().reshape(z, y, x, COEFFS)
        return self._host.reshape(*self._host.shape[:3], 9, 3)

    def textures(self, layers: tuple[int, int] | None = None) -> list[np.ndarray]:
        """The 7 arrays of the paper's layout: 6 × (Z, Y, X, 4) + (Z, Y, X, 3) float32; with
        ``layers`` = (first, n) only that slab of y-layers, (Z, n, X, ·)."""
        c = self.coefficients()
        x, _, z = self.resolution
        if layers is None:
            return pack_sh_textures(c.reshape(-1, COEFFS), self.resolution)
        first, n = (int(v) for v in layers)
        slab = c[:, first:first + n]
        return pack_sh_textures(slab.reshape(-1, COEFFS), (x, n, z))

    def irradiance_wp(self, points, normals) -> np.ndarray:
        """(N, 3) float32 W·m⁻²: :meth:`irradiance` by a Warp kernel on the volume's device (the
        frame's sky-light VPLs: tens of thousands of G-buffer points per update)."""
        p = np.ascontiguousarray(np.asarray(points, np.float32).reshape(-1, 3))
        n = np.ascontiguousarray(np.asarray(normals, np.float32).reshape(-1, 3))
        out = wp.empty(len(p), dtype=wp.vec3, device=self.device)
        x, y, z = self.resolution
        dev = self.device
        launch(lookup_sky_irradiance, len(p),
               [self._coeffs, self._open_sky(), *self._vis_wp, wp.vec3(*self.grid_origin.astype(np.float32)),
                wp.vec3(*self.cell_size.astype(np.float32)), x, y, z, float(self.normal_offset_m),
                wp.array(p, dtype=wp.vec3, device=dev), wp.array(n, dtype=wp.vec3, device=dev), out], device=dev)
        return out.numpy()

    def irradiance(self, points, normals) -> np.ndarray:
        """(N, 3) float64 W·m⁻² at surface points with unit normals, as the shader evaluates it."""
        c = self.coefficients().reshape(*self.resolution[::-1], COEFFS)
        return eval_volume_irradiance(c, self.grid_origin, self.cell_size, self.resolution, self.normal_offset_m,
                                      points, normals, self.open_coefficients(), self.visibility)

    def glossy(self, points, normals, directions, shininess) -> np.ndarray:
        """(N, 3) float64 W·m⁻²·sr⁻¹: the volume's radiance around ``directions`` filtered by the Phong
        lobe of exponent ``shininess`` (scalar or (N,)), looked up at the surface points and normals,
        as the shader evaluates it (``SkyConfig.glossy``)."""
        c = self.coefficients().reshape(*self.resolution[::-1], COEFFS)
        return eval_volume_glossy(c, self.grid_origin, self.cell_size, self.resolution, self.normal_offset_m,
                                  points, normals, directions, shininess, self.open_coefficients(), self.visibility)

    def _open_sky(self):
        """The (27,) Warp array of :meth:`open_coefficients`, current."""
        self.open_coefficients()
        return self._open

"""Ray-traced irradiance probes: the sky volume's probes lit by the sky *and* by the light the scene
bounces, through the real geometry (``SkyConfig.method = "gather"``; beyond the paper, §7–§8).

Why: the paper lights its probes with the sky through occlusion quads and leaves all bounced light
to the light propagation volumes. Measured against path-traced references, the LPV is where the
error sits — it over-lights surfaces next to a bright patch, a lit plane lights itself, light
leaks through thin walls, and it carries one bounce where a courtyard of pale walls or a closed room
gets a third of its indirect light from later ones. Here the probes instead *gather*: each casts
``gather_rays`` rays through the scene's kd-tree once (the geometry is static), and each frame a
probe's radiance along a ray is

    a miss:  the sky map (ω.y ≥ 0) or the ground below the horizon (``SkyVolume.ground_radiance``);
    a hit:   the Lambertian radiance leaving the surface element ("surfel") the ray hit,
             B_s = ρ_s/π · (E_sun · max(0, n_s·l) · V_s + E_volume(p_s, n_s)),

projected onto L2 SH and convolved with the clamped cosine as the sky volume's own probes are
(E_k = Â_l·w_l·4π/R·Σ_i L(ω_i)·Y_k(ω_i)). E_volume is the probe volume itself at the surfel, so
each pass over the volume adds one more bounce of sky and sun light (radiosity by gathering: after
k passes the volume holds k bounces; ``gather_bounces`` passes follow every change of the sun).

The surfels' albedo is the diffuse albedo plus the energy of the material's Phong lobe k_s
(``glossy_energy``, materials that are neither mirrors nor transparent): a lobe as broad as the
built-in scenes' (exponents 8–24) sends its k_s of the light around as a diffuse surface would, and
the reference reflects it. Rays are bent through up to ``transmissions`` transparent interfaces
(``SkyConfig.gather_transmissions``; the window panes: the tracer's ``transmissions``) instead of
stopping on the glass as if it were an opaque diffuse wall.

Surfels: the rays' hit points quantised to cubes of ``gather_surfel_size`` metres (counted from the
corner of the scene's bounding box) and the dominant axis of their normal (so the two faces of a
thin wall are two surfels), each with the mean position, normal and albedo (the tracer's
ray-cone-filtered texture × material albedo) of its hits. V_s is one shadow ray towards the sun's
centre through the kd-tree, from one of the surfel's own hits, the one nearest a point of its square
fixed per surfel (``shadow_origins``: from the centres, which lie on a grid, a straight shadow edge
flipped a whole row at once; from the square's point itself, a surfel at a corner or an edge started
its ray inside the wall beside it or beyond the edge), re-traced when the sky map is rebaked (the
sun moved). Rays that hit a back face (the probe sits inside or under geometry) mark the probe: a
probe with more than ``BACKFACE_LIMIT`` of its rays on back faces is moved by up to half a cell to a
free spot (DDGI's probe relocation, Majercik et al. 2019); its texel stays on the grid. Each probe is
first judged on every ``RELOCATION_STRIDE``-th ray, as a spot to move to is, so that a probe inside
geometry is traced in full only where it moves to (about half of a room's probes next to its
surfaces). Directions:
``DIRECTION_SETS`` spherical Fibonacci sets of R directions, each turned by its own random rotation;
probe p uses set p mod ``DIRECTION_SETS`` (neighbouring probes sample different directions, so the
quantisation of one set does not line up across the volume).

Probes no lookup reads (DDGI's probe classification, Majercik et al. 2021): a lookup at a surface
point reads the 8 probes around it, moved by the normal offset, so a probe whose cells no triangle
comes within that offset of (the air in the middle of a room, 60 % of the breakfast room's probes)
is never read. Those probes are not traced or gathered (``reachable_probes``; their coefficients are
zeros); a surfel's own lookup, from its mean position, is checked too.

Costs (``benchmarks/``): the rays are traced once per scene (``ProbeGather._build``), in chunks that
are merged into surfels and depth moments as they come (the hits of every ray never exist at once);
the result is cached on disk, and so are the coefficients after a first lighting's passes
(``converged_path``); a pass is one surfel update (a volume lookup per surfel) and one gather of R
loads per probe.
"""

from __future__ import annotations

import hashlib
import math
import os
from pathlib import Path

import numpy as np
import warp as wp
from tqdm import tqdm

from serenity.kernels.atmosphere_ref import sample_sky_map_np
from serenity.kernels.kdtree_build import cache_dir
from serenity.kernels.launch import launch
from serenity.kernels.sh import eval_sh9, sh_basis, vec9
from serenity.memory import mapped_large_blocks
from serenity.scene.model import IDENTITY_UV
from serenity.threads import single_threaded_blas

wp.set_module_options({"enable_backward": False})

#: rotated direction sets the probes cycle through (probe index mod this)
DIRECTION_SETS = 8
#: a probe with more than this fraction of its rays on back faces sits inside geometry
BACKFACE_LIMIT = 0.1
#: a relocation spot is judged on every this-many-th ray of the probe's set before it is traced in full
RELOCATION_STRIDE = 8
#: relocation offsets tried for such a probe, in cells (first the one up: probes under a floor)
RELOCATIONS = ((0.0, 0.45, 0.0), (0.45, 0.0, 0.0), (-0.45, 0.0, 0.0), (0.0, 0.0, 0.45), (0.0, 0.0, -0.45),
               (0.0, -0.45, 0.0), (0.3, 0.3, 0.3), (-0.3, 0.3, -0.3))

_INV_PI = wp.constant(1.0 / math.pi)


#: bump when the traced data or its cached layout changes
FORMAT_VERSION = 5
#: host work over every probe ray (millions) runs in slices of this many, so that no temporary
#: spans them all
_SLICE = 1 << 20
SURFEL_SHADOW_SPREAD = 0.5
"""Where in its square a surfel's shadow ray may start (``shadow_origins``), as a fraction of the
square's side around its mean position: far enough apart that a straight shadow edge crosses a row of
surfels one at a time, near enough the mean that the one ray stands for the surfel (FLIP of
``traced-probes`` at 320×180: the full square 0.0571 courtyard / 0.0433 Cornell box, half 0.0565 /
0.0430, the mean itself 0.0560 / 0.0426)."""
#: traces of at least this many rays are cached on disk (``cache_dir()/probegather-<key>.npz``)
CACHE_MIN_RAYS = 1_000_000
#: rays the probes' trace hands the tracer per call (its G-buffer for those rays is the memory peak)
TRACE_CHUNK_RAYS = 1 << 18
#: a trace of at least this many rays shows a progress bar
PROGRESS_RAYS = 4_000_000

#: the probes' depth moments (visibility): an octahedral map of VIS_OCT² texels per probe, stored with a
#: one-texel border as a VIS_TILE² tile; each texel averages the rays' hit distances d and d² weighted
#: by max(0, cos)^VIS_POWER around its direction; a miss (or a hit farther) counts as VIS_MAX_CELLS cells
VIS_OCT = 8
VIS_TILE = VIS_OCT + 2
VIS_POWER = 16.0
VIS_MAX_CELLS = 2.0
#: a probe's weight below this is crushed (w³/VIS_CRUSH²), as DDGI does, so that a probe the point
#: cannot see adds next to nothing
VIS_CRUSH = 0.2
#: the visibility test looks from the probe at p + VIS_BIAS_CELLS·(smallest cell edge)·n, however small
#: the lookup's own normal offset: a point on the surface itself sits at the probe's mean depth there
VIS_BIAS_CELLS = 0.5

#: beyond the grid's sides and top, the lookup fades to the open sky's coefficients over this many cells
OPEN_FADE_CELLS = 2.0
#: the probes the lookups can read (``reachable_probes``) are found around the triangles within the
#: lookup's normal offset and this many cells more (rasterised positions, normal-mapped normals)
REACH_MARGIN_CELLS = 0.02
#: a triangle whose reach spans more probes than this is tested against each one's distance to its plane
_REACH_PLANE_PROBES = 64
#: rounds of tracing the probes that the surfels' own lookups read beyond the active ones (``ProbeGather``)
_REACH_ROUNDS = 3


@wp.func
def oct_encode(d: wp.vec3) -> wp.vec2:
    """Octahedral map of a unit direction (y up) onto [-1, 1]²: (x, z) / (|x| + |y| + |z|), the
    lower half folded over the diagonals."""
    s = wp.abs(d[0]) + wp.abs(d[1]) + wp.abs(d[2])
    x = d[0] / s
    z = d[2] / s
    if d[1] < 0.0:
        fx = (1.0 - wp.abs(z)) * wp.where(x >= 0.0, 1.0, -1.0)
        fz = (1.0 - wp.abs(x)) * wp.where(z >= 0.0, 1.0, -1.0)
        x = fx
        z = fz
    return wp.vec2(x, z)


@wp.func
def probe_visibility(vis: wp.array3d(dtype=wp.vec2), offsets: wp.array(dtype=wp.vec3), probe: int, xi: int,
                     yi: int, zi: int, grid_pos: wp.vec3, p: wp.vec3, x: wp.vec3, n: wp.vec3) -> float:
    """DDGI's weight of probe ``probe`` (grid cell xi, yi, zi at ``grid_pos``, moved by its relocation
    offset) for surface point p with normal n, looked up at x: the smooth back-face weight
    ((n·ω_p + 1)/2)² + 0.2 towards the probe, times the Chebyshev bound that the probe sees x (its
    depth moments bilinear at the direction probe → x), crushed below VIS_CRUSH (module docstring)."""
    q = grid_pos + offsets[probe]
    to_probe = wp.normalize(q - p)
    b = (wp.dot(to_probe, n) + 1.0) * 0.5
    w = b * b + 0.2
    d = x - q
    dist = wp.length(d)
    uv = oct_encode(d / wp.max(dist, 1.0e-9))
    tu = float(xi * VIS_TILE + 1) + (uv[0] * 0.5 + 0.5) * float(VIS_OCT) - 0.5
    tv = float(zi * VIS_TILE + 1) + (uv[1] * 0.5 + 0.5) * float(VIS_OCT) - 0.5
    u0 = int(wp.floor(tu))
    v0 = int(wp.floor(tv))
    fu = tu - float(u0)
    fv = tv - float(v0)
    lo_u = xi * VIS_TILE
    lo_v = zi * VIS_TILE
    ua = wp.clamp(u0, lo_u, lo_u + VIS_TILE - 1)
    ub = wp.clamp(u0 + 1, lo_u, lo_u + VIS_TILE - 1)
    va = wp.clamp(v0, lo_v, lo_v + VIS_TILE - 1)
    vb = wp.clamp(v0 + 1, lo_v, lo_v + VIS_TILE - 1)
    m = (vis[va, yi, ua] * (1.0 - fu) + vis[va, yi, ub] * fu) * (1.0 - fv) \
        + (vis[vb, yi, ua] * (1.0 - fu) + vis[vb, yi, ub] * fu) * fv
    if dist > m[0]:
        var = wp.abs(m[1] - m[0] * m[0])
        t = dist - m[0]
        c = var / (var + t * t + 1.0e-12)
        w = w * wp.max(c * c * c, 0.0)
    w = wp.max(w, 1.0e-6)
    if w < VIS_CRUSH:
        w = w * w * w / (VIS_CRUSH * VIS_CRUSH)
    return w


@wp.func
def volume_irradiance(coeffs: wp.array2d(dtype=float), open_sky: wp.array(dtype=float),
                      vis: wp.array3d(dtype=wp.vec2), offsets: wp.array(dtype=wp.vec3), origin: wp.vec3,
                      cell: wp.vec3, res_x: int, res_y: int, res_z: int, normal_offset: float, p: wp.vec3,
                      n: wp.vec3) -> wp.vec3:
    """Irradiance of the volume at a surface point (sky.glsl's arithmetic): trilinear coefficients
    at p + offset·n — each probe's weight also times its visibility (:func:`probe_visibility`) when
    ``vis`` holds the probes' depth moments (an empty array: plain trilinear) — faded to ``open_sky``
    (27, the open sky's) beyond the grid's sides and top, evaluated at n, clamped at 0."""
    x = p + n * normal_offset
    gr = wp.cw_div(x - origin, cell)
    beyond = wp.max(wp.max(wp.max(-gr[0], gr[0] - float(res_x - 1)), wp.max(-gr[2], gr[2] - float(res_z - 1))),
                    gr[1] - float(res_y - 1))
    w_open = wp.clamp(beyond / OPEN_FADE_CELLS, 0.0, 1.0)
    g = wp.vec3(wp.clamp(gr[0], 0.0, float(res_x - 1)), wp.clamp(gr[1], 0.0, float(res_y - 1)),
                wp.clamp(gr[2], 0.0, float(res_z - 1)))
    x0 = int(wp.floor(g[0]))
    y0 = int(wp.floor(g[1]))
    z0 = int(wp.floor(g[2]))
    ax = g[0] - float(x0)
    ay = g[1] - float(y0)
    az = g[2] - float(z0)
    y = eval_sh9(n)
    e = wp.vec3()
    wsum = float(0.0)
    use_vis = vis.shape[0] > 0
    x_vis = p + n * (VIS_BIAS_CELLS * wp.min(wp.min(cell[0], cell[1]), cell[2]))
    for corner in range(8):
        dx = corner & 1
        dy = (corner >> 1) & 1
        dz = corner >> 2
        xi = wp.min(x0 + dx, res_x - 1)
        yi = wp.min(y0 + dy, res_y - 1)
        zi = wp.min(z0 + dz, res_z - 1)
        w = wp.where(dx == 1, ax, 1.0 - ax) * wp.where(dy == 1, ay, 1.0 - ay) * wp.where(dz == 1, az, 1.0 - az)
        probe = (zi * res_y + yi) * res_x + xi
        if use_vis:
            q = origin + wp.cw_mul(wp.vec3(float(xi), float(yi), float(zi)), cell)
            w = w * probe_visibility(vis, offsets, probe, xi, yi, zi, q, p, x_vis, n)
        wsum += w
        for k in range(9):
            wk = w * y[k]
            e += wp.vec3(coeffs[probe, 3 * k], coeffs[probe, 3 * k + 1], coeffs[probe, 3 * k + 2]) * wk
    if use_vis:
        e = e / wp.max(wsum, 1.0e-30)
    e_open = wp.vec3()
    for k in range(9):
        e_open += wp.vec3(open_sky[3 * k], open_sky[3 * k + 1], open_sky[3 * k + 2]) * y[k]
    e = e * (1.0 - w_open) + e_open * w_open
    return wp.vec3(wp.max(e[0], 0.0), wp.max(e[1], 0.0), wp.max(e[2], 0.0))


@wp.kernel
def surfel_radiance(
    # inputs
    positions: wp.array(dtype=wp.vec3),
    normals: wp.array(dtype=wp.vec3),
    albedo: wp.array(dtype=wp.vec3),
    sun_visible: wp.array(dtype=float),
    sun_dir: wp.vec3,
    sun_irradiance: wp.vec3,
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
    # outputs
    radiance: wp.array(dtype=wp.vec3),
    offset: int,
):
    """B_s = ρ_s/π·(E_sun·max(0, n·l)·V_s + E_volume(p_s, n_s)) (module docstring)."""
    i = wp.tid() + offset
    n = normals[i]
    e = volume_irradiance(coeffs, open_sky, vis, offsets, origin, cell, res_x, res_y, res_z, normal_offset,
                          positions[i], n)
    e += sun_irradiance * (wp.max(wp.dot(n, sun_dir), 0.0) * sun_visible[i])
    radiance[i] = wp.cw_mul(albedo[i], e) * _INV_PI


@wp.kernel
def gather_probes(
    # inputs
    res_x: int,
    res_y: int,
    first_layer: int,
    rays: int,
    active: wp.array(dtype=wp.int32),
    surfel: wp.array2d(dtype=wp.int32),
    surfel_radiance: wp.array(dtype=wp.vec3),
    miss_radiance: wp.array2d(dtype=wp.vec3),
    basis: wp.array2d(dtype=vec9),
    scale: vec9,
    # outputs
    coeffs: wp.array2d(dtype=float),
    offset: int,
):
    """The i-th probe of the y-layers from ``first_layer`` on (x fastest, then z; stored (z, y, x)):
    E_k = scale_k·4π/R·Σ_r L_r·Y_k(ω_r), L_r the radiance of the surfel ray r hit (surfel[p, r] ≥ 0),
    the miss radiance of the probe's direction set (−1), or 0 (−2: a back face); zeros for a probe
    that is not ``active`` (no lookup reads it: :func:`reachable_probes`)."""
    t = wp.tid() + offset
    res_z = surfel.shape[0] // (res_x * res_y)
    slab = res_x * res_z
    y = first_layer + t // slab
    rem = t - (t // slab) * slab
    z = rem // res_x
    x = rem - z * res_x
    probe = (z * res_y + y) * res_x + x
    if active[probe] == 0:
        for k in range(27):
            coeffs[probe, k] = 0.0
        return
    s = probe % basis.shape[0]
    acc_r = vec9()
    acc_g = vec9()
    acc_b = vec9()
    for r in range(rays):
        j = surfel[probe, r]
        radiance = wp.vec3()
        if j >= 0:
            radiance = surfel_radiance[j]
        elif j == -1:
            radiance = miss_radiance[s, r]
        b = basis[s, r]
        acc_r += b * radiance[0]
        acc_g += b * radiance[1]
        acc_b += b * radiance[2]
    w = 4.0 * wp.pi / float(rays)
    for k in range(9):
        sk = scale[k] * w
        coeffs[probe, 3 * k + 0] = acc_r[k] * sk
        coeffs[probe, 3 * k + 1] = acc_g[k] * sk
        coeffs[probe, 3 * k + 2] = acc_b[k] * sk


def oct_decode_np(uv: np.ndarray) -> np.ndarray:
    """(N, 3) unit directions of octahedral coordinates (N, 2) in [-1, 1]² (inverse of oct_encode)."""
    u, v = uv[:, 0].astype(np.float64), uv[:, 1].astype(np.float64)
    y = 1.0 - np.abs(u) - np.abs(v)
    x, z = u.copy(), v.copy()
    low = y < 0
    x[low] = (1.0 - np.abs(v[low])) * np.where(u[low] >= 0, 1.0, -1.0)
    z[low] = (1.0 - np.abs(u[low])) * np.where(v[low] >= 0, 1.0, -1.0)
    d = np.stack([x, y, z], axis=1)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def oct_encode_np(d: np.ndarray) -> np.ndarray:
    """(N, 2) octahedral coordinates of unit directions (N, 3): the host twin of oct_encode."""
    d = np.asarray(d, np.float64)
    s = np.abs(d).sum(axis=1)
    x, z = d[:, 0] / s, d[:, 2] / s
    low = d[:, 1] < 0
    fx = (1.0 - np.abs(z)) * np.where(x >= 0, 1.0, -1.0)
    fz = (1.0 - np.abs(x)) * np.where(z >= 0, 1.0, -1.0)
    return np.stack([np.where(low, fx, x), np.where(low, fz, z)], axis=1)


def oct_texel_directions(size: int) -> np.ndarray:
    """(size², 3) the directions of an octahedral map's texel centres, row-major (v, u)."""
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    v, u = np.meshgrid(c, c, indexing="ij")
    return oct_decode_np(np.stack([u.ravel(), v.ravel()], axis=1))


def shadow_ray_offsets(normals: np.ndarray, size: float) -> np.ndarray:
    """(S, 3) float64: where in its square each surfel's shadow ray starts, relative to its mean
    position: surfel i's point of the R2 low-discrepancy sequence (Roberts 2018), frac(½ + i·(1/g, 1/g²))
    with g the plastic number, on the size × size square across its normal. The surfels' centres lie
    on a grid; from the centres, a roof's straight shadow edge moving with the sun crossed a whole row
    of them in one frame and the gathered light popped (``docs/stability.md``). Surfels are numbered
    along the grid's z, then y, then x (``_make_surfels``), so the surfels of a row get points spread
    evenly across the square, and the edge crosses them one at a time."""
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    g = 1.32471795724474602596
    i = np.arange(len(n), dtype=np.float64)[:, None]
    uv = ((0.5 + i * np.array([[1.0 / g, 1.0 / (g * g)]])) % 1.0 - 0.5) * float(size)
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(n, helper)
    t1 /= np.maximum(np.linalg.norm(t1, axis=1, keepdims=True), 1e-12)
    t2 = np.cross(n, t1)
    return uv[:, :1] * t1 + uv[:, 1:] * t2


def shadow_origins(positions: np.ndarray, surfel: np.ndarray, means: np.ndarray, normals: np.ndarray,
                   size: float) -> np.ndarray:
    """(S, 3) float64: where each surfel's shadow ray starts: of the hits ``positions`` (N, 3) that
    make surfel ``surfel`` (N,), the one nearest the surfel's point (``means`` + ``SURFEL_SHADOW_SPREAD``
    × :func:`shadow_ray_offsets`). A hit lies on the surface, where a point of the square may not: at
    a corner or an edge it lies inside the wall beside the surfel or beyond the edge."""
    pos = np.asarray(positions).reshape(-1, 3)
    inv = np.asarray(surfel).reshape(-1)
    means = np.asarray(means, np.float64)
    target = (means + SURFEL_SHADOW_SPREAD * shadow_ray_offsets(normals, size)).astype(np.float32)

    def d2(a):  # the squared distances of hits a .. a + _SLICE to their surfel's point
        diff = pos[a:a + _SLICE].astype(np.float32) - target[inv[a:a + _SLICE]]
        return np.einsum("ij,ij->i", diff, diff)

    # in slices, twice (the nearest, then which hit it is): millions of hits as float64 (N, 3) cost
    # a GB, and even one float per hit is tens of MB
    nearest = np.full(len(means), np.inf, np.float32)
    for a in range(0, len(pos), _SLICE):
        np.minimum.at(nearest, inv[a:a + _SLICE], d2(a))  # O(N): a sort of millions of hits cost seconds
    idx = np.concatenate([np.flatnonzero(d2(a) == nearest[inv[a:a + _SLICE]]) + a
                          for a in range(0, len(pos), _SLICE)] or [np.zeros(0, np.int64)])
    # (a tie keeps the last of its hits)
    out = means.copy()
    out[inv[idx]] = pos[idx]
    return out



def _hit_distances(hits: dict, origins: np.ndarray, rays: int, cap: float) -> np.ndarray:
    """(P, R) float32 the distance of each ray's hit (front or back face) in ``hits`` (P·R rays,
    probe-major) from its probe at ``origins`` (P, 3); a miss or a hit beyond ``cap`` at ``cap``."""
    diff = hits["position"].reshape(-1, rays, 3) - origins[:, None, :].astype(np.float32)
    d = np.sqrt(np.einsum("prc,prc->pr", diff, diff))
    any_hit = (hits["hit"] | hits["back"]).reshape(-1, rays)
    return np.where(any_hit, np.minimum(d, np.float32(cap)), np.float32(cap)).astype(np.float32)


class _MomentWeights:
    """The probes' depth moments (module constants) as a matrix product per direction set: texel t of
    a probe of set s is Σ_r W[s, t, r]·(d_r, d_r²) / Σ_r W[s, t, r], W = max(0, ω_t·ω_r)^VIS_POWER,
    the same for every probe of the set."""

    def __init__(self, dirs: np.ndarray):
        texels = oct_texel_directions(VIS_OCT).astype(np.float32).astype(np.float64)
        c = np.einsum("tc,src->str", texels, np.asarray(dirs, np.float64))
        self.weights = np.where(c > 0.0, np.maximum(c, 0.0) ** VIS_POWER, 0.0).astype(np.float32)  # (S, T, R)
        self.norm = np.maximum(self.weights.sum(axis=2, dtype=np.float64), 1e-12).astype(np.float32)  # (S, T)

    def moments(self, dist: np.ndarray, sets: np.ndarray) -> np.ndarray:
        """(P, T, 2) float32 the moments of P probes' ray distances ``dist`` (P, R) of sets ``sets`` (P,)."""
        out = np.empty((len(dist), self.weights.shape[1], 2), np.float32)
        for k in np.unique(sets):
            i = np.flatnonzero(sets == k)
            d = dist[i]
            w = self.weights[k].T
            out[i, :, 0] = (d @ w) / self.norm[k]
            out[i, :, 1] = ((d * d) @ w) / self.norm[k]
        return out


def surfel_keys(positions: np.ndarray, normals: np.ndarray, anchor: np.ndarray, size: float) -> np.ndarray:
    """(N,) int64 the surfel of each hit: its cube of ``size`` metres counted from ``anchor`` and the
    dominant axis and sign of its normal (sorted by key: along z, then y, then x)."""
    axis = np.argmax(np.abs(normals), axis=1)
    side = normals[np.arange(len(normals)), axis] > 0
    key = axis.astype(np.int64) * 2 + side
    for c, prime in ((2, 1), (1, 1_000_033), (0, 1_000_033 * 1_000_003)):
        key += np.floor((positions[:, c] - anchor[c]) / size).astype(np.int64) * (6 * prime)
    return key


class _SurfelMerge:
    """Ray hits merged into surfels chunk by chunk (``surfel_keys``): each chunk's hits are summed
    per surfel as they come, ``finish`` merges the chunks' sums; only the hits' positions (for the
    shadow rays' origins) and each ray's surfel outlive their chunk."""

    def __init__(self, rays: int, anchor: np.ndarray, size: float):
        if rays >= 2**31:
            raise ValueError(f"{rays} probe rays: at most 2**31 - 1")
        self.anchor, self.size = np.asarray(anchor, np.float64), float(size)
        self.surfel = np.full(rays, -1, np.int32)  # per ray: a chunk's surfel (``merged``), -2 a back face
        self.keys, self.sums = np.zeros(0, np.int64), np.zeros((0, 10))  # the surfels so far, sorted by key
        self.merged = np.zeros(0, np.int32)  # each chunk's surfel (numbered across chunks): its index in keys
        self.hit_positions = np.empty((rays, 3), np.float32)  # filled from the front (pages as written)
        self.hit_surfel = np.empty(rays, np.int32)
        self.hits = 0

    def add(self, rows, hit, back, positions, normals, albedo) -> None:
        """The rays ``rows`` (a slice or indices, probe-major) with their hit and back-face masks and hits;
        the rays of neither mask are left as they are."""
        idx = np.flatnonzero(hit)
        p, n = positions[idx], normals[idx]
        keys, inv = np.unique(surfel_keys(p, n, self.anchor, self.size), return_inverse=True)
        inv = inv.reshape(-1)
        m = len(keys)
        sums = np.empty((m, 10))
        sums[:, 0] = np.bincount(inv, minlength=m)
        for j, a in enumerate((p, n, albedo[idx])):
            for c in range(3):
                sums[:, 1 + 3 * j + c] = np.bincount(inv, a[:, c], m)
        # merged into the surfels so far (tens of thousands): their sums, and where each moved
        old = len(self.keys)
        self.keys, both = np.unique(np.concatenate([self.keys, keys]), return_inverse=True)
        both = both.reshape(-1).astype(np.int32)
        every = np.concatenate([self.sums, sums])
        self.sums = np.stack([np.bincount(both, every[:, c], len(self.keys)) for c in range(10)], axis=1)
        local = (inv + len(self.merged)).astype(np.int32)
        self.merged = np.concatenate([both[:old][self.merged], both[old:]])
        rays = self.surfel[rows]
        if isinstance(rows, slice):  # a view: written in place
            rays[idx] = local
            rays[back] = -2
        else:
            rays[idx] = local
            rays[back] = -2
            self.surfel[rows] = rays
        h = self.hits
        self.hit_positions[h:h + len(idx)] = p
        self.hit_surfel[h:h + len(idx)] = local
        self.hits += len(idx)

    def means(self) -> tuple[np.ndarray, np.ndarray]:
        """The surfels so far: mean positions and (unit) mean normals, float64 (S, 3) each."""
        cnt = np.maximum(self.sums[:, :1], 1.0)
        sn = self.sums[:, 4:7] / cnt
        sn /= np.maximum(np.linalg.norm(sn, axis=1, keepdims=True), 1e-12)
        return self.sums[:, 1:4] / cnt, sn

    def finish(self):
        """(surfel per ray (N,) int32: ≥ 0, −1 a miss, −2 a back face; the surfels' mean positions,
        normals and albedo, float64 (S, 3) each; their shadow rays' origins, ``shadow_origins``)."""
        total, inv = self.sums, self.merged
        sp, sn = self.means()
        sa = total[:, 7:10] / np.maximum(total[:, :1], 1.0)
        surfel, hit_surfel = self.surfel, self.hit_surfel[:self.hits]
        for a in range(0, len(surfel), _SLICE):  # in place, in slices: no temporaries of every ray
            s = surfel[a:a + _SLICE]
            hit = s >= 0
            s[hit] = inv[s[hit]]
            h = hit_surfel[a:a + _SLICE]
            h[:] = inv[h]
        origins = shadow_origins(self.hit_positions[:self.hits], hit_surfel, sp, sn, self.size)
        self.surfel = self.hit_positions = self.hit_surfel = None
        return surfel, sp, sn, sa, origins


def visibility_atlas(moments: np.ndarray, resolution) -> np.ndarray:
    """The probes' depth moments ((P, VIS_OCT², 2), storage order z, y, x) as one (Z·T, Y, X·T, 2)
    float32 array (T = VIS_TILE): probe (x, y, z)'s tile at [z·T : z·T + T, y, x·T : x·T + T], its map
    inside a one-texel border copied by the octahedral map's wrap (an edge texel's neighbour across
    the edge is the mirrored texel of the same edge; a corner's is the opposite corner), so that a
    bilinear tap inside the tile filters across the map's seams."""
    x, y, z = (int(a) for a in resolution)
    o, t = VIS_OCT, VIS_TILE
    m = np.asarray(moments, np.float32).reshape(z, y, x, o, o, 2)  # (..., v, u)
    tile = np.empty((z, y, x, t, t, 2), np.float32)
    tile[:, :, :, 1:-1, 1:-1] = m
    tile[:, :, :, 0, 1:-1] = m[:, :, :, 0, ::-1]
    tile[:, :, :, -1, 1:-1] = m[:, :, :, -1, ::-1]
    tile[:, :, :, 1:-1, 0] = m[:, :, :, ::-1, 0]
    tile[:, :, :, 1:-1, -1] = m[:, :, :, ::-1, -1]
    tile[:, :, :, 0, 0] = m[:, :, :, -1, -1]
    tile[:, :, :, 0, -1] = m[:, :, :, -1, 0]
    tile[:, :, :, -1, 0] = m[:, :, :, 0, -1]
    tile[:, :, :, -1, -1] = m[:, :, :, 0, 0]
    # (z, y, x, v, u) -> (z, v, y, x, u) -> (Z·T, Y, X·T)
    return np.ascontiguousarray(tile.transpose(0, 3, 1, 2, 4, 5).reshape(z * t, y, x * t, 2))


def scene_key(scene) -> str:
    """Digest of what a probe's traced rays depend on in ``scene``: its merged geometry and its
    materials (albedo, textures, Phong and glass parameters)."""
    h = hashlib.blake2b(digest_size=20)
    for a in scene.merged():
        h.update(np.ascontiguousarray(a).tobytes())
    for m in scene.materials:
        h.update(f"{m.name}|{m.specular}|{m.shininess}|{m.reflectivity}|{m.transparency}|{m.ior}".encode())
        h.update(np.ascontiguousarray(m.albedo, np.float64).tobytes())
        if m.albedo_texture is not None:
            h.update(np.ascontiguousarray(m.albedo_texture.mips[0]).tobytes())
        if m.alpha_tested or m.normal_texture is not None or not np.array_equal(m.albedo_uv_transform, IDENTITY_UV):
            # cut-outs, normal maps and uv transforms change what the rays hit and see (only such
            # scenes' keys change)
            h.update(f"|cutout {m.alpha_tested} {m.alpha} {m.alpha_cutoff} {m.normal_scale}".encode())
            h.update(np.ascontiguousarray(np.concatenate([m.albedo_uv_transform, m.normal_uv_transform])).tobytes())
            if m.normal_texture is not None:
                h.update(np.ascontiguousarray(m.normal_texture.mips[0]).tobytes())
    return h.hexdigest()


def lookup_probes(points: np.ndarray, origin, cell, resolution) -> np.ndarray:
    """(N, 8) int64: the probes (storage order z, y, x) the lookup at ``points`` (N, 3), already moved
    by the normal offset, reads: the corners of its cell, clamped to the grid (:func:`volume_irradiance`)."""
    res = np.asarray(resolution, np.int64)
    g = np.clip((np.asarray(points, np.float64).reshape(-1, 3) - np.asarray(origin, np.float64))
                / np.asarray(cell, np.float64), 0.0, res - 1)
    i0 = np.floor(g).astype(np.int64)
    i1 = np.minimum(i0 + 1, res - 1)
    out = np.empty((len(g), 8), np.int64)
    for corner in range(8):
        c = np.where([(corner >> k) & 1 for k in range(3)], i1, i0)
        out[:, corner] = (c[:, 2] * res[1] + c[:, 1]) * res[0] + c[:, 0]
    return out


def reach_key(reach: float, resolution) -> str:
    """What :func:`reachable_probes` (and the surfels' check, ``ProbeGather``) depend on beyond the scene
    and the probes' positions: the cache key of a trace whose active probes are made on demand."""
    return f"reach {float(reach)!r} {tuple(int(r) for r in resolution)} {REACH_MARGIN_CELLS!r} " \
           f"{_REACH_PLANE_PROBES} {_REACH_ROUNDS}"


def reachable_probes(vertices: np.ndarray, faces: np.ndarray, origin, cell, resolution, reach: float) -> np.ndarray:
    """(P,) bool in storage order (z, y, x): the probes a lookup at a point of the triangles
    ``vertices[faces]`` can read. The lookup at surface point p with unit normal n reads the 8 probes
    around x = p + offset·n (:func:`volume_irradiance`, sky.glsl), in grid units clamped to the grid;
    x lies within ``reach`` (the offset and a margin) of a triangle, so the triangles' boxes grown by
    ``reach``, clamped to the grid, hold every such x, and the probes around them are all a lookup can
    read. A triangle whose grown box spans more than ``_REACH_PLANE_PROBES`` probes and lies inside the
    grid keeps only the probes within one cell (each axis) and ``reach`` of its plane."""
    x, y, z = (int(a) for a in resolution)
    res = np.array([x, y, z])
    origin, cell = np.asarray(origin, np.float64), np.asarray(cell, np.float64)
    out = np.zeros(x * y * z, bool)
    faces = np.asarray(faces).reshape(-1, 3)
    if not len(faces):
        return out
    for a in range(0, len(faces), _SLICE // 4):  # (N, 3, 3) float64 of every triangle at once: 18 MB per 262k
        tri = np.asarray(vertices)[faces[a:a + _SLICE // 4]].astype(np.float64)
        glo = (tri.min(axis=1) - reach - origin) / cell
        ghi = (tri.max(axis=1) + reach - origin) / cell
        lo = np.floor(np.clip(glo, 0.0, res - 1)).astype(np.int64)
        hi = np.minimum(np.floor(np.clip(ghi, 0.0, res - 1)).astype(np.int64) + 1, res - 1)
        span = hi - lo + 1
        big = (span.prod(axis=1) > _REACH_PLANE_PROBES) & np.all(glo >= 0.0, axis=1) & np.all(ghi <= res - 1, axis=1)
        small = ~big
        # the small boxes as a 3D difference array: +-1 at their 8 corners, summed along each axis
        diff = np.zeros((z + 1, y + 1, x + 1), np.int64)
        lo_s, hi_s = lo[small], hi[small] + 1
        for corner in range(8):
            c = np.where([(corner >> k) & 1 for k in range(3)], hi_s, lo_s)
            sign = -1 if bin(corner).count("1") % 2 else 1
            flat = (c[:, 2] * (y + 1) + c[:, 1]) * (x + 1) + c[:, 0]
            diff.reshape(-1)[:] += sign * np.bincount(flat, minlength=diff.size)
        out |= (diff.cumsum(0).cumsum(1).cumsum(2)[:z, :y, :x] > 0).reshape(-1)
        for t in np.flatnonzero(big):
            n = np.cross(tri[t, 1] - tri[t, 0], tri[t, 2] - tri[t, 0])
            n /= max(float(np.linalg.norm(n)), 1e-30)
            kz, ky, kx = np.meshgrid(*(np.arange(lo[t, k], hi[t, k] + 1) for k in (2, 1, 0)), indexing="ij")
            q = origin + np.stack([kx, ky, kz], axis=-1).reshape(-1, 3) * cell
            near = np.abs((q - tri[t, 0]) @ n) <= float(np.abs(n) @ cell) + reach
            out[((kz.reshape(-1) * y + ky.reshape(-1)) * x + kx.reshape(-1))[near]] = True
    return out


def direction_sets(rays: int, sets: int = DIRECTION_SETS, seed: int = 0) -> np.ndarray:
    """(sets, rays, 3) float64 unit directions: a spherical Fibonacci set of ``rays`` points, turned
    by one random rotation per set."""
    i = np.arange(rays) + 0.5
    z = 1.0 - 2.0 * i / rays
    phi = math.pi * (1.0 + math.sqrt(5.0)) * i
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    base = np.stack([r * np.cos(phi), z, r * np.sin(phi)], axis=1)
    rng = np.random.default_rng(seed)
    out = np.empty((sets, rays, 3))
    for k in range(sets):
        q, rr = np.linalg.qr(rng.normal(size=(3, 3)))
        q *= np.sign(np.diag(rr))  # a uniformly random rotation (det may be -1: a reflection is as good)
        out[k] = base @ q.T
    return out


class ProbeGather:
    """The traced rays of one probe grid and the surfels they hit (module docstring).

    The constructor traces (and relocates probes inside geometry); ``set_sky`` and
    ``update_visibility`` follow a new sky and sun; a pass over the volume is ``update_surfels``
    (one more bounce) then ``gather`` of its y-layers into the volume's coefficients."""

    def __init__(self, tracer, positions: np.ndarray, cell: np.ndarray, rays: int, surfel_size: float,
                 device, glossy_energy=None, transmissions: int = 0, cache_key: str | None = None,
                 active=None, grid: tuple | None = None, active_key: str | None = None):
        """``glossy_energy``: per material of the tracer's scene, the albedo its surfels gain from
        its Phong lobe (module docstring), None: none; ``transmissions``: transparent interfaces a
        ray is bent through before the hit it lights the probe with; ``cache_key``: a digest of the
        tracer's scene (geometry and materials), with which a big trace is cached on disk (like the
        kd-tree: ``$SERENITY_CACHE`` or ``~/.cache/serenity``) and read back by the next renderer of
        the same scene and grid; None: no cache. ``active``: (P,) bool, the probes a lookup can read
        (:func:`reachable_probes`); only they are traced and gathered, the others hold zeros; None:
        every probe; or a function that returns them, called only when the probes are traced (not
        when they are read from the disk cache), with ``active_key`` a string of everything they
        depend on beyond the scene and the grid (:func:`reach_key`), which the cache key takes
        instead of them. ``grid``: (origin, resolution, normal offset in m) of the volume, with which the
        surfels' own lookups are checked to read active probes only (else those probes are traced too)."""
        self.device = device
        self.rays = int(rays)
        n_probes = len(positions)
        #: (P,) bool: the probes traced and gathered (``active``)
        self._active_fn = None
        if callable(active) and active_key is not None:
            self._active_fn, self.active = active, None
        else:
            self._set_active(active() if callable(active) else active, n_probes)
        self._active_key = active_key if self._active_fn is not None else None
        self.grid = None if grid is None or active is None else grid
        self.tracer = tracer
        self.glossy_energy = None if glossy_energy is None else np.asarray(glossy_energy, np.float32)
        self.transmissions = int(transmissions)
        self.dirs = direction_sets(self.rays)
        self.dirs32 = self.dirs.astype(np.float32)
        self.from_cache = False
        path = None
        #: the trace's cache key (None: not cached), which the converged lighting's key extends
        self.cache_key = None
        if cache_key is not None and len(positions) * self.rays >= CACHE_MIN_RAYS:
            self.cache_key = self._key(cache_key, positions, cell, surfel_size)
            path = cache_dir() / f"probegather-{self.cache_key}.npz"
            self.from_cache = self._load(path, len(positions))
        if not self.from_cache:
            if self.active is None:
                self._set_active(self._active_fn(), len(positions))
            # chunk after chunk of rays: freed, not kept on the heap; the moments' small matrix
            # products on one thread (BLAS's threads only spun beside the tracer's: 5x slower)
            with mapped_large_blocks(), single_threaded_blas():
                self._build(positions, cell, surfel_size)
            if path is not None:
                self._save(path)
        dev = device
        self._basis = wp.array(np.stack([sh_basis(d) for d in self.dirs]).astype(np.float32), dtype=vec9, device=dev)
        self._active = wp.array(self.active.astype(np.int32), dtype=wp.int32, device=dev)
        self._miss = wp.zeros((DIRECTION_SETS, self.rays), dtype=wp.vec3, device=dev)
        self._radiance = wp.zeros(self.surfel_count, dtype=wp.vec3, device=dev)
        self._visible = wp.zeros(self.surfel_count, dtype=float, device=dev)
        self._visible_host = np.zeros(self.surfel_count, np.float32)
        self._vis_sun = np.array([0.0, 1.0, 0.0])
        self._vis_parts, self._vis_left, self._vis_next = 1, 0, 0

    def _set_active(self, active, n_probes: int) -> None:
        self.active = np.ones(n_probes, bool) if active is None else np.asarray(active, bool).reshape(-1).copy()
        if len(self.active) != n_probes:
            raise ValueError(f"active: {len(self.active)} flags for {n_probes} probes")

    def _trace_chunks(self, origins: np.ndarray, sets: np.ndarray, progress: bool = False):
        """The rays of the given probes (their direction sets) in chunks of about ``TRACE_CHUNK_RAYS``
        (the tracer's G-buffer for those rays is the memory peak): yields (first probe, last probe + 1,
        hits) per chunk, hits a dict of the chunk's rays (probe-major): hit mask (front faces),
        back-face mask, position, shading normal (facing the ray) and albedo (+ the Phong lobe's
        energy), float32 (a tqdm bar for big jobs)."""
        n, r = len(origins), self.rays
        total = n * r
        per = max(1, TRACE_CHUNK_RAYS // r)
        bar = tqdm(total=total, desc=f"probe rays ({n:,} probes x {r})", unit="ray", unit_scale=True,
                   leave=False, disable=not (progress and total >= PROGRESS_RAYS))
        for a in range(0, n, per):
            b = min(n, a + per)
            o = np.repeat(origins[a:b].astype(np.float32), r, axis=0)
            d = self.dirs32[sets[a:b]].reshape(-1, 3)
            g = self.tracer.trace(o, d, 0.0, 0.0, backfaces=True, transmissions=self.transmissions)
            del o, d
            back = g.pop("backface")
            albedo = g["albedo"][:, :3]
            if self.glossy_energy is not None and len(self.glossy_energy):
                material = np.clip(np.rint(g["albedo"][:, 3]).astype(np.int32), 0, len(self.glossy_energy) - 1)
                albedo = albedo + self.glossy_energy[material][:, None]
            hits = {"hit": (g["position"][:, 3] > 0) & ~back, "back": back,
                    "position": np.ascontiguousarray(g["position"][:, :3]),
                    "normal": np.ascontiguousarray(g["normal"][:, :3]), "albedo": np.ascontiguousarray(albedo)}
            del g
            bar.update(len(back))
            yield a, b, hits
        bar.close()

    def _build(self, positions, cell, surfel_size) -> None:
        """Trace the active probes' rays, move probes out of geometry, merge the hits into surfels and
        the distances into depth moments, chunk by chunk: the hits of every ray at once (14M rays of a
        262k-triangle room: half a GB, and as much again to merge them) never exist. Where a surfel's
        own lookup reads a probe that is not active (its mean lies off the triangles), that probe is
        made active and traced too (``_REACH_ROUNDS`` rounds at most)."""
        n_probes, r = len(positions), self.rays
        s = np.arange(n_probes) % DIRECTION_SETS
        cell = np.asarray(cell, np.float64)
        origins = np.asarray(positions, np.float64).copy()
        cap = VIS_MAX_CELLS * float(np.linalg.norm(cell))
        self.moments = np.empty((n_probes, VIS_OCT * VIS_OCT, 2), np.float32)
        self.moments[~self.active] = (cap, cap * cap)  # no lookup reads them: as if every ray missed
        merge = _SurfelMerge(n_probes * r, self._surfel_anchor(), surfel_size)
        merge.surfel.reshape(n_probes, r)[~self.active] = -2  # not traced: no light (the gather skips them)
        weights = _MomentWeights(self.dirs32)
        bad = np.zeros(n_probes, bool)  # probes with too many back faces: merged once their place is settled
        self.relocated = 0

        def merge_probes(probes, hits, rays):  # the probes' rays (a mask of the chunk's) into the surfels
            hits = {k: v[rays] for k, v in hits.items()}
            rows = (probes[:, None] * r + np.arange(r)).reshape(-1)
            merge.add(rows, *(hits[k] for k in ("hit", "back", "position", "normal", "albedo")))
            self.moments[probes] = weights.moments(_hit_distances(hits, origins[probes], r, cap), s[probes])

        def trace(act):  # the probes ``act`` (sorted indices) traced, relocated where needed, merged
            # first judged on every RELOCATION_STRIDE-th ray, as a relocation spot is: a probe inside
            # geometry (most of a room's probes next to its surfaces, or under its floor) is not traced
            # in full where it is, only where it moves to
            pre = self._backface_fraction(origins[act], s[act]) > BACKFACE_LIMIT
            bad[act[pre]] = True
            act = act[~pre]
            for a, b, hits in self._trace_chunks(origins[act], s[act], progress=True):
                probes = act[a:b]
                first_bad = hits["back"].reshape(b - a, r).mean(axis=1) > BACKFACE_LIMIT
                bad[probes] = first_bad
                for i in np.flatnonzero(first_bad):
                    hits["hit"][i * r:(i + 1) * r] = False
                    hits["back"][i * r:(i + 1) * r] = False
                rows = slice(probes[0] * r, (probes[-1] + 1) * r) if probes[-1] - probes[0] == b - a - 1 else \
                    (probes[:, None] * r + np.arange(r)).reshape(-1)
                merge.add(rows, *(hits[k] for k in ("hit", "back", "position", "normal", "albedo")))
                self.moments[probes] = weights.moments(_hit_distances(hits, origins[probes], r, cap), s[probes])
                del hits
            for off in RELOCATIONS:  # probes inside geometry: try a free spot nearby
                if not bad.any():
                    break
                idx = np.nonzero(bad)[0]
                cand = origins[idx] + np.asarray(off) * cell
                # judged on every RELOCATION_STRIDE-th ray of the set (a spread subset of the spherical
                # Fibonacci points), then traced in full only where the spot is free
                ok = self._backface_fraction(cand, s[idx]) <= BACKFACE_LIMIT
                if not ok.any():
                    continue
                idx, cand = idx[ok], cand[ok]
                for a, b, hits in self._trace_chunks(cand, s[idx]):
                    keep = hits["back"].reshape(b - a, r).mean(axis=1) <= BACKFACE_LIMIT
                    take = idx[a:b][keep]
                    origins[take] = cand[a:b][keep]
                    merge_probes(take, hits, np.repeat(keep, r))
                    bad[take] = False
                    self.relocated += len(take)
                    del hits
            if bad.any():  # no free spot found: kept, their back-face hits count as misses, traced again
                idx = np.flatnonzero(bad)  # where they are (cheaper than keeping every bad probe's first rays)
                self.inside += len(idx)
                for a, b, hits in self._trace_chunks(origins[idx], s[idx]):
                    merge_probes(idx[a:b], hits, np.ones((b - a) * r, bool))
                    del hits
                bad[idx] = False

        self.inside = 0
        todo = np.flatnonzero(self.active)
        for _ in range(_REACH_ROUNDS):
            if len(todo):
                trace(todo)
            if self.grid is None:
                break
            sp, sn = merge.means()
            origin, resolution, offset = self.grid
            read = np.zeros(n_probes, bool)
            read[lookup_probes(sp + offset * sn, origin, cell, resolution).reshape(-1)] = True
            todo = np.flatnonzero(read & ~self.active)
            if not len(todo):
                break
            self.active[todo] = True
            merge.surfel.reshape(n_probes, r)[todo] = -1
        self.offsets = (origins - np.asarray(positions, np.float64)).astype(np.float32)
        surfel, sp, sn, sa, sv = merge.finish()
        self._set_surfels(surfel.reshape(-1, r), sp, sn, sa, sv)

    def _surfel_anchor(self) -> np.ndarray:
        """(3,) float64 the corner the surfels' cubes are counted from: the scene's bounding box's
        (every hit lies inside it, and it is known before the first ray is traced)."""
        bounds = getattr(self.tracer, "bounds", None)
        return np.zeros(3) if bounds is None else np.asarray(bounds[0], np.float64)

    # -- the disk cache

    _CACHED = ("surfel", "surfel_positions", "surfel_normals", "surfel_albedo", "surfel_shadow_origins", "moments",
               "offsets", "active")

    def _key(self, scene_key: str, positions, cell, surfel_size) -> str:
        h = hashlib.blake2b(digest_size=20)
        h.update(f"probegather-v{FORMAT_VERSION}|{scene_key}|{self.rays}|{self.transmissions}|{surfel_size!r}|"
                 f"{DIRECTION_SETS}|{BACKFACE_LIMIT}|{RELOCATIONS}|{RELOCATION_STRIDE}".encode())
        for a in (np.asarray(positions, np.float64), np.asarray(cell, np.float64),
                  np.zeros(0) if self.glossy_energy is None else self.glossy_energy,
                  self.active if self._active_key is None else np.frombuffer(self._active_key.encode(), np.uint8)):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()

    def _save(self, path: Path) -> None:
        """Write the traced data (an ``.npz`` of plain arrays); an unwritable cache is ignored."""
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
            np.savez(tmp, surfel=self._surfel.numpy(), surfel_positions=self.surfel_positions,
                     surfel_normals=self.surfel_normals, surfel_albedo=self.surfel_albedo,
                     surfel_shadow_origins=self.surfel_shadow_origins, moments=self.moments,
                     offsets=self.offsets, active=self.active,
                     meta=np.array([FORMAT_VERSION, self.relocated, self.inside], np.int64))
            os.replace(tmp, path)
        except OSError:
            pass  # an unwritable cache only costs a trace next time

    def _load(self, path: Path, n_probes: int) -> bool:
        """Read the traced data cached at ``path``; False when absent, unreadable or stale."""
        if not path.is_file():
            return False
        try:
            with np.load(path, allow_pickle=False) as z:
                a = {k: np.array(z[k]) for k in self._CACHED}
                meta = z["meta"].tolist()
        except (OSError, ValueError, KeyError, EOFError):
            return False
        m = len(a["surfel_positions"])
        if (len(meta) != 3 or meta[0] != FORMAT_VERSION or a["surfel"].shape != (n_probes, self.rays)
                or a["surfel"].max(initial=-1) >= m or a["moments"].shape != (n_probes, VIS_OCT * VIS_OCT, 2)
                or a["offsets"].shape != (n_probes, 3) or a["active"].shape != (n_probes,)
                or (self.active is not None and np.any(self.active & ~a["active"].astype(bool)))
                or a["surfel_shadow_origins"].shape != (m, 3)):
            return False
        self.relocated, self.inside = int(meta[1]), int(meta[2])
        self.moments, self.offsets, self.active = a["moments"], a["offsets"], a["active"].astype(bool)
        self._set_surfels(a["surfel"], a["surfel_positions"], a["surfel_normals"], a["surfel_albedo"],
                          a["surfel_shadow_origins"])
        return True

    # -- the converged lighting (the passes of a volume lit for the first time)

    def converged_path(self, *inputs) -> Path | None:
        """Where the coefficients after every pass of a first lighting are cached, keyed by the trace's
        key and everything else they depend on (``inputs``: arrays and numbers — the sky map, the
        ground and the sun, the grid, the passes); None where the trace is not cached. A renderer
        started again on the same scene, sky and sun reads them instead of running the passes
        (the breakfast room's 21 passes until converged: seconds of its warm start)."""
        if self.cache_key is None:
            return None
        h = hashlib.blake2b(digest_size=20)
        h.update(f"converged-v{FORMAT_VERSION}|{self.cache_key}|{len(inputs)}".encode())
        for a in inputs:
            a = np.ascontiguousarray(a)
            h.update(f"|{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())
        return cache_dir() / f"probegather-lit-{h.hexdigest()}.npy"

    @staticmethod
    def load_converged(path: Path | None, coeffs) -> bool:
        """Read the cached coefficients at ``path`` into the Warp array ``coeffs``; False when absent,
        unreadable or of another shape."""
        if path is None or not path.is_file():
            return False
        try:
            a = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError):
            return False
        if a.shape != tuple(coeffs.shape) or a.dtype != np.float32 or not np.all(np.isfinite(a)):
            return False
        coeffs.assign(a)
        return True

    @staticmethod
    def save_converged(path: Path | None, coeffs) -> None:
        """Cache the coefficients (the Warp array ``coeffs``) at ``path``; an unwritable cache is ignored."""
        if path is None:
            return
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npy")
            np.save(tmp, coeffs.numpy().astype(np.float32))
            os.replace(tmp, path)
        except OSError:
            pass

    def _backface_fraction(self, origins: np.ndarray, sets: np.ndarray) -> np.ndarray:
        """(N,) fraction of back-face hits over every ``RELOCATION_STRIDE``-th ray of each probe's set."""
        sub = self.dirs32[:, ::RELOCATION_STRIDE]
        r = sub.shape[1]
        out = np.empty(len(origins))
        per = max(1, TRACE_CHUNK_RAYS // r)
        for a in range(0, len(origins), per):  # chunks of about TRACE_CHUNK_RAYS (the tracer's G-buffer)
            o = np.repeat(origins[a:a + per].astype(np.float32), r, axis=0)
            d = sub[sets[a:a + per]].reshape(-1, 3)
            g = self.tracer.trace(o, d, 0.0, 0.0, backfaces=True, transmissions=self.transmissions)
            out[a:a + per] = g["backface"].reshape(-1, r).mean(axis=1)
        return out

    def _set_surfels(self, surfel, sp, sn, sa, sv) -> None:
        """The surfel each ray hit ((P, R) int32: ≥ 0, −1 a miss, −2 a back face) and the surfels'
        mean positions, normals and albedo and their shadow rays' origins ((S, 3) each)."""
        self.surfel_count = len(sp)
        self.surfel_positions, self.surfel_normals, self.surfel_albedo = sp, sn, sa
        self.surfel_shadow_origins = np.asarray(sv, np.float64)
        dev = self.device
        self._surfel = wp.array(np.ascontiguousarray(surfel, np.int32), dtype=wp.int32, device=dev)
        self._sp = wp.array(sp.astype(np.float32), dtype=wp.vec3, device=dev)
        self._sn = wp.array(sn.astype(np.float32), dtype=wp.vec3, device=dev)
        self._sa = wp.array(sa.astype(np.float32), dtype=wp.vec3, device=dev)

    def update_visibility(self, sun_direction, parts: int = 1) -> None:
        """V_s towards a new sun: one shadow ray per surfel (from just off the surfel, at its own hit
        nearest its point of the surfel's square: ``shadow_origins``), all of them
        now (``parts`` = 1) or in ``parts`` slices, the first now and one per :meth:`refresh_visibility`
        (the slices continue the cycle where it stood: under a sun that moves every frame each surfel
        is re-traced once every ``parts`` frames, against the newest sun)."""
        sun = np.asarray(sun_direction, np.float64)
        self._vis_sun = sun / max(np.linalg.norm(sun), 1e-12)
        self._vis_parts = max(1, int(parts))
        self._vis_left = self._vis_parts
        self.refresh_visibility()

    def refresh_visibility(self) -> bool:
        """Re-trace the next slice of surfels against the sun of the last :meth:`update_visibility`,
        if any are still to do; returns whether it traced."""
        m = self.surfel_count
        if self._vis_left <= 0 or m == 0:
            self._vis_left = 0
            return False
        n = -(-m // self._vis_parts)
        a = self._vis_next if self._vis_parts > 1 else 0
        b = min(m, a + n)
        sun = self._vis_sun
        eps = self.tracer.ray_epsilon
        o = (self.surfel_shadow_origins[a:b] + self.surfel_normals[a:b] * (4 * eps)).astype(np.float32)
        d = np.broadcast_to(sun.astype(np.float32), o.shape)
        occ = self.tracer.tree.occluded(o, d, tmin=eps)
        self._visible_host[a:b] = (~occ).astype(np.float32) * (self.surfel_normals[a:b] @ sun > 0)
        self._visible.assign(self._visible_host)
        self._vis_next = b % m
        self._vis_left -= 1
        return True

    def set_sky(self, sky_map: np.ndarray, ground: np.ndarray) -> None:
        """The miss radiance of every direction: the sky map above the horizon, the ground below."""
        d = self.dirs.reshape(-1, 3)
        out = np.empty((len(d), 3))
        up = d[:, 1] >= 0
        out[up] = sample_sky_map_np(sky_map, d[up])
        out[~up] = np.asarray(ground, np.float64)
        self._miss.assign(out.reshape(DIRECTION_SETS, self.rays, 3).astype(np.float32))

    def update_surfels(self, coeffs, open_sky, visibility, grid, sun_direction, sun_irradiance) -> None:
        """B_s of every surfel from the volume as it is now (one more bounce); ``open_sky``: the (27,)
        Warp array of the open sky's coefficients beyond the grid; ``visibility``: (atlas, offsets) Warp
        arrays of the lookup's probe visibility (empty arrays: plain trilinear)."""
        origin, cell, res, offset = grid
        if self.surfel_count == 0:
            return
        sun = np.asarray(sun_direction, np.float64)
        sun = sun / max(np.linalg.norm(sun), 1e-12)
        launch(surfel_radiance, self.surfel_count,
               [self._sp, self._sn, self._sa, self._visible, wp.vec3(*sun.astype(np.float32)),
                wp.vec3(*np.asarray(sun_irradiance, np.float32)), coeffs, open_sky, *visibility,
                wp.vec3(*origin.astype(np.float32)),
                wp.vec3(*cell.astype(np.float32)), int(res[0]), int(res[1]), int(res[2]), float(offset),
                self._radiance], device=self.device)

    def gather(self, coeffs, scale, resolution, first_layer: int, layers: int) -> None:
        """The probes of y-layers ``first_layer .. first_layer + layers - 1`` gathered into ``coeffs``."""
        x, y, z = resolution
        launch(gather_probes, layers * x * z,
               [int(x), int(y), int(first_layer), self.rays, self._active, self._surfel, self._radiance, self._miss,
                self._basis, scale, coeffs], device=self.device)

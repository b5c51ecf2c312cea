"""The sky volume's probe grid and its lookup (paper §7): the irradiance at a surface point from the
27 coefficients of the probes around it, whichever method lit them (``serenity.kernels.skyvolume``).

Grid (:class:`ProbeGrid`): probe (x, y, z) at ``origin + (x, y, z)·cell`` (m) for x < X, y < Y,
z < Z (``res`` = (X, Y, Z)), stored in the order (z, y, x): probe index (z·Y + y)·X + x.
The lookup's data (:class:`ProbeVolume`): the grid, ``normal_offset`` (m), ``coeffs`` (P, 27)
float32 W·m⁻² (coefficient-major, flat index f = 3k + c: k the SH index 0..8, c the RGB channel),
``open_sky`` (27,) the coefficients of a probe under the open sky, and for the traced probes'
visibility ``vis`` (Z·T, Y, X·T) vec2 (the depth moments' atlas, T = ``VIS_TILE``) and ``offsets``
(P,) vec3 (each probe's relocation, m); empty arrays: plain trilinear.

The lookup at surface point p with unit normal n, defined once, point by point, by
:func:`lookup_reference`:

    x = p + normal_offset·n;  g = (x − origin)/cell (grid units);
    w_open = clamp(max(−g.x, g.x − (X−1), −g.z, g.z − (Z−1), g.y − (Y−1)) / OPEN_FADE_CELLS, 0, 1);
    g clamped to [0, res − 1]; the 8 probes of its cell (the upper ones clamped to the grid), each
    weighed by its trilinear weight — with visibility also by :func:`probe_visibility`'s weight,
    seen from p + VIS_BIAS_CELLS·(smallest cell edge)·n, and the weights renormalised —;
    c = (1 − w_open)·Σ w·c_probe + w_open·open_sky;  E(n) = max(0, Σ_k c_k·Y_k(n)) per channel;
    the glossy term (``SkyConfig.glossy``): max(0, Σ_k c_k·Y_k(r)·glossy_band_factors(m)_k).

Its implementations, each held to :func:`lookup_reference` by ``tests/kernels/test_skylookup.py``:
:func:`volume_irradiance` (Warp: the surfels' radiance of the traced probes and the frame's sky-light
VPLs, :func:`lookup_sky_irradiance`), :func:`interpolate_volume` (numpy, vectorised: the host's
``SkyVolume.irradiance`` and ``.glossy``) and ``serenity/raster/glsl/sky.glsl``'s ``sky_volume_lookup``
(the deferred passes; ``tests/raster/test_sky_gl.py`` compares it with the numpy one).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from serenity.kernels.sh import A_HAT, BAND, eval_sh9, sh_basis

wp.set_module_options({"enable_backward": False})

# ---------------------------------------------------------------------------------------------
# constants

#: float32 coefficients per probe: 9 SH coefficients × RGB
COEFFS = 27
#: beyond the grid's sides and top, the lookup fades to the open sky's coefficients over this many cells
OPEN_FADE_CELLS = 2.0
#: the probes' depth moments (visibility): an octahedral map of VIS_OCT² texels per probe, stored with a
#: one-texel border as a VIS_TILE² tile of the atlas
VIS_OCT = 8
VIS_TILE = VIS_OCT + 2
#: a probe's weight below this is crushed (w³/VIS_CRUSH²), as DDGI does, so that a probe the point
#: cannot see adds next to nothing
VIS_CRUSH = 0.2
#: the visibility test looks from the probe at p + VIS_BIAS_CELLS·(smallest cell edge)·n, however small
#: the lookup's own normal offset: a point on the surface itself sits at the probe's mean depth there
VIS_BIAS_CELLS = 0.5
#: a triangle whose reach spans more probes than this is tested against each one's distance to its plane
#: (``reachable_probes``)
REACH_PLANE_PROBES = 64
#: ``reachable_probes`` takes the triangles this many at a time
_TRIANGLE_CHUNK = 1 << 18


# ---------------------------------------------------------------------------------------------
# structs


@wp.struct
class ProbeGrid:
    """The probes' positions: ``origin + (x, y, z)·cell`` for (x, y, z) < ``res``."""

    origin: wp.vec3
    cell: wp.vec3
    res: wp.vec3i


@wp.struct
class ProbeVolume:
    """What the lookup reads (module docstring)."""

    grid: ProbeGrid
    normal_offset: float
    coeffs: wp.array2d(dtype=float)
    open_sky: wp.array(dtype=float)
    vis: wp.array3d(dtype=wp.vec2)
    offsets: wp.array(dtype=wp.vec3)


# ---------------------------------------------------------------------------------------------
# funcs


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
def probe_visibility(vol: ProbeVolume, probe: int, xi: int, yi: int, zi: int, grid_pos: wp.vec3, p: wp.vec3,
                     x: wp.vec3, n: wp.vec3) -> float:
    """DDGI's weight of probe ``probe`` (grid cell xi, yi, zi at ``grid_pos``, moved by its relocation
    offset) for surface point p with normal n, looked up at x: the smooth back-face weight
    ((n·ω_p + 1)/2)² + 0.2 towards the probe, times the Chebyshev bound that the probe sees x (its
    depth moments bilinear at the direction probe → x), crushed below VIS_CRUSH."""
    q = grid_pos + vol.offsets[probe]
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
    m = (vol.vis[va, yi, ua] * (1.0 - fu) + vol.vis[va, yi, ub] * fu) * (1.0 - fv) \
        + (vol.vis[vb, yi, ua] * (1.0 - fu) + vol.vis[vb, yi, ub] * fu) * fv
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
def volume_irradiance(vol: ProbeVolume, p: wp.vec3, n: wp.vec3) -> wp.vec3:
    """Irradiance of the volume at surface point p with unit normal n (module docstring): trilinear
    coefficients at p + offset·n — each probe's weight also times :func:`probe_visibility` when
    ``vol.vis`` holds the probes' depth moments — faded to the open sky's beyond the grid's sides and
    top, evaluated at n, clamped at 0."""
    res_x = vol.grid.res[0]
    res_y = vol.grid.res[1]
    res_z = vol.grid.res[2]
    origin = vol.grid.origin
    cell = vol.grid.cell
    x = p + n * vol.normal_offset
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
    use_vis = vol.vis.shape[0] > 0
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
            w = w * probe_visibility(vol, probe, xi, yi, zi, q, p, x_vis, n)
        wsum += w
        for k in range(9):
            wk = w * y[k]
            e += wp.vec3(vol.coeffs[probe, 3 * k], vol.coeffs[probe, 3 * k + 1], vol.coeffs[probe, 3 * k + 2]) * wk
    if use_vis:
        e = e / wp.max(wsum, 1.0e-30)
    e_open = wp.vec3()
    for k in range(9):
        e_open += wp.vec3(vol.open_sky[3 * k], vol.open_sky[3 * k + 1], vol.open_sky[3 * k + 2]) * y[k]
    e = e * (1.0 - w_open) + e_open * w_open
    return wp.vec3(wp.max(e[0], 0.0), wp.max(e[1], 0.0), wp.max(e[2], 0.0))


# ---------------------------------------------------------------------------------------------
# kernels


@wp.kernel
def lookup_sky_irradiance(
    # inputs
    vol: ProbeVolume,
    points: wp.array(dtype=wp.vec3),
    normals: wp.array(dtype=wp.vec3),
    # outputs
    irradiance: wp.array(dtype=wp.vec3),
    offset: int,
):
    """The volume's irradiance at surface points (:func:`volume_irradiance`)."""
    i = wp.tid() + offset
    irradiance[i] = volume_irradiance(vol, points[i], normals[i])


# ---------------------------------------------------------------------------------------------
# host


def probe_grid(origin, cell, resolution) -> ProbeGrid:
    """The :class:`ProbeGrid` of ``origin`` (3,) m, ``cell`` (3,) m and ``resolution`` (X, Y, Z)."""
    g = ProbeGrid()
    g.origin = wp.vec3(*np.asarray(origin, np.float64).astype(np.float32))
    g.cell = wp.vec3(*np.asarray(cell, np.float64).astype(np.float32))
    g.res = wp.vec3i(*(int(r) for r in resolution))
    return g


def probe_volume(grid: ProbeGrid, normal_offset: float, coeffs, open_sky, vis, offsets) -> ProbeVolume:
    """The :class:`ProbeVolume` of the Warp arrays of the module docstring."""
    v = ProbeVolume()
    v.grid = grid
    v.normal_offset = float(normal_offset)
    v.coeffs, v.open_sky, v.vis, v.offsets = coeffs, open_sky, vis, offsets
    return v


def oct_encode_np(d: np.ndarray) -> np.ndarray:
    """(N, 2) octahedral coordinates of unit directions (N, 3): the host twin of :func:`oct_encode`."""
    d = np.asarray(d, np.float64)
    s = np.abs(d).sum(axis=1)
    x, z = d[:, 0] / s, d[:, 2] / s
    low = d[:, 1] < 0
    fx = (1.0 - np.abs(z)) * np.where(x >= 0, 1.0, -1.0)
    fz = (1.0 - np.abs(x)) * np.where(z >= 0, 1.0, -1.0)
    return np.stack([np.where(low, fx, x), np.where(low, fz, z)], axis=1)


def glossy_band_factors(shininess) -> np.ndarray:
    """(N, 9) weights that turn irradiance coefficients E_lm = Â_l·L_lm into the radiance filtered by
    the normalised Phong lobe of exponent m, (m + 1)/(2π)·cos^m: its SH factors are 1, (m + 1)/(m + 2)
    and m/(m + 3) for bands 0, 1, 2 (∫ P_l(x)·(m + 1)·x^m dx over [0, 1]), over Â_l = π, 2π/3, π/4."""
    m = np.asarray(shininess, np.float64).reshape(-1)
    band = np.stack([np.full_like(m, 1.0), (m + 1.0) / (m + 2.0), m / (m + 3.0)], axis=1)
    band /= np.array([A_HAT])
    return band[:, np.asarray(BAND)]


def lookup_reference(coeffs_zyx, origin, cell, resolution, normal_offset_m: float, p, n, open_coeffs=None,
                     visibility=None) -> np.ndarray:
    """(9, 3) float64: the coefficients the lookup evaluates at one surface point ``p`` (3,) with unit
    normal ``n`` (3,) — the definition of the lookup (module docstring), one probe at a time, in
    float64. ``coeffs_zyx`` (Z, Y, X, 27); ``open_coeffs`` (9, 3) or None (zeros); ``visibility`` None
    or (atlas (Z·T, Y, X·T, 2), offsets (P, 3))."""
    p, n = np.asarray(p, np.float64), np.asarray(n, np.float64)
    origin, cell = np.asarray(origin, np.float64), np.asarray(cell, np.float64)
    res = [int(r) for r in resolution]
    g = (p + normal_offset_m * n - origin) / cell
    beyond = max(-g[0], g[0] - (res[0] - 1), -g[2], g[2] - (res[2] - 1), g[1] - (res[1] - 1))
    w_open = min(max(beyond / OPEN_FADE_CELLS, 0.0), 1.0)
    g = np.array([min(max(g[a], 0.0), res[a] - 1.0) for a in range(3)])
    lo = [int(np.floor(v)) for v in g]
    frac = g - lo
    x_vis = p + VIS_BIAS_CELLS * float(cell.min()) * n
    total, wsum = np.zeros((9, 3)), 0.0
    for corner in range(8):
        up = [(corner >> a) & 1 for a in range(3)]
        c = [min(lo[a] + up[a], res[a] - 1) for a in range(3)]
        w = float(np.prod([frac[a] if up[a] else 1.0 - frac[a] for a in range(3)]))
        if visibility is not None:
            w *= _visibility_reference(visibility, c, res, origin + np.array(c) * cell, p, x_vis, n)
        wsum += w
        total += w * np.asarray(coeffs_zyx, np.float64)[c[2], c[1], c[0]].reshape(9, 3)
    if visibility is not None:
        total /= max(wsum, 1e-30)
    sky = np.zeros((9, 3)) if open_coeffs is None else np.asarray(open_coeffs, np.float64).reshape(9, 3)
    return (1.0 - w_open) * total + w_open * sky


def _visibility_reference(visibility, c, res, grid_pos, p, x, n) -> float:
    """:func:`probe_visibility` of the probe in cell ``c`` (x, y, z), one point, float64."""
    atlas, offsets = np.asarray(visibility[0], np.float64), np.asarray(visibility[1], np.float64).reshape(-1, 3)
    q = grid_pos + offsets[(c[2] * res[1] + c[1]) * res[0] + c[0]]
    to_probe = (q - p) / np.linalg.norm(q - p)
    w = ((to_probe @ n + 1.0) * 0.5) ** 2 + 0.2
    dist = float(np.linalg.norm(x - q))
    uv = oct_encode_np(((x - q) / max(dist, 1e-9))[None])[0]
    t = np.array([c[0] * VIS_TILE + 1, c[2] * VIS_TILE + 1]) + (uv * 0.5 + 0.5) * VIS_OCT - 0.5
    t0 = np.floor(t).astype(int)
    f = t - t0
    tile = np.array([c[0], c[2]]) * VIS_TILE

    def texel(du, dv):
        u, v = np.clip(t0 + [du, dv], tile, tile + VIS_TILE - 1)
        return atlas[v, c[1], u]

    m = (texel(0, 0) * (1 - f[0]) + texel(1, 0) * f[0]) * (1 - f[1]) + \
        (texel(0, 1) * (1 - f[0]) + texel(1, 1) * f[0]) * f[1]
    if dist > m[0]:
        var = abs(m[1] - m[0] ** 2)
        w *= max((var / (var + (dist - m[0]) ** 2 + 1e-12)) ** 3, 0.0)
    w = max(w, 1e-6)
    return w ** 3 / VIS_CRUSH ** 2 if w < VIS_CRUSH else w


def _probe_visibility_np(vis, offsets, idx, cells, grid_pos, p, x, n) -> np.ndarray:
    """(N,) :func:`probe_visibility` on the host, for one corner: probe indices ``idx`` (N,), their
    cells (N, 3) and grid positions (N, 3)."""
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
    """(N, 9, 3) float64 :func:`lookup_reference` of many points at once (the arguments as there,
    ``points`` and ``normals`` (N, 3))."""
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
    """(N,3) float64 irradiance from (Z, Y, X, 27) coefficients — the lookup on the host."""
    c = interpolate_volume(coeffs_zyx, origin, cell, resolution, normal_offset_m, points, normals, open_coeffs,
                           visibility)
    y = sh_basis(np.asarray(normals, np.float64).reshape(-1, 3))
    return np.maximum(np.einsum("nk,nkc->nc", y, c), 0.0)


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


def lookup_probes(points: np.ndarray, origin, cell, resolution) -> np.ndarray:
    """(N, 8) int64: the probes (storage order z, y, x) the lookup at ``points`` (N, 3), already moved
    by the normal offset, reads: the corners of its cell, clamped to the grid."""
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


def reachable_probes(vertices: np.ndarray, faces: np.ndarray, origin, cell, resolution, reach: float) -> np.ndarray:
    """(P,) bool in storage order (z, y, x): the probes a lookup at a point of the triangles
    ``vertices[faces]`` can read. The lookup at surface point p with unit normal n reads the 8 probes
    around x = p + offset·n (:func:`lookup_reference`), in grid units clamped to the grid;
    x lies within ``reach`` (the offset and a margin) of a triangle, so the triangles' boxes grown by
    ``reach``, clamped to the grid, hold every such x, and the probes around them are all a lookup can
    read. A triangle whose grown box spans more than ``REACH_PLANE_PROBES`` probes and lies inside the
    grid keeps only the probes within one cell (each axis) and ``reach`` of its plane."""
    x, y, z = (int(a) for a in resolution)
    res = np.array([x, y, z])
    origin, cell = np.asarray(origin, np.float64), np.asarray(cell, np.float64)
    out = np.zeros(x * y * z, bool)
    faces = np.asarray(faces).reshape(-1, 3)
    if not len(faces):
        return out
    for a in range(0, len(faces), _TRIANGLE_CHUNK):  # (N, 3, 3) float64 of every triangle at once: 18 MB per 262k
        tri = np.asarray(vertices)[faces[a:a + _TRIANGLE_CHUNK]].astype(np.float64)
        glo = (tri.min(axis=1) - reach - origin) / cell
        ghi = (tri.max(axis=1) + reach - origin) / cell
        lo = np.floor(np.clip(glo, 0.0, res - 1)).astype(np.int64)
        hi = np.minimum(np.floor(np.clip(ghi, 0.0, res - 1)).astype(np.int64) + 1, res - 1)
        span = hi - lo + 1
        big = (span.prod(axis=1) > REACH_PLANE_PROBES) & np.all(glo >= 0.0, axis=1) & np.all(ghi <= res - 1, axis=1)
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


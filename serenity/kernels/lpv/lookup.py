"""LPV lookups (package docstring, "Lookup", "Self-illumination damping", "Temporal blend"): diffuse
irradiance at points with normals (the leak guard, the lookup occlusion and the blockers' planes
compiled in or out by ``lookup_irradiance_kernel``), glossy radiance marched along reflected
directions (paper Fig. 10), cascades blended finest first; and the temporal blend of what lookups read.

Inputs (Warp arrays on the volume's device): points (N,) vec3 m, unit normals or reflected directions
(N,) vec3, Phong exponents (N,) float; the grids lookups read (vec4 per cell and channel), the
geometry volume's face openness and blocker planes (vec3 per cell), the cascade table
(``grid.Cascade``). Outputs: (N,) vec3 RGB, irradiance in W/m² or radiance in W·m⁻²·sr⁻¹.
"""

from __future__ import annotations

import warp as wp

from serenity.kernels.factory import kernel_factory
from serenity.kernels.lpv.basis import C0, C1, E0, E1
from serenity.kernels.lpv.grid import Cascade, grid_coord, sample_sh

wp.set_module_options({"enable_backward": False})


@wp.func
def guard_weight(n: wp.vec3, us: wp.vec3, x: int, y: int, z: int) -> float:
    """g = clamp(4·n·(centre − us), 0, 1) of cell (x, y, z) for a surface at us (cells)."""
    c = wp.vec3(float(x) + 0.5, float(y) + 0.5, float(z) + 0.5)
    return wp.clamp(4.0 * wp.dot(n, c - us), 0.0, 1.0)


@wp.func
def home_cell(opn: wp.array(dtype=wp.vec3), plane: wp.array(dtype=wp.vec3), cell_base: int, res: int, us: wp.vec3,
              n: wp.vec3, planes: bool) -> wp.vec3i:
    """The cell on the surface's side of the geometry volume (package doc, "Lookup occlusion"): the cell
    h = ⌊q⌋ of q = us + n/4 (just in front of the surface), moved one cell down an axis when h's low face
    there is blocked and its blocker lies inside h beyond q (q is then on the far side of the blocker: a
    wall row just under a ceiling that lies in a cell's lower half), or up when its high face is and q
    lies beyond that blocker. ``planes``: the blocker offsets are known (else h)."""
    q = us + 0.25 * n
    hx = wp.clamp(int(wp.floor(q[0])), 0, res - 1)
    hy = wp.clamp(int(wp.floor(q[1])), 0, res - 1)
    hz = wp.clamp(int(wp.floor(q[2])), 0, res - 1)
    h0 = wp.vec3i(hx, hy, hz)
    if not planes:
        return h0
    hi = plane[cell_base + (hz * res + hy) * res + hx]
    oh = opn[cell_base + (hz * res + hy) * res + hx]
    step = wp.vec3i(0, 0, 0)
    for a in range(3):
        f = q[a] - float(h0[a])
        moved = False
        if h0[a] > 0:
            lo = wp.vec3i(hx, hy, hz)
            lo[a] = h0[a] - 1
            j = cell_base + (lo[2] * res + lo[1]) * res + lo[0]
            t = plane[j][a]
            if t > 0.0 and f < t and opn[j][a] < 1.0:
                step[a] = -1
                moved = True
        if not moved and h0[a] < res - 1:
            if hi[a] < 0.0 and f > 1.0 + hi[a] and oh[a] < 1.0:
                step[a] = 1
    return wp.vec3i(hx + step[0], hy + step[1], hz + step[2])


@wp.func
def open_weight(opn: wp.array(dtype=wp.vec3), cell_base: int, res: int, h: wp.vec3i, x: int, y: int,
                z: int) -> float:
    """Π over the axes where cell (x, y, z) differs from the home cell h (``home_cell``) of the openness
    of the face between them on that axis, taken in h's row: a cell behind a wall, floor or ceiling of
    the geometry volume does not light the surface (package doc, "Lookup occlusion")."""
    hx = h[0]
    hy = h[1]
    hz = h[2]
    f = float(1.0)
    if x != hx:
        f = f * opn[cell_base + (hz * res + hy) * res + wp.min(x, hx)][0]
    if y != hy:
        f = f * opn[cell_base + (hz * res + wp.min(y, hy)) * res + hx][1]
    if z != hz:
        f = f * opn[cell_base + (wp.min(z, hz) * res + hy) * res + hx][2]
    return f


@wp.func
def trilinear_sh(grid: wp.array(dtype=wp.vec4), base: int, res: int, u: wp.vec3, us: wp.vec3, n: wp.vec3,
                 guard: bool, opn: wp.array(dtype=wp.vec3), cell_base: int, occlusion: bool, h: wp.vec3i) -> wp.vec4:
    """Trilinear SH at grid coordinate u (cells), cell centres at i + 0.5, clamp to edge (GL_LINEAR).
    With ``guard`` (a compile-time constant at every call), each of the 8 cells' weights is also
    multiplied by ``guard_weight`` for a surface at us with normal n and, with ``occlusion``, by
    ``open_weight`` (the faces of the geometry volume between the surface's home cell h and it; ``opn``
    the cascade's face openness from ``cell_base`` on), and renormalised (package doc), plain
    trilinear where they sum below 1e-4."""
    p = u - wp.vec3(0.5, 0.5, 0.5)
    fx = wp.floor(p[0])
    fy = wp.floor(p[1])
    fz = wp.floor(p[2])
    tx = p[0] - fx
    ty = p[1] - fy
    tz = p[2] - fz
    x0 = wp.clamp(int(fx), 0, res - 1)
    y0 = wp.clamp(int(fy), 0, res - 1)
    z0 = wp.clamp(int(fz), 0, res - 1)
    x1 = wp.clamp(int(fx) + 1, 0, res - 1)
    y1 = wp.clamp(int(fy) + 1, 0, res - 1)
    z1 = wp.clamp(int(fz) + 1, 0, res - 1)
    plain = wp.vec4()
    acc = wp.vec4()
    wsum = float(0.0)
    for k in range(8):
        xi = x0
        wx = 1.0 - tx
        if k % 2 == 1:
            xi = x1
            wx = tx
        yi = y0
        wy = 1.0 - ty
        if (k // 2) % 2 == 1:
            yi = y1
            wy = ty
        zi = z0
        wz = 1.0 - tz
        if k // 4 == 1:
            zi = z1
            wz = tz
        w = wx * wy * wz
        s = grid[base + (zi * res + yi) * res + xi]
        plain += w * s
        if guard:
            gw = w * guard_weight(n, us, xi, yi, zi)
            if occlusion:
                gw = gw * open_weight(opn, cell_base, res, h, xi, yi, zi)
            acc += gw * s
            wsum += gw
    if not guard or wsum < 1.0e-4:
        return plain
    return acc / wsum



@wp.func
def cascade_weight(u: wp.vec3, res: int, margin: float, band: float, last: bool) -> float:
    """α of a cascade at grid coordinate u (package doc): smoothstep(margin, margin+band, d), step if
    band = 0; the last cascade clamp(d + 1, 0, 1). d = distance to the box border in cells."""
    fr = float(res)
    d = wp.min(wp.min(wp.min(u[0], u[1]), u[2]), wp.min(wp.min(fr - u[0], fr - u[1]), fr - u[2]))
    if last:
        return wp.clamp(d + 1.0, 0.0, 1.0)
    if band > 0.0:
        t = wp.clamp((d - margin) / band, 0.0, 1.0)
        return t * t * (3.0 - 2.0 * t)
    if d > margin:
        return 1.0
    return 0.0


@wp.func
def eval_irradiance(s: wp.vec4, n: wp.vec3, inv_area: float) -> float:
    """Irradiance (W/m²) on a surface of normal n from an intensity SH s of a cell of area 1/inv_area."""
    e = E0 * s[0] - E1 * (s[1] * n[0] + s[2] * n[1] + s[3] * n[2])
    return wp.max(e * inv_area, 0.0)


@wp.func
def eval_radiance(s: wp.vec4, w: wp.vec3, a1: float, inv_area: float) -> float:
    """Radiance (W·m⁻²·sr⁻¹) travelling along w, band 1 scaled by a1 (lobe prefilter), clamped ≥ 0."""
    e = C0 * s[0] + a1 * C1 * (s[1] * w[0] + s[2] * w[1] + s[3] * w[2])
    return wp.max(e * inv_area, 0.0)


@wp.func
def self_damping(near: float, far: float, power: float) -> float:
    """Self-illumination damping (package doc, "Self-illumination"): (far / near)^power clamped to [0, 1],
    near the DC where the surface looks up, far the DC damp_dist cells further along its normal; 1
    where near ≤ 0 (nothing to damp)."""
    if not (near > 0.0):
        return 1.0
    r = wp.clamp(far / near, 0.0, 1.0)
    return wp.pow(r, power)


@wp.func
def open_ahead(opn: wp.array(dtype=wp.vec3), cell_base: int, res: int, h: wp.vec3i, n: wp.vec3, steps: int) -> float:
    """Π of the openness of the ``steps`` faces met going from the home cell h along the normal's dominant
    axis (stops at the grid's edge): the self-illumination damping's far sample is only trusted as far as
    the space in front of the surface is open (under an overhang it would read the ground's far side)."""
    a = int(0)
    if wp.abs(n[1]) > wp.abs(n[a]):
        a = 1
    if wp.abs(n[2]) > wp.abs(n[a]):
        a = 2
    st = int(1)
    if n[a] < 0.0:
        st = -1
    c = wp.vec3i(h[0], h[1], h[2])
    o = float(1.0)
    for _k in range(steps):
        if c[a] + st >= 0 and c[a] + st <= res - 1:
            lo = wp.vec3i(c[0], c[1], c[2])
            lo[a] = wp.min(c[a], c[a] + st)
            o = o * opn[cell_base + (lo[2] * res + lo[1]) * res + lo[0]][a]
            c[a] = c[a] + st
    return o


@wp.func
def cascade_irradiance(grids: wp.array(dtype=wp.vec4), g: Cascade, last: bool, p: wp.vec3, n: wp.vec3,
                       lookup_offset: float, leak_guard: bool, margin: float, band: float, keep: float,
                       opn: wp.array(dtype=wp.vec3), occlusion: bool, plane: wp.array(dtype=wp.vec3),
                       planes: bool, damp_dist: float, damp_pow: float) -> wp.vec4:
    """Cascade g's share of the irradiance at p (normal n): (α·E_rgb, α), α its blend weight times
    what the finer cascades left (``keep``). The twin of lpv.glsl's lpv_cascade_irradiance."""
    us = grid_coord(g, p)
    u = us + n * lookup_offset
    alpha = cascade_weight(u, g.res, margin, band, last) * keep
    if alpha <= 0.0:
        return wp.vec4()
    inv_area = 1.0 / (g.cell * g.cell)
    n3 = g.res * g.res * g.res
    h = wp.vec3i()
    if occlusion:
        h = home_cell(opn, plane, g.cell_base, g.res, us, n, planes)
    sr = trilinear_sh(grids, g.base, g.res, u, us, n, leak_guard, opn, g.cell_base, occlusion, h)
    sg = trilinear_sh(grids, g.base + n3, g.res, u, us, n, leak_guard, opn, g.cell_base, occlusion, h)
    sb = trilinear_sh(grids, g.base + 2 * n3, g.res, u, us, n, leak_guard, opn, g.cell_base, occlusion, h)
    if damp_dist > 0.0:
        uf = u + n * damp_dist
        o = float(1.0)
        if occlusion:
            o = open_ahead(opn, g.cell_base, g.res, h, n, int(wp.ceil(damp_dist)))
        sr = sr * (1.0 - o * (1.0 - self_damping(sr[0], sample_sh(grids, g.base, g.res, uf)[0], damp_pow)))
        sg = sg * (1.0 - o * (1.0 - self_damping(sg[0], sample_sh(grids, g.base + n3, g.res, uf)[0], damp_pow)))
        sb = sb * (1.0 - o * (1.0 - self_damping(sb[0], sample_sh(grids, g.base + 2 * n3, g.res, uf)[0], damp_pow)))
    return wp.vec4(alpha * eval_irradiance(sr, n, inv_area), alpha * eval_irradiance(sg, n, inv_area),
                   alpha * eval_irradiance(sb, n, inv_area), alpha)


@wp.func
def cascade_radiance(grids: wp.array(dtype=wp.vec4), g: Cascade, last: bool, q: wp.vec3, w: wp.vec3,
                     a1: float, margin: float, band: float, keep: float) -> wp.vec4:
    """Cascade g's share of the radiance travelling along w at q: (α·L_rgb, α), as above."""
    u = grid_coord(g, q)
    alpha = cascade_weight(u, g.res, margin, band, last) * keep
    if alpha <= 0.0:
        return wp.vec4()
    inv_area = 1.0 / (g.cell * g.cell)
    n3 = g.res * g.res * g.res
    return wp.vec4(alpha * eval_radiance(sample_sh(grids, g.base, g.res, u), w, a1, inv_area),
                   alpha * eval_radiance(sample_sh(grids, g.base + n3, g.res, u), w, a1, inv_area),
                   alpha * eval_radiance(sample_sh(grids, g.base + 2 * n3, g.res, u), w, a1, inv_area), alpha)



@kernel_factory(leak_guard=(False, True), occlusion=(False, True), planes=(False, True))
def lookup_irradiance_kernel(leak_guard: bool, occlusion: bool = False, planes: bool = False):
    """Irradiance lookups (W/m², RGB) at points with unit normals, cascades blended finest first; the
    leak guard, its lookup occlusion and the blockers' positions in the home cell (package doc)
    compiled in or out."""

    @wp.kernel(enable_backward=False, module="unique")
    def lookup_irradiance(
        # inputs
        points: wp.array(dtype=wp.vec3),
        normals: wp.array(dtype=wp.vec3),
        grids: wp.array(dtype=wp.vec4),
        opn: wp.array(dtype=wp.vec3),
        plane: wp.array(dtype=wp.vec3),
        cascades: wp.array(dtype=Cascade),
        n_cascades: int,
        lookup_offset: float,
        margin: float,
        band: float,
        damp_dist: float,
        damp_pow: float,
        # outputs
        out: wp.array(dtype=wp.vec3),
        offset: int,
    ):
        i = wp.tid() + offset
        p = points[i]
        n = wp.normalize(normals[i])
        e = wp.vec3()
        keep = float(1.0)
        for c in range(n_cascades):
            r = cascade_irradiance(grids, cascades[c], c == n_cascades - 1, p, n, lookup_offset,
                                   wp.static(leak_guard), margin, band, keep, opn,
                                   wp.static(occlusion), plane, wp.static(planes), damp_dist, damp_pow)
            e += wp.vec3(r[0], r[1], r[2])
            keep = keep - r[3]
        out[i] = e

    return lookup_irradiance


@wp.kernel(enable_backward=False)
def lookup_glossy(
    # inputs
    points: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    shininess: wp.array(dtype=float),
    grids: wp.array(dtype=wp.vec4),
    cascades: wp.array(dtype=Cascade),
    n_cascades: int,
    steps: int,
    step_len: float,
    margin: float,
    band: float,
    # outputs
    out: wp.array(dtype=wp.vec3),
    offset: int,
):
    """Radiance (W·m⁻²·sr⁻¹, RGB) arriving at points from the reflected directions, marched (Fig. 10)."""
    i = wp.tid() + offset
    p = points[i]
    r = wp.normalize(directions[i])
    m = shininess[i]
    a1 = (m + 1.0) / (m + 2.0)
    w = -r
    acc = wp.vec3()
    for k in range(steps):
        q = p + r * (step_len * float(k + 1))
        keep = float(1.0)
        for c in range(n_cascades):
            s = cascade_radiance(grids, cascades[c], c == n_cascades - 1, q, w, a1, margin, band, keep)
            acc += wp.vec3(s[0], s[1], s[2])
            keep = keep - s[3]
    out[i] = acc / float(steps)


@wp.kernel(enable_backward=False)
def blend_shown(
    # inputs
    target: wp.array(dtype=wp.vec4),
    previous: wp.array(dtype=wp.vec4),
    base: int,
    res: int,
    shift: wp.vec3i,
    alpha: float,
    # outputs
    shown: wp.array(dtype=wp.vec4),
    offset: int,
):
    """One level's shown light (3·res³ vec4 from ``base``) a fraction ``alpha`` of the way from what it
    showed before (``previous``, in a grid ``shift`` cells away: cell i of the new grid is cell i + shift
    of the old one) to ``target``; cells the old grid did not hold take the target."""
    i = wp.tid() + offset
    n3 = res * res * res
    ch = i // n3
    k = i - ch * n3
    x = k % res + shift[0]
    y = (k // res) % res + shift[1]
    z = k // (res * res) + shift[2]
    t = target[base + i]
    if x >= 0 and y >= 0 and z >= 0 and x < res and y < res and z < res:
        p = previous[base + ch * n3 + (z * res + y) * res + x]
        shown[base + i] = p + alpha * (t - p)
    else:
        shown[base + i] = t

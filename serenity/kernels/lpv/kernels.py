"""LPV Warp functions and kernels (package docstring: what is stored, propagation, lookups).

A cascade in a kernel is a ``Cascade`` struct (its grid's placement and its offsets in the shared
arrays). Two tables of them: the **levels** (one per config cascade, offsets only: which cells of
the per-cell arrays belong to which grid) and the **cascades** (the fitted or active ones, finest
first, with origin and cell size). Every kernel is 1-D with a trailing ``offset`` (see
``serenity.kernels.launch``); the scatter kernels (``inject_vpls``, ``inject_geometry``) follow
``ScatterGrid``'s convention. Flags are compiled in or out by cached factories
(``propagate_kernel(geometry_volume)``, ``lookup_irradiance_kernel(leak_guard)``).
"""

from __future__ import annotations

import warp as wp

from serenity.kernels.factory import kernel_factory
from serenity.kernels.launch import slot_base
from serenity.kernels.lpv.basis import (
    C0,
    C1,
    E0,
    E1,
    G0,
    G1,
    INV_SQRT5,
    K0,
    K1,
    T_AX_AX,
    T_AX_DC,
    T_DC_AX,
    T_DC_DC,
    T_PERP,
    W_FRONT_C,
    W_SIDE_C,
)

wp.set_module_options({"enable_backward": False})


@wp.struct
class Cascade:
    """One cascade's grid and where its cells live in the shared arrays."""

    origin: wp.vec3
    """World position of the grid's min corner (m); unused in the level table."""
    cell: float
    """Edge of a cubic cell (m); unused in the level table."""
    res: int
    """Cells per axis."""
    base: int
    """First vec4 of this grid in the SH arrays (3·res³ vec4: R, G, B blocks, each z, y, x)."""
    cell_base: int
    """First cell in the per-cell arrays (res³)."""
    gv_base: int
    """First vec4 in the geometry volume ((res+1)³)."""


# ----------------------------------------------------------------------------------------------
# Warp functions
# ----------------------------------------------------------------------------------------------


@wp.func
def find_level(i: int, levels: wp.array(dtype=Cascade), n_levels: int) -> int:
    """Config level whose cells [cell_base, cell_base + res³) hold global cell i (−1: none)."""
    found = int(-1)
    for l in range(n_levels):
        e = levels[l]
        if i >= e.cell_base and i < e.cell_base + e.res * e.res * e.res:
            found = l
    return found


@wp.func
def grid_coord(g: Cascade, p: wp.vec3) -> wp.vec3:
    """Grid coordinate (cells, float) of world point p in cascade g."""
    return (p - g.origin) / g.cell


@wp.func
def inside(u: wp.vec3, res: int) -> bool:
    """u in [0, res)³."""
    fr = float(res)
    return u[0] >= 0.0 and u[1] >= 0.0 and u[2] >= 0.0 and u[0] < fr and u[1] < fr and u[2] < fr


@wp.func
def gather_pair(out: wp.vec4, p: wp.vec4, m: wp.vec4, axis: int) -> wp.vec4:
    """Add what a cell gathers along one axis: ``p`` = (weighted) SH of the source at −e_axis
    (light travelling +e_axis), ``m`` = source at +e_axis (travelling −e_axis).

    The sparse transfer (``basis.TRANSFER``) for d = ±e_axis, summed for the pair: with σ = p + m,
    δ = p − m: out0 += T_DC_DC·σ0 + T_DC_AX·δ_a, out_a += T_AX_DC·δ0 + T_AX_AX·σ_a,
    out_⟂ += T_PERP·σ_⟂.
    """
    s = p + m
    d = p - m
    if axis == 0:
        return out + wp.vec4(T_DC_DC * s[0] + T_DC_AX * d[1], T_AX_DC * d[0] + T_AX_AX * s[1],
                             T_PERP * s[2], T_PERP * s[3])
    if axis == 1:
        return out + wp.vec4(T_DC_DC * s[0] + T_DC_AX * d[2], T_PERP * s[1],
                             T_AX_DC * d[0] + T_AX_AX * s[2], T_PERP * s[3])
    return out + wp.vec4(T_DC_DC * s[0] + T_DC_AX * d[3], T_PERP * s[1], T_PERP * s[2],
                         T_AX_DC * d[0] + T_AX_AX * s[3])


@wp.func
def face_emit(out: wp.vec4, phi: float, axis: int, sign: float) -> wp.vec4:
    """out + the clamped-cosine lobe of flux phi facing sign·e_axis: phi·(K0, K1·sign·e_axis)."""
    if axis == 0:
        return out + wp.vec4(K0 * phi, K1 * sign * phi, 0.0, 0.0)
    if axis == 1:
        return out + wp.vec4(K0 * phi, 0.0, K1 * sign * phi, 0.0)
    return out + wp.vec4(K0 * phi, 0.0, 0.0, K1 * sign * phi)


@wp.func
def gather_clamped(out: wp.vec4, s: wp.vec4, axis: int, sign: float) -> wp.vec4:
    """What a cell gathers from a source of SH s at −d, d = sign·e_axis, with every face's flux
    clamped at 0: Φ_f = Δω_f·max(0, I_s(ω_f)) (package doc, "Clamped faces"). The explicit 5-face sum
    of the package docstring, which ``gather_pair`` collapses to a linear 4×4 transfer without the clamp."""
    sd = sign * s[axis + 1]
    if s[0] >= 0.0 and C0 * C0 * s[0] * s[0] >= C1 * C1 * (s[1] * s[1] + s[2] * s[2] + s[3] * s[3]):
        # I_s ≥ 0 in every direction (C0·s0 ≥ C1·|s_xyz|, squared: no square root on this hot path):
        # no face is clamped, the linear transfer is exact (and cheaper)
        lin = wp.vec4(T_DC_DC * s[0] + T_DC_AX * sd, T_PERP * s[1], T_PERP * s[2], T_PERP * s[3])
        lin[axis + 1] = sign * (T_AX_DC * s[0] + T_AX_AX * sd)
        return out + lin
    i_front = C0 * s[0] + C1 * sd
    out = face_emit(out, W_FRONT_C * wp.max(i_front, 0.0), axis, sign)
    for k in range(2):
        e = (axis + 1 + k) % 3
        se = s[e + 1]
        base = C0 * s[0] + C1 * INV_SQRT5 * 2.0 * sd
        out = face_emit(out, W_SIDE_C * wp.max(base + C1 * INV_SQRT5 * se, 0.0), e, 1.0)
        out = face_emit(out, W_SIDE_C * wp.max(base - C1 * INV_SQRT5 * se, 0.0), e, -1.0)
    return out


@wp.func
def gv_at(gv: wp.array(dtype=wp.vec4), base: int, r1: int, x: int, y: int, z: int) -> wp.vec4:
    return gv[base + (z * r1 + y) * r1 + x]


@wp.func
def gv_face(gv: wp.array(dtype=wp.vec4), base: int, r1: int, axis: int, x: int, y: int, z: int) -> wp.vec4:
    """Mean blocking SH of the 4 geometry cells at the corners of the face ⟂ axis whose low corner is (x,y,z)."""
    if axis == 0:
        return 0.25 * (gv_at(gv, base, r1, x, y, z) + gv_at(gv, base, r1, x, y + 1, z)
                       + gv_at(gv, base, r1, x, y, z + 1) + gv_at(gv, base, r1, x, y + 1, z + 1))
    if axis == 1:
        return 0.25 * (gv_at(gv, base, r1, x, y, z) + gv_at(gv, base, r1, x + 1, y, z)
                       + gv_at(gv, base, r1, x, y, z + 1) + gv_at(gv, base, r1, x + 1, y, z + 1))
    return 0.25 * (gv_at(gv, base, r1, x, y, z) + gv_at(gv, base, r1, x + 1, y, z)
                   + gv_at(gv, base, r1, x, y + 1, z) + gv_at(gv, base, r1, x + 1, y + 1, z))


@wp.func
def eval_transmittance(b: wp.vec4, axis: int, sign: float) -> float:
    """1 − clamp(B(−d)) for light travelling along d = sign·e_axis through a face of blocking SH b."""
    blk = C0 * b[0] - sign * C1 * b[axis + 1]
    return 1.0 - wp.clamp(blk, 0.0, 1.0)


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
def sample_sh(grid: wp.array(dtype=wp.vec4), base: int, res: int, u: wp.vec3) -> wp.vec4:
    """Plain trilinear SH at grid coordinate u (``trilinear_sh`` without the guard)."""
    p = u - wp.vec3(0.5, 0.5, 0.5)
    f = wp.vec3(wp.floor(p[0]), wp.floor(p[1]), wp.floor(p[2]))
    t = p - f
    x0 = wp.clamp(int(f[0]), 0, res - 1)
    y0 = wp.clamp(int(f[1]), 0, res - 1)
    z0 = wp.clamp(int(f[2]), 0, res - 1)
    x1 = wp.clamp(int(f[0]) + 1, 0, res - 1)
    y1 = wp.clamp(int(f[1]) + 1, 0, res - 1)
    z1 = wp.clamp(int(f[2]) + 1, 0, res - 1)
    r0 = (1.0 - t[0]) * grid[base + (z0 * res + y0) * res + x0] + t[0] * grid[base + (z0 * res + y0) * res + x1]
    r1 = (1.0 - t[0]) * grid[base + (z0 * res + y1) * res + x0] + t[0] * grid[base + (z0 * res + y1) * res + x1]
    r2 = (1.0 - t[0]) * grid[base + (z1 * res + y0) * res + x0] + t[0] * grid[base + (z1 * res + y0) * res + x1]
    r3 = (1.0 - t[0]) * grid[base + (z1 * res + y1) * res + x0] + t[0] * grid[base + (z1 * res + y1) * res + x1]
    return (1.0 - t[2]) * ((1.0 - t[1]) * r0 + t[1] * r1) + t[2] * ((1.0 - t[1]) * r2 + t[1] * r3)


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


# ----------------------------------------------------------------------------------------------
# kernels
# ----------------------------------------------------------------------------------------------


@wp.func
def splat_axes(n: wp.vec3) -> wp.vec3i:
    """(the normal's dominant axis, the two others): a VPL's light is split between the cells beside
    each other along its surface (bilinearly along the two others) but kept in the one layer of cells
    in front of the surface along the first (``inject_vpls``)."""
    ax = wp.abs(n[0])
    ay = wp.abs(n[1])
    az = wp.abs(n[2])
    if ax >= ay and ax >= az:
        return wp.vec3i(0, 1, 2)
    if ay >= az:
        return wp.vec3i(1, 0, 2)
    return wp.vec3i(2, 0, 1)


@wp.func
def splat_cell(u: wp.vec3, axes: wp.vec3i, k: int, res: int) -> wp.vec4:
    """Corner ``k`` (0..3) of the bilinear splat of point ``u`` (cells): (x, y, z, weight); the cell
    containing u along axes[0], the two cell centres around u along axes[1] and axes[2] (clamped to
    the grid: a point within half a cell of the border keeps all of its weight inside)."""
    out = wp.vec4(wp.floor(u[0]), wp.floor(u[1]), wp.floor(u[2]), 1.0)
    for j in range(2):
        a = axes[j + 1]
        v = u[a] - 0.5
        v0 = wp.floor(v)
        f = v - v0
        bit = (k >> j) & 1
        c = v0 + float(bit)
        out[a] = wp.clamp(c, 0.0, float(res - 1))
        out[3] = out[3] * wp.where(bit == 1, f, 1.0 - f)
    return out


@wp.kernel(enable_backward=False)
def inject_vpls(
    # inputs
    positions: wp.array(dtype=wp.vec3),
    normals: wp.array(dtype=wp.vec3),
    flux: wp.array(dtype=wp.vec3),
    cascades: wp.array(dtype=Cascade),
    n_cascades: int,
    shift: float,
    slot_starts: wp.array(dtype=int),
    slot_stride: int,
    # outputs
    grid: wp.array(dtype=wp.vec4),
    offset: int,
):
    """Add each VPL's clamped-cosine intensity lobe at p + shift·s·n to every cascade: to the layer of cells
    that holds that point along the normal's dominant axis, split bilinearly between the 4 cells around it
    across the other two (package doc, "Injection")."""
    i = wp.tid() + offset
    n = normals[i]
    ln = wp.length(n)
    if not (ln > 0.0):
        return
    n = n / ln
    f = flux[i]
    lobe = wp.vec4(K0, K1 * n[0], K1 * n[1], K1 * n[2])
    sbase = slot_base(offset, slot_starts, slot_stride)
    for c in range(n_cascades):
        g = cascades[c]
        res = g.res
        u = grid_coord(g, positions[i]) + n * shift
        if inside(u, res):
            n3 = res * res * res
            axes = splat_axes(n)
            for k in range(4):
                s = splat_cell(u, axes, k, res)
                cell = sbase + g.base + (int(s[2]) * res + int(s[1])) * res + int(s[0])
                wp.atomic_add(grid, cell, lobe * (f[0] * s[3]))
                wp.atomic_add(grid, cell + n3, lobe * (f[1] * s[3]))
                wp.atomic_add(grid, cell + 2 * n3, lobe * (f[2] * s[3]))


@wp.kernel(enable_backward=False)
def inject_geometry(
    # inputs
    positions: wp.array(dtype=wp.vec3),
    normals: wp.array(dtype=wp.vec3),
    areas: wp.array(dtype=float),
    cascades: wp.array(dtype=Cascade),
    n_cascades: int,
    planes: int,
    slot_starts: wp.array(dtype=int),
    slot_stride: int,
    # outputs
    gv: wp.array(dtype=wp.vec4),
    offset: int,
):
    """Add each surfel's blocking lobe to the geometry cell centred on its nearest cell corner; with
    ``planes`` > 0 (the geometry volume's size) also its weighted offset from that corner along each axis
    at ``planes`` + cell and its weight at 2·``planes`` + cell (where the blocker lies in the cell)."""
    i = wp.tid() + offset
    n = normals[i]
    ln = wp.length(n)
    if not (ln > 0.0):
        return
    n = n / ln
    sbase = slot_base(offset, slot_starts, slot_stride)
    for c in range(n_cascades):
        g = cascades[c]
        r1 = g.res + 1
        u = grid_coord(g, positions[i]) + wp.vec3(0.5, 0.5, 0.5)
        if inside(u, r1):
            cover = areas[i] / (g.cell * g.cell)
            cell = sbase + g.gv_base + (int(u[2]) * r1 + int(u[1])) * r1 + int(u[0])
            wp.atomic_add(gv, cell, wp.vec4(G0 * cover, G1 * cover * n[0], G1 * cover * n[1], G1 * cover * n[2]))
            if planes > 0:
                # where the blocker lies along each axis: Σ w_a·d_a and Σ w_a, w_a = cover·n_a², d_a ∈ [−½, ½)
                # the surfel's offset from the corner (package doc, "Lookup occlusion")
                d = u - wp.vec3(wp.floor(u[0]), wp.floor(u[1]), wp.floor(u[2])) - wp.vec3(0.5, 0.5, 0.5)
                w = wp.vec3(cover * n[0] * n[0], cover * n[1] * n[1], cover * n[2] * n[2])
                wp.atomic_add(gv, cell + planes, wp.vec4(w[0] * d[0], w[1] * d[1], w[2] * d[2], 0.0))
                wp.atomic_add(gv, cell + 2 * planes, wp.vec4(w[0], w[1], w[2], 0.0))


@wp.kernel(enable_backward=False)
def measure_cells(
    # inputs
    grid: wp.array(dtype=wp.vec4),
    levels: wp.array(dtype=Cascade),
    n_levels: int,
    # outputs
    total: wp.array(dtype=float),
    offset: int,
):
    """total[cell] = Σ_RGB |DC| of each cell (per-cascade sums say which cascades received light)."""
    i = wp.tid() + offset
    l = find_level(i, levels, n_levels)
    if l < 0:
        return
    e = levels[l]
    n3 = e.res * e.res * e.res
    j = e.base + i - e.cell_base
    total[i] = wp.abs(grid[j][0]) + wp.abs(grid[j + n3][0]) + wp.abs(grid[j + 2 * n3][0])


@wp.kernel(enable_backward=False)
def eval_face_transmittance(
    # inputs
    gv: wp.array(dtype=wp.vec4),
    levels: wp.array(dtype=Cascade),
    n_levels: int,
    # outputs
    trans_pos: wp.array(dtype=wp.vec3),
    trans_neg: wp.array(dtype=wp.vec3),
    opn: wp.array(dtype=wp.vec3),
    plane: wp.array(dtype=wp.vec3),
    planes: int,
    flags: int,
    offset: int,
):
    """Per receiving cell: transmittance of the face shared with the source at −d, for d = ±x, ±y, ±z;
    and the openness of its three high faces (+x, +y, +z) for the lookup occlusion: 1 − clamp(B(d) or
    B(−d), whichever blocks more) = 1 − clamp(C0·b0 + C1·|b_axis|, 0, 1). With ``planes`` (the offset
    of the blockers' moments in ``gv``, 0: none) and ``flags`` & 2 (lookup planes) also where each high
    face's blocker lies (``plane``), and the openness is at most 1 − clamp(Σ w_axis) (projected
    coverage); with ``flags`` & 1 the transmittances are too (package doc, "Coverage blocking")."""
    i = wp.tid() + offset
    l = find_level(i, levels, n_levels)
    if l < 0:
        return
    e = levels[l]
    res = e.res
    k = i - e.cell_base
    x = k % res
    y = (k // res) % res
    z = k // (res * res)
    r1 = res + 1
    b = e.gv_base
    tp = wp.vec3()
    tn = wp.vec3()
    tp[0] = eval_transmittance(gv_face(gv, b, r1, 0, x, y, z), 0, 1.0)
    tn[0] = eval_transmittance(gv_face(gv, b, r1, 0, x + 1, y, z), 0, -1.0)
    tp[1] = eval_transmittance(gv_face(gv, b, r1, 1, x, y, z), 1, 1.0)
    tn[1] = eval_transmittance(gv_face(gv, b, r1, 1, x, y + 1, z), 1, -1.0)
    tp[2] = eval_transmittance(gv_face(gv, b, r1, 2, x, y, z), 2, 1.0)
    tn[2] = eval_transmittance(gv_face(gv, b, r1, 2, x, y, z + 1), 2, -1.0)
    if planes > 0 and flags % 2 == 1:
        # an opaque face blocks light from either side: at most 1 − its projected coverage Σ A·n_a²/s²
        c2 = b + 2 * planes
        tp[0] = wp.min(tp[0], 1.0 - wp.clamp(gv_face(gv, c2, r1, 0, x, y, z)[0], 0.0, 1.0))
        tn[0] = wp.min(tn[0], 1.0 - wp.clamp(gv_face(gv, c2, r1, 0, x + 1, y, z)[0], 0.0, 1.0))
        tp[1] = wp.min(tp[1], 1.0 - wp.clamp(gv_face(gv, c2, r1, 1, x, y, z)[1], 0.0, 1.0))
        tn[1] = wp.min(tn[1], 1.0 - wp.clamp(gv_face(gv, c2, r1, 1, x, y + 1, z)[1], 0.0, 1.0))
        tp[2] = wp.min(tp[2], 1.0 - wp.clamp(gv_face(gv, c2, r1, 2, x, y, z)[2], 0.0, 1.0))
        tn[2] = wp.min(tn[2], 1.0 - wp.clamp(gv_face(gv, c2, r1, 2, x, y, z + 1)[2], 0.0, 1.0))
    trans_pos[i] = tp
    trans_neg[i] = tn
    o = wp.vec3()
    bx = gv_face(gv, b, r1, 0, x + 1, y, z)
    by = gv_face(gv, b, r1, 1, x, y + 1, z)
    bz = gv_face(gv, b, r1, 2, x, y, z + 1)
    o[0] = 1.0 - wp.clamp(C0 * bx[0] + C1 * wp.abs(bx[1]), 0.0, 1.0)
    o[1] = 1.0 - wp.clamp(C0 * by[0] + C1 * wp.abs(by[2]), 0.0, 1.0)
    o[2] = 1.0 - wp.clamp(C0 * bz[0] + C1 * wp.abs(bz[3]), 0.0, 1.0)
    opn[i] = o
    if planes > 0 and flags >= 2:
        # where the blocker of each high face lies, relative to the face (cells, in [−½, ½]; 0: none)
        t = wp.vec3()
        px = gv_face(gv, b + planes, r1, 0, x + 1, y, z)
        wx = gv_face(gv, b + 2 * planes, r1, 0, x + 1, y, z)
        py = gv_face(gv, b + planes, r1, 1, x, y + 1, z)
        wy = gv_face(gv, b + 2 * planes, r1, 1, x, y + 1, z)
        pz = gv_face(gv, b + planes, r1, 2, x, y, z + 1)
        wz = gv_face(gv, b + 2 * planes, r1, 2, x, y, z + 1)
        if wx[0] > 1.0e-6:
            t[0] = wp.clamp(px[0] / wx[0], -0.5, 0.5)
        if wy[1] > 1.0e-6:
            t[1] = wp.clamp(py[1] / wy[1], -0.5, 0.5)
        if wz[2] > 1.0e-6:
            t[2] = wp.clamp(pz[2] / wz[2], -0.5, 0.5)
        # quantised to 1/254 cell: what the GL twin unpacks (LightPropagationVolume.openness)
        for a in range(3):
            t[a] = wp.round((t[a] + 0.5) * 254.0) / 254.0 - 0.5
        plane[i] = t
        # a lookup is blocked by a face's projected coverage Σ A·n_a²/s² too, whichever side the surfels
        # face (two-sided, the L1 blocking above is only 2/3)
        o[0] = wp.min(o[0], 1.0 - wp.clamp(wx[0], 0.0, 1.0))
        o[1] = wp.min(o[1], 1.0 - wp.clamp(wy[1], 0.0, 1.0))
        o[2] = wp.min(o[2], 1.0 - wp.clamp(wz[2], 0.0, 1.0))
        opn[i] = o


@kernel_factory(geometry_volume=(False, True), clamp_faces=(False, True), loop=(False, True))
def propagate_kernel(geometry_volume: bool, clamp_faces: bool = False, loop: bool = False):
    """The propagation kernel, geometry volume and the face clamp (package doc, "Clamped faces")
    compiled in or out. ``loop=False``: one iteration, one thread per cell (one launch covers every
    cascade). ``loop=True``: every iteration in one single-threaded launch, cascades stopping as
    their counts or the early stop say (``LightPropagationVolume.propagate``: on the CPU, a launch
    per iteration cost more Python than the few thousand cells of a 12³ cascade cost to compute)."""

    @wp.func
    def propagate_cell(
        i: int,
        l: int,
        src: wp.array(dtype=wp.vec4),
        acc_src: wp.array(dtype=wp.vec4),
        trans_pos: wp.array(dtype=wp.vec3),
        trans_neg: wp.array(dtype=wp.vec3),
        levels: wp.array(dtype=Cascade),
        far_from: wp.array(dtype=int),
        iteration: int,
        dst: wp.array(dtype=wp.vec4),
        accum: wp.array(dtype=wp.vec4),
        far: wp.array(dtype=wp.vec4),
    ) -> wp.vec2:
        """Cell i (of level l) gathers one iteration from its 6 neighbours in ``src``: written to
        ``dst``, added to ``accum`` (and to ``far`` past the level's hand-over iteration); returns
        (Σ_RGB |DC| of what it gathered, Σ_RGB |DC| of its accumulated light)."""
        e = levels[l]
        res = e.res
        k = i - e.cell_base
        x = k % res
        y = (k // res) % res
        z = k // (res * res)
        n3 = res * res * res
        rr = res * res
        tp = wp.vec3(1.0, 1.0, 1.0)
        tn = wp.vec3(1.0, 1.0, 1.0)
        if wp.static(geometry_volume):
            tp = trans_pos[i]
            tn = trans_neg[i]
        dc_change = float(0.0)
        dc_total = float(0.0)
        to_far = iteration >= far_from[l]
        for ch in range(3):
            j = e.base + ch * n3 + k
            out = wp.vec4()
            if wp.static(clamp_faces):
                if x > 0:
                    out = gather_clamped(out, tp[0] * src[j - 1], 0, 1.0)
                if x < res - 1:
                    out = gather_clamped(out, tn[0] * src[j + 1], 0, -1.0)
                if y > 0:
                    out = gather_clamped(out, tp[1] * src[j - res], 1, 1.0)
                if y < res - 1:
                    out = gather_clamped(out, tn[1] * src[j + res], 1, -1.0)
                if z > 0:
                    out = gather_clamped(out, tp[2] * src[j - rr], 2, 1.0)
                if z < res - 1:
                    out = gather_clamped(out, tn[2] * src[j + rr], 2, -1.0)
            else:
                # x pair: p = source at x−1 (light travelling +x), m = source at x+1
                p = wp.vec4()
                m = wp.vec4()
                if x > 0:
                    p = tp[0] * src[j - 1]
                if x < res - 1:
                    m = tn[0] * src[j + 1]
                out = gather_pair(out, p, m, 0)
                p = wp.vec4()
                m = wp.vec4()
                if y > 0:
                    p = tp[1] * src[j - res]
                if y < res - 1:
                    m = tn[1] * src[j + res]
                out = gather_pair(out, p, m, 1)
                p = wp.vec4()
                m = wp.vec4()
                if z > 0:
                    p = tp[2] * src[j - rr]
                if z < res - 1:
                    m = tn[2] * src[j + rr]
                out = gather_pair(out, p, m, 2)
            dst[j] = out
            a = acc_src[j] + out
            accum[j] = a
            if to_far:
                far[j] = far[j] + out
            dc_change += wp.abs(out[0])
            dc_total += wp.abs(a[0])
        return wp.vec2(dc_change, dc_total)

    if not loop:

        @wp.kernel(enable_backward=False, module="unique")
        def propagate_lpv(
            # inputs
            src: wp.array(dtype=wp.vec4),
            acc_src: wp.array(dtype=wp.vec4),
            trans_pos: wp.array(dtype=wp.vec3),
            trans_neg: wp.array(dtype=wp.vec3),
            levels: wp.array(dtype=Cascade),
            n_levels: int,
            level_on: wp.array(dtype=int),
            far_from: wp.array(dtype=int),
            iteration: int,
            # outputs
            dst: wp.array(dtype=wp.vec4),
            accum: wp.array(dtype=wp.vec4),
            far: wp.array(dtype=wp.vec4),
            change: wp.array(dtype=float),
            total: wp.array(dtype=float),
            offset: int,
        ):
            i = wp.tid() + offset
            l = find_level(i, levels, n_levels)
            if l < 0:
                return
            if level_on[l] == 0:
                return
            ct = propagate_cell(i, l, src, acc_src, trans_pos, trans_neg, levels, far_from, iteration, dst, accum,
                                far)
            change[i] = ct[0]
            total[i] = ct[1]

        return propagate_lpv

    @wp.kernel(enable_backward=False, module="unique")
    def propagate_lpv_loop(
        # inputs
        inj: wp.array(dtype=wp.vec4),
        trans_pos: wp.array(dtype=wp.vec3),
        trans_neg: wp.array(dtype=wp.vec3),
        levels: wp.array(dtype=Cascade),
        n_levels: int,
        iters: wp.array(dtype=int),
        far_from: wp.array(dtype=int),
        n_iter: int,
        lo: int,
        hi: int,
        thresh: wp.float64,
        # in/out
        level_on: wp.array(dtype=int),
        ping: wp.array(dtype=wp.vec4),
        pong: wp.array(dtype=wp.vec4),
        accum: wp.array(dtype=wp.vec4),
        far: wp.array(dtype=wp.vec4),
        # outputs
        done: wp.array(dtype=int),
        sums: wp.array(dtype=wp.float64),
        offset: int,
    ):
        """Iterations k = 0 … n_iter−1 over cells [lo, hi) of the levels still on: iteration k reads
        ``inj`` (k = 0) or the ping-pong buffer k−1 wrote and writes buffer k % 2 (ping, pong); a level
        stops after iters[l] iterations, or (thresh > 0) once what it gathered in an iteration is at most
        thresh × its accumulated light (Σ over its cells, float64). done[l]: the iterations it ran."""
        for l in range(n_levels):
            done[l] = 0
        for k in range(n_iter):
            live = int(0)
            for l in range(n_levels):
                if level_on[l] != 0 and iters[l] <= k:
                    level_on[l] = 0
                live += level_on[l]
                sums[2 * l] = wp.float64(0.0)
                sums[2 * l + 1] = wp.float64(0.0)
            if live == 0:
                break
            for i in range(lo, hi):
                l = find_level(i, levels, n_levels)
                if l >= 0:
                    if level_on[l] != 0:
                        ct = wp.vec2()
                        if k == 0:
                            ct = propagate_cell(i, l, inj, accum, trans_pos, trans_neg, levels, far_from, k + 1,
                                                ping, accum, far)
                        elif k % 2 == 0:
                            ct = propagate_cell(i, l, pong, accum, trans_pos, trans_neg, levels, far_from, k + 1,
                                                ping, accum, far)
                        else:
                            ct = propagate_cell(i, l, ping, accum, trans_pos, trans_neg, levels, far_from, k + 1,
                                                pong, accum, far)
                        sums[2 * l] = sums[2 * l] + wp.float64(ct[0])
                        sums[2 * l + 1] = sums[2 * l + 1] + wp.float64(ct[1])
            for l in range(n_levels):
                if level_on[l] != 0:
                    done[l] = done[l] + 1
                    if thresh > wp.float64(0.0):
                        c = sums[2 * l]
                        t = sums[2 * l + 1]
                        if c <= thresh * t or t <= wp.float64(0.0):
                            level_on[l] = 0

    return propagate_lpv_loop


@wp.kernel(enable_backward=False)
def hand_over_far(
    # inputs
    far: wp.array(dtype=wp.vec4),
    cascades: wp.array(dtype=Cascade),
    n_cascades: int,
    c: int,
    # outputs
    accum: wp.array(dtype=wp.vec4),
    offset: int,
):
    """accum of active cascade c += Σ_{d>c} (s_c/s_d)²·far_d at each cell centre (trilinear): the
    light coarser cascades carried beyond the finer ones' reach (package doc, "Hand-over")."""
    i = wp.tid() + offset
    g = cascades[c]
    res = g.res
    n3 = res * res * res
    x = i % res
    y = (i // res) % res
    z = i // (res * res)
    centre = g.origin + g.cell * wp.vec3(float(x) + 0.5, float(y) + 0.5, float(z) + 0.5)
    add_r = wp.vec4()
    add_g = wp.vec4()
    add_b = wp.vec4()
    for d in range(c + 1, n_cascades):
        gd = cascades[d]
        rd = gd.res
        u = grid_coord(gd, centre)
        if inside(u, rd):
            scale = (g.cell / gd.cell) * (g.cell / gd.cell)
            nd = rd * rd * rd
            add_r += scale * sample_sh(far, gd.base, rd, u)
            add_g += scale * sample_sh(far, gd.base + nd, rd, u)
            add_b += scale * sample_sh(far, gd.base + 2 * nd, rd, u)
    j = g.base + i
    accum[j] = accum[j] + add_r
    accum[j + n3] = accum[j + n3] + add_g
    accum[j + 2 * n3] = accum[j + 2 * n3] + add_b


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

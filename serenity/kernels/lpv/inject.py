"""LPV injection (package docstring, "Injection" and "Geometry volume"): VPLs scattered into the
cascades' SH grids, surfels into their geometry volumes, and the per-cell measure that says which
cascades received light.

Inputs (Warp arrays on the volume's device): VPL positions (N,) vec3 m, normals (N,) vec3 (any
length; zero skips the VPL), flux (N,) vec3 W per RGB channel; surfel positions (M,) vec3 m, normals
(M,) vec3, areas (M,) float m². Outputs: the SH grids (vec4 per cell and channel, the package's
layout) and the geometry volume ((res+1)³ vec4 per cascade), through ``ScatterGrid`` (scatter
kernels: ``slot_starts``, ``slot_stride``, the grid, ``offset`` last).
"""

from __future__ import annotations

import warp as wp

from serenity.kernels.launch import slot_base
from serenity.kernels.lpv.basis import G0, G1, K0, K1
from serenity.kernels.lpv.grid import Cascade, find_level, grid_coord, inside

wp.set_module_options({"enable_backward": False})


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

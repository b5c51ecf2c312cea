"""The LPV's grids inside a kernel (package docstring: what is stored, propagation, lookups).

A cascade in a kernel is a ``Cascade`` struct (its grid's placement and its offsets in the shared
arrays). Two tables of them: the **levels** (one per config cascade, offsets only: which cells of
the per-cell arrays belong to which grid) and the **cascades** (the fitted or active ones, finest
first, with origin and cell size). This module holds the struct and the Warp functions every stage
reads a grid with (which level a cell is in, world point → grid coordinate, plain trilinear SH); the
stages' kernels are in ``inject`` (VPLs and surfels scattered into the grids), ``propagate`` (the
geometry volume's faces, the iterations, the hand-over) and ``lookup`` (irradiance and glossy lookups,
the temporal blend of what they read). Every kernel is 1-D with a trailing ``offset`` (see
``serenity.kernels.launch``); the scatter kernels (``inject.inject_vpls``, ``inject.inject_geometry``)
follow ``ScatterGrid``'s convention. Flags are compiled in or out by cached factories
(``propagate.propagate_kernel(geometry_volume, ...)``, ``lookup.lookup_irradiance_kernel(leak_guard, ...)``).
"""

from __future__ import annotations

import warp as wp

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

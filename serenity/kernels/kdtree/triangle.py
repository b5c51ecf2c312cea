"""The ray–triangle test, once: Woop, Benthin & Wald's watertight test (2013) with its edge
functions, determinant and t in float64 (exact products of float32), so that no ray leaks through
a closed mesh, and a leaf's triangles under one rule (the closest hit; equal t resolve to the
lower triangle index).

:func:`intersect_triangle` is the test; :func:`intersect_leaf` runs it over a leaf. On the CPU the
leaf's triangles are first tested 8 at a time as SIMD lanes (``leaf8.h``, included by
``triangle.h``'s :func:`leaf_pick` and by the packets' leaf test, ``cpu/packets.h``), in the same
float32 and float64 operations per triangle, and the one triangle that wins is tested again here
for its t, u, v: every path returns the same bits (``tests/kernels/test_kdtree.py``).
"""

from __future__ import annotations

from pathlib import Path

import warp as wp

from .layout import TRACE_MODULE_OPTIONS, KdTreeData, ref_prim, ref_vertex
from .native import native_body

wp.set_module_options(TRACE_MODULE_OPTIONS)

HEADER = Path(__file__).with_name("triangle.h")


@wp.func
def setup_ray(d: wp.vec3):
    """Woop et al.'s ray set-up: the dominant axis kz, the other two (kx, ky, winding-preserving)
    and the shear constants (sx, sy, sz). sz is not finite for a zero/tiny/NaN direction."""
    ax = wp.abs(d[0])
    ay = wp.abs(d[1])
    az = wp.abs(d[2])
    kz = int(2)
    if ax >= ay and ax >= az:
        kz = 0
    elif ay >= az:
        kz = 1
    kx = (kz + 1) % 3
    ky = (kx + 1) % 3
    if d[kz] < 0.0:
        tmp = kx
        kx = ky
        ky = tmp
    sx = d[kx] / d[kz]
    sy = d[ky] / d[kz]
    sz = 1.0 / d[kz]
    return kx, ky, kz, sx, sy, sz


@wp.func
def intersect_triangle(
    o: wp.vec3,
    kx: int,
    ky: int,
    kz: int,
    sx: float,
    sy: float,
    sz: float,
    p0: wp.vec3,
    p1: wp.vec3,
    p2: wp.vec3,
    tmin: float,
    tmax: float,
):
    """Watertight ray–triangle test (Woop, Benthin, Wald 2013). Returns (hit, t, u, v) with
    tmin < t ≤ tmax; edge functions, determinant and t in float64 (exact products of float32)."""
    a = p0 - o
    b = p1 - o
    c = p2 - o
    a_x = a[kx] - sx * a[kz]
    a_y = a[ky] - sy * a[kz]
    b_x = b[kx] - sx * b[kz]
    b_y = b[ky] - sy * b[kz]
    c_x = c[kx] - sx * c[kz]
    c_y = c[ky] - sy * c[kz]
    t = float(0.0)
    u = float(0.0)
    v = float(0.0)
    eu = wp.float64(c_x) * wp.float64(b_y) - wp.float64(c_y) * wp.float64(b_x)
    ev = wp.float64(a_x) * wp.float64(c_y) - wp.float64(a_y) * wp.float64(c_x)
    ew = wp.float64(b_x) * wp.float64(a_y) - wp.float64(b_y) * wp.float64(a_x)
    zero = wp.float64(0.0)
    hit = True
    # outside when two edge functions have opposite signs; as bit operations on 0/1 rather than
    # Python's short-circuit 'or'/'and', which Warp turns into a chain of branches
    neg = wp.where(eu < zero, 1, 0) | wp.where(ev < zero, 1, 0) | wp.where(ew < zero, 1, 0)
    pos = wp.where(eu > zero, 1, 0) | wp.where(ev > zero, 1, 0) | wp.where(ew > zero, 1, 0)
    if (neg & pos) != 0:
        hit = False
    else:
        det = eu + ev + ew
        if det == zero:
            hit = False
        else:
            tt = (eu * wp.float64(sz * a[kz]) + ev * wp.float64(sz * b[kz]) + ew * wp.float64(sz * c[kz])) / det
            t = float(tt)
            if not (t > tmin and t <= tmax):
                hit = False
            else:
                u = float(ev / det)
                v = float(ew / det)
    return hit, t, u, v


@wp.func
def intersect_triangle_fixed(
    o: wp.vec3,
    kx: int,
    ky: int,
    kz: int,
    sx: float,
    sy: float,
    sz: float,
    p0: wp.vec3,
    p1: wp.vec3,
    p2: wp.vec3,
    tmin: float,
    tmax: float,
):
    """``intersect_triangle`` with the ray's axis permutation (kx, ky, kz) turned into constants:
    one of its six forms is chosen per call, each inlined with literal axes, so the vertices'
    components are registers instead of indexed loads from the stack (the same arithmetic, the
    same bits)."""
    hit = False
    t = float(0.0)
    u = float(0.0)
    v = float(0.0)
    if kz == 2:
        if kx == 0:
            hit, t, u, v = intersect_triangle(o, 0, 1, 2, sx, sy, sz, p0, p1, p2, tmin, tmax)
        else:
            hit, t, u, v = intersect_triangle(o, 1, 0, 2, sx, sy, sz, p0, p1, p2, tmin, tmax)
    elif kz == 1:
        if kx == 2:
            hit, t, u, v = intersect_triangle(o, 2, 0, 1, sx, sy, sz, p0, p1, p2, tmin, tmax)
        else:
            hit, t, u, v = intersect_triangle(o, 0, 2, 1, sx, sy, sz, p0, p1, p2, tmin, tmax)
    else:
        if kx == 1:
            hit, t, u, v = intersect_triangle(o, 1, 2, 0, sx, sy, sz, p0, p1, p2, tmin, tmax)
        else:
            hit, t, u, v = intersect_triangle(o, 2, 1, 0, sx, sy, sz, p0, p1, p2, tmin, tmax)
    return hit, t, u, v


@wp.func_native(native_body(HEADER, "leaf_pick"))
def leaf_pick(refs: wp.array(dtype=float), first: int, k: int, o: wp.vec3, kx: int, ky: int, kz: int, sx: float,
              sy: float, sz: float, tlo: float, best_t: float, prim: int, any_hit: int) -> int:
    """Which of a leaf's ``k`` triangles (its block at word ``first`` of ``refs``) :func:`intersect_leaf`'s
    loop would end on: Woop's test for 8 triangles at a time as SIMD lanes (``leaf8.h``), in the loop's
    float32 and float64 operations per triangle, then the hits in the triangles' order under its rule
    (closer, or as close with a lower index than the best so far, ``best_t`` and ``prim``; the first
    such for ``any_hit``). Returns the triangle's place in the leaf, -1 if none beats the best so
    far, and -2 on CUDA, where the loop runs as it is."""
    ...


@wp.func
def intersect_leaf(
    tree: KdTreeData,
    first_ref: int,
    count: int,
    o: wp.vec3,
    kx: int,
    ky: int,
    kz: int,
    sx: float,
    sy: float,
    sz: float,
    tlo: float,
    best_t: float,
    prim: int,
    hit_u: float,
    hit_v: float,
    any_hit: bool,
):
    """A leaf of :func:`trace_kd`'s walk: its ``count`` triangles from reference ``first_ref`` on,
    against the ray's Woop set-up (:func:`setup_ray`), tested against the best hit so far (prim,
    best_t, hit_u, hit_v), which it returns updated (the lower primitive index wins a tie). On the
    CPU :func:`leaf_pick` finds the triangle the loop below would end on, 8 at a time in SIMD, and
    that one triangle's test gives its t, u, v: the loop's bits."""
    pick = leaf_pick(tree.refs, first_ref, count, o, kx, ky, kz, sx, sy, sz, tlo, best_t, prim,
                     wp.where(any_hit, 1, 0))
    if pick >= 0:
        r = first_ref + pick
        p0 = ref_vertex(tree.refs, r, count)
        p1 = ref_vertex(tree.refs, r + 3 * count, count)
        p2 = ref_vertex(tree.refs, r + 6 * count, count)
        hit, t, u, v = intersect_triangle_fixed(o, kx, ky, kz, sx, sy, sz, p0, p1, p2, tlo, best_t)
        best_t = t
        prim = ref_prim(tree.refs, r + 9 * count)
        hit_u = u
        hit_v = v
        count = 0  # done
    elif pick == -1:
        count = 0  # no triangle beats the best so far
    for j in range(count):
        r = first_ref + j
        p0 = ref_vertex(tree.refs, r, count)
        p1 = ref_vertex(tree.refs, r + 3 * count, count)
        p2 = ref_vertex(tree.refs, r + 6 * count, count)
        hit, t, u, v = intersect_triangle_fixed(o, kx, ky, kz, sx, sy, sz, p0, p1, p2, tlo, best_t)
        f = int(-1)
        if hit:
            f = ref_prim(tree.refs, r + 9 * count)
        if hit and (t < best_t or f < prim):
            best_t = t
            prim = f
            hit_u = u
            hit_v = v
            if any_hit:
                break
    return prim, best_t, hit_u, hit_v

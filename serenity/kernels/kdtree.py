"""kd-tree traversal in Warp kernels, and the host class that builds, caches and queries a tree (paper §9).

:class:`KdTree` takes a scene's triangles (vertices (V,3) and faces (F,3)), builds or loads its
SAH kd-tree (:mod:`serenity.kernels.kdtree_build`, settings :class:`serenity.config.KdBuildConfig`)
and answers two queries on a device:

- :meth:`KdTree.intersect`: closest hits of rays with origins ``o`` (N,3) and directions ``d``
  (N,3) float32, t in units of |d| (directions need not be unit), hits with tmin < t < tmax:
  :class:`Hits` of ``t`` (N,) float32 (inf on a miss), ``prim`` (N,) int32 (−1), barycentrics
  ``u``, ``v`` (N,) float32 with p = (1−u−v)·v0 + u·v1 + v·v2 (Embree's convention); equal t
  resolve to the lower triangle index.
- :meth:`KdTree.occluded`: any hit, (N,) bool.

Degenerate rays (a zero, NaN or infinite direction, a NaN origin, tmax ≤ tmin or NaN) are misses.
The ray–triangle test is Woop, Benthin & Wald's watertight test with its edge functions in float64,
so no ray leaks through a closed mesh, and every path — one ray per kernel thread (CUDA, small
batches), interleaved rays, 16-ray packets, reordered or not, any thread count — returns the same
hits bit for bit (tests). The tracing kernels are compiled without FMA contraction
(``TRACE_MODULE_OPTIONS``) so that CUDA's hits equal the CPU's.

Layout on a device (:class:`KdTreeData`, made from the build's arrays by :meth:`KdTree.device_data`;
``nodes`` and ``refs`` contiguous, as the traversal's native loads :func:`node_head` etc. assume):
    nodes (nodes,) KdNode, 8 bytes: inner node: ``head`` = (first child << 4) | (right child is an
        empty leaf) << 3 | (left child is an empty leaf) << 2 | axis (children are consecutive: left
        at first child, right at first child + 1), ``split`` = the split position (world units);
        leaf: ``head`` = (its block's first word in ``refs`` << 2) | 3, ``split`` = its triangle count.
    refs (W,) float32: one block of 10·k words per non-empty leaf of k triangles: the triangles'
        vertex coordinates (the k x of v0, the k y of v0, …, the k z of v2), then their indices (as
        int32 bits), 40 bytes per reference; padded by ``REF_PAD`` words.
    tri_verts (3F,) vec3: the three vertices of triangle f at 3f, 3f+1, 3f+2 (for shading a hit).

How the traversal, the ray reordering, the packets and the threading work, why each is the way
it is, and their figures: docs/kdtree.md.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from serenity.config import KD_MAX_DEPTH, KdBuildConfig
from serenity.device import cpu_threads, init_warp, resolve_device
from serenity.errors import SerenityError
from serenity.kernels.factory import kernel_factory
from serenity.kernels.kdtree_build import (
    CACHE_MIN_TRIANGLES,
    PROGRESS_MIN_TRIANGLES,
    KdStats,
    build_arrays,
    cache_dir,
    geometry_key,
    load_tree,
    save_tree,
    validate_mesh,
)
from serenity.kernels.launch import MIN_ITEMS_PER_CHUNK, Staging, launch

#: Kernels that trace (here and in ``raytrace``) are compiled without floating-point contraction
#: (``fuse_fp``): NVRTC fuses a multiply and an add into one FMA across statements, which moved the
#: sheared vertex coordinates of Woop's test by an ulp and let 1-2 % of rays aimed at the vertices
#: and edges of closed meshes through on an NVIDIA H200 (0 with contraction off); unfused, CUDA's
#: hits are bit-identical to the CPU's (``tests/kernels/test_kdtree.py``).
TRACE_MODULE_OPTIONS = {"enable_backward": False, "fuse_fp": False}
wp.set_module_options(TRACE_MODULE_OPTIONS)

# ----------------------------------------------------------------------------------------------
# constants
# ----------------------------------------------------------------------------------------------

#: traversal stack entries: the stack holds at most one entry per level of the tree (the far children
#: of the current node's ancestors), so a tree of depth <= KD_MAX_DEPTH never overflows it and the
#: traversal does not test for that (``KdTree.device_data`` refuses a deeper tree)
STACK_SIZE = KD_MAX_DEPTH + 2
#: words of padding after the last leaf block (``refs``): SIMD leaf tests load 8 or 16 words at a time
REF_PAD = 16
#: a ray goes on through at most this many cut-out hits the alpha test rejects (``KdTree.set_alpha_test``)
MAX_CUTOUT_LAYERS = 64
T_TOLERANCE = 1e-6  # relative (to the scene scale) overlap of near/far traversal intervals
BOX_PADDING = 1e-5  # the root box is padded by this fraction of its largest extent
TINY_DIRECTION = 1e-30  # a direction whose largest |component| is below this is a miss
#: CPU launches of rays are balanced (``launch(balanced=True)``): rays differ a lot in cost (sky vs
#: geometry), and one contiguous chunk per thread left 2 threads at 1.45-1.48x one on the
#: benchmark's rays. The interleaved kernel gives its kernel threads few enough rays that a launch
#: still has this many ``MIN_ITEMS_PER_CHUNK``-item chunks' worth of them per worker (``_slot_rays``)
CHUNKS_PER_THREAD = 16
#: ray reordering (``sort=None`` in the queries): batches of at least this many rays are traced in
#: the order of a ``SORT_KEY_BITS``-bit key (:func:`ray_sort_key`): the Morton code of the origin's cell on a
#: ``SORT_COARSE_BITS``-bit grid per axis over the root box, the direction's octant, the origin's
#: cell on the finer ``SORT_ORIGIN_BITS``-bit grid within the coarse cell, then the direction's cell
#: on a ``SORT_DIRECTION_BITS``-bit grid per coordinate of the octant's octahedral map, so that
#: consecutive rays walk the same nodes and triangles (docs/kdtree.md, "Ray reordering")
SORT_MIN_RAYS = 1 << 15
SORT_MIN_RUN = 4  # ... whose keys change on average more often than every this many rays (``ray_order``)
#: ... estimated from this many evenly spaced pairs of consecutive rays (a coherent batch is then
#: traced without a key per ray: 3 % of a camera batch's time)
SORT_SAMPLE_PAIRS = 4096
#: interleaved CPU queries (docs/kdtree.md, "Interleaved rays"; ``rays_per_thread``): the slot
#: counts the kernel factory ``trace_rays_kernel`` compiles, the usual slot count, and the most rays a
#: slot takes in turn in one kernel thread (fewer when that would leave a launch too few chunks to
#: balance the threads: ``_slot_rays``)
INTERLEAVE_FACTORS = (2, 4)
CPU_RAYS_PER_THREAD = 2
RAYS_PER_SLOT = 8
SORT_COARSE_BITS = 3
SORT_ORIGIN_BITS = 5
SORT_DIRECTION_BITS = 5
#: the key's bits, sorted on the CPU as two digits of ``SORT_DIGIT_BITS`` (``counting_order``)
SORT_KEY_BITS = 3 * SORT_ORIGIN_BITS + 3 + 2 * SORT_DIRECTION_BITS
SORT_DIGIT_BITS = 14
assert SORT_KEY_BITS <= 2 * SORT_DIGIT_BITS and SORT_KEY_BITS < 32 and SORT_COARSE_BITS <= SORT_ORIGIN_BITS
#: :func:`batch_is_coherent` compares keys without their low bits: the origin's fine cell and the
#: octant stay, the direction's cell only to its 2 top bits per coordinate (a camera's neighbouring
#: pixels share it)
SORT_SAMPLE_SHIFT = 2 * (SORT_DIRECTION_BITS - 2)
#: the CPU counting sort's count gives each thread a contiguous run of at least this many keys (below
#: it, one thread: zeroing and summing a thread's bins costs about as much as counting them)
SORT_MIN_KEYS_PER_THREAD = 1 << 16
assert STACK_SIZE & (STACK_SIZE - 1) == 0  # a power of 2: the stack index is masked (``_STACK_MASK``)
_STACK_MASK = wp.constant(STACK_SIZE - 1)
_stack_i = wp.types.vector(length=STACK_SIZE, dtype=wp.int32)
_stack_f = wp.types.vector(length=STACK_SIZE, dtype=wp.float32)

_INF = wp.constant(math.inf)
_TOL = wp.constant(T_TOLERANCE)
_TINY = wp.constant(TINY_DIRECTION)
_FLT_MAX = wp.constant(float(np.finfo(np.float32).max))
_SORT_CELLS = wp.constant(float(1 << SORT_ORIGIN_BITS))
_SORT_FINE = wp.constant(3 * (SORT_ORIGIN_BITS - SORT_COARSE_BITS))
_SORT_DIR_CELLS = wp.constant(float(1 << SORT_DIRECTION_BITS))
_SORT_BINS = wp.constant(1 << SORT_DIGIT_BITS)
_SORT_DIGIT = wp.constant(SORT_DIGIT_BITS)
_SORT_DIGIT_MASK = wp.constant((1 << SORT_DIGIT_BITS) - 1)
_SORT_SAMPLE_SHIFT = wp.constant(SORT_SAMPLE_SHIFT)


# ----------------------------------------------------------------------------------------------
# structs
# ----------------------------------------------------------------------------------------------


@wp.struct
class KdNode:
    """One node, 8 bytes: ``head`` = (first child << 4) | empty-children flags << 2 | axis, or
    (first reference << 2) | 3 for a leaf; ``split`` = the split position of an inner node, the
    triangle count of a leaf (module docstring, layout)."""

    head: wp.int32
    split: wp.float32


@wp.struct
class KdTreeData:
    """The tree on one device (see the module docstring for the layout)."""

    nodes: wp.array(dtype=KdNode)
    refs: wp.array(dtype=wp.float32)
    tri_verts: wp.array(dtype=wp.vec3)
    box_lo: wp.vec3  # padded root box
    box_hi: wp.vec3
    scale: float  # largest |coordinate| of the root box, for the t tolerance


# ----------------------------------------------------------------------------------------------
# functions
# ----------------------------------------------------------------------------------------------


# Loads without Warp's index arithmetic. Warp's ``a[i]`` multiplies ``i`` by the array's run-time
# stride and wraps a negative ``i``, both on the traversal's chain of dependent loads (node, next
# node, ...); these read element ``i`` of a contiguous array (``device_data`` makes them so) at
# ``data + i * sizeof(element)``, a compile-time size: one scaled-index load. ``i`` must be in range.


@wp.func_native("return nodes.data[(unsigned)i].head;")
def node_head(nodes: wp.array(dtype=KdNode), i: int) -> int:
    """``nodes[i].head`` (see the note above)."""
    ...


@wp.func_native("return nodes.data[(unsigned)i].split;")
def node_split(nodes: wp.array(dtype=KdNode), i: int) -> float:
    """``nodes[i].split`` (see the note above)."""
    ...


@wp.func_native("const float* p = refs.data + (unsigned)i; return wp::vec3(p[0], p[k], p[2 * k]);")
def ref_vertex(refs: wp.array(dtype=float), i: int, k: int) -> wp.vec3:
    """A vertex of a leaf's block (module docstring, ``refs``): its x at word ``i``, y and z ``k``
    and ``2k`` words on (``k`` = the leaf's triangle count)."""
    ...


@wp.func_native("return ((const int*)refs.data)[(unsigned)i];")
def ref_prim(refs: wp.array(dtype=float), i: int) -> int:
    """The triangle index stored (as its bits) at word ``i`` of a leaf's block."""
    ...


@wp.func
def finite(x: float) -> bool:
    """``wp.isfinite`` for float32, inline: false for ±inf and NaN (every comparison with NaN is
    false). Warp's CPU ``isfinite`` is a call into its runtime, ~10 per ray in ``start_ray``."""
    return wp.abs(x) <= _FLT_MAX


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


@wp.func
def start_ray(tree: KdTreeData, o: wp.vec3, d: wp.vec3, tmin: float, tmax: float):
    """A ray's traversal set-up: Woop's (kx, ky, kz, sx, sy, sz), the inverse direction ``inv`` (0 on
    an axis the ray is parallel to), its segment (t0, t1) in the padded root box, the interval
    overlap ``teps``, the lower bound ``tlo`` of hits, and whether there is nothing to trace."""
    kx, ky, kz, sx, sy, sz = setup_ray(d)
    tlo = wp.max(tmin, 0.0)
    t0 = tlo
    t1 = tmax
    valid = finite(o[0]) and finite(o[1]) and finite(o[2])
    valid = valid and finite(d[0]) and finite(d[1]) and finite(d[2])
    valid = valid and wp.abs(d[kz]) >= _TINY and finite(sz) and t1 > t0
    inv = wp.vec3(0.0, 0.0, 0.0)  # 0 marks an axis the ray is parallel to
    if valid:
        for a in range(3):
            if d[a] != 0.0:
                r = 1.0 / d[a]
                if finite(r):
                    inv[a] = r
        # root box clip
        for a in range(3):
            if inv[a] == 0.0:
                if o[a] < tree.box_lo[a] or o[a] > tree.box_hi[a]:
                    valid = False
            else:
                ta = (tree.box_lo[a] - o[a]) * inv[a]
                tb = (tree.box_hi[a] - o[a]) * inv[a]
                t0 = wp.max(t0, wp.min(ta, tb))
                t1 = wp.min(t1, wp.max(ta, tb))
    ao = wp.max(wp.max(wp.abs(o[0]), wp.abs(o[1])), wp.abs(o[2]))
    teps = _TOL * (tree.scale + ao) * wp.abs(sz)
    done = not valid or t0 > t1 + teps
    return kx, ky, kz, sx, sy, sz, inv, t0, t1, teps, tlo, done


@wp.func
def trace_kd(tree: KdTreeData, o: wp.vec3, d: wp.vec3, tmin: float, tmax: float, any_hit: bool):
    """Front-to-back kd-tree traversal. Returns (prim, t, u, v); prim = −1 and t = inf on a miss.
    ``any_hit`` stops at the first hit in (tmin, tmax) (occlusion); otherwise the closest hit."""
    prim = int(-1)
    best_t = tmax
    hit_u = float(0.0)
    hit_v = float(0.0)
    kx, ky, kz, sx, sy, sz, inv, t0, t1, teps, tlo, done = start_ray(tree, o, d, tmin, tmax)
    node = int(0)
    sp = int(0)
    st_node = _stack_i()
    st_t0 = _stack_f()
    st_t1 = _stack_f()
    while not done:
        head = node_head(tree.nodes, node)  # a load at data + 8 node (no stride multiply, no index wrap)
        axis = head & 3
        leaf_end = False  # a leaf is done (or an empty one skipped): stop or pop
        if axis != 3:
            split = node_split(tree.nodes, node)
            child = head >> 4
            oa = o[axis]
            first = child
            second = child + 1
            empty_first = (head >> 2) & 1  # the flags of the empty leaves among the children
            empty_second = (head >> 3) & 1
            if oa > split or (oa == split and d[axis] > 0.0):
                first = child + 1
                second = child
                empty_first = (head >> 3) & 1
                empty_second = (head >> 2) & 1
            ia = inv[axis]
            if ia == 0.0:
                # parallel to the plane: only the side of the origin, both when on the plane
                if oa == split and empty_second == 0:
                    k = sp & _STACK_MASK  # not negative: no index wrap
                    st_node[k] = second
                    st_t0[k] = t0
                    st_t1[k] = t1
                    sp += 1
                node = first
                leaf_end = empty_first != 0
            else:
                ts = (split - oa) * ia
                if ts <= 0.0 or ts > t1 + teps:
                    node = first
                    leaf_end = empty_first != 0
                elif ts < t0 - teps:
                    node = second
                    leaf_end = empty_second != 0
                else:
                    if empty_second == 0:
                        k = sp & _STACK_MASK
                        st_node[k] = second
                        st_t0[k] = wp.max(t0, ts - teps)
                        st_t1[k] = t1
                        sp += 1
                    node = first
                    t1 = wp.min(t1, ts + teps)
                    leaf_end = empty_first != 0
        else:
            prim, best_t, hit_u, hit_v = intersect_leaf(tree, head >> 2, int(node_split(tree.nodes, node)), o, kx,
                                                        ky, kz, sx, sy, sz, tlo, best_t, prim, hit_u, hit_v,
                                                        any_hit)
            leaf_end = True
        if leaf_end:
            if prim >= 0 and (any_hit or best_t <= t1):
                done = True
            else:
                popped = int(0)
                while sp > 0 and popped == 0:
                    sp -= 1
                    k = sp & _STACK_MASK
                    node = st_node[k]
                    t0 = st_t0[k]
                    t1 = st_t1[k]
                    if t0 <= best_t:
                        popped = 1
                if popped == 0:
                    done = True
    if prim < 0:
        best_t = _INF
    return prim, best_t, hit_u, hit_v


@wp.func
def inner_step_flat(head: int, split: float, oa: float, ia: float, axis_flags: int, t0: float, t1: float,
                    teps: float):
    """:func:`trace_kd`'s inner-node step without branches, for the interleaved kernels: the ray's
    origin ``oa`` and inverse direction ``ia`` on the node's axis, ``axis_flags`` = (direction > 0)
    | (parallel to the axis) << 1 there, its interval (t0, t1). Returns (next node, its t1, push
    (0/1), the node to push, its t0, the next node is an empty leaf (0/1)); a pushed entry's t1 is
    the ray's t1 before the step. The same choices as ``trace_kd``'s, as 0/1 arithmetic: a
    mispredicted branch discards the other slots' work in flight, Warp turns ``and``/``or`` into
    branches, and the compiler turns an integer select on the loop's chain back into one."""
    child = head >> 4
    dpos = axis_flags & 1
    par = axis_flags >> 1
    gt = wp.where(oa > split, 1, 0)
    ge = wp.where(oa >= split, 1, 0)
    swap = gt | (ge & dpos)  # 1: the origin is on the right child's side (on the plane: the ray goes there)
    ts = (split - oa) * ia  # 0 when parallel (the origin lies in the root box, so split - oa is finite)
    tn = ts + teps
    tf = ts - teps
    near_only = par | wp.where(ts <= 0.0, 1, 0) | wp.where(ts > t1 + teps, 1, 0)
    far_only = (near_only ^ 1) & wp.where(ts < t0 - teps, 1, 0)
    both = (near_only | far_only) ^ 1
    pick = swap ^ far_only  # the next child: the origin's side, or the other one when only that is crossed
    empty_second = (head >> (3 - swap)) & 1
    # parallel to the plane and on it: both children, as in trace_kd (ge & not gt: oa == split)
    push = (both | (par & ge & (gt ^ 1))) & (empty_second ^ 1)
    new_t1 = wp.where((both & wp.where(tn < t1, 1, 0)) != 0, tn, t1)
    pushed_t0 = wp.where(((par ^ 1) & wp.where(tf > t0, 1, 0)) != 0, tf, t0)
    return child + pick, new_t1, push, child + 1 - swap, pushed_t0, (head >> (2 + pick)) & 1


# The SIMD leaf test's C, shared by leaf_pick and leaf_simd: Woop's test on 8 triangles of a leaf at a
# time, then their hits in order under intersect_leaf's rule; ends with the best's triangle index
# ``prim``, its t ``best`` and its place in the leaf ``found`` (-1: none beat the best so far).
_LEAF_SIMD = """
typedef float f8 __attribute__((ext_vector_type(8)));
typedef double d8 __attribute__((ext_vector_type(8)));
typedef int i8 __attribute__((ext_vector_type(8)));
const float* R = refs.data + (unsigned)first;
const int* P = (const int*)R + 9 * (size_t)k;
const float oc[3] = {o.c[0], o.c[1], o.c[2]};
const d8 dz = 0.0;
typedef __typeof__(dz < dz) l8;  /* the mask type of a float64 comparison */
float best = best_t;
int found = -1;
double ev_found = 0.0, ew_found = 0.0, det_found = 1.0;
for (int b = 0; b < k; b += 8) {
    f8 w[3][3];  /* [vertex][axis]: the vertex minus the origin, as trace_kd's a = p0 - o */
    for (int v = 0; v < 3; ++v)
        for (int a = 0; a < 3; ++a) {
            f8 x;
            __builtin_memcpy(&x, R + (3 * v + a) * (size_t)k + b, sizeof(f8));
            w[v][a] = x - oc[a];
        }
    d8 ex[3], ey[3];
    f8 ez[3];
    for (int v = 0; v < 3; ++v) {
        ex[v] = __builtin_convertvector(w[v][kx] - sx * w[v][kz], d8);
        ey[v] = __builtin_convertvector(w[v][ky] - sy * w[v][kz], d8);
        ez[v] = w[v][kz];
    }
    /* Woop's edge functions in float64 (a = vertex 0, b = vertex 1, c = vertex 2) */
    d8 eu = ex[2] * ey[1] - ey[2] * ex[1];
    d8 ev = ex[0] * ey[2] - ey[0] * ex[2];
    d8 ew = ex[1] * ey[0] - ey[1] * ex[0];
    l8 neg = (eu < dz) | (ev < dz) | (ew < dz);
    l8 pos = (eu > dz) | (ev > dz) | (ew > dz);
    d8 det = eu + ev + ew;
    l8 ok = ~(neg & pos) & (det != dz);
    d8 tt = (eu * __builtin_convertvector(sz * ez[0], d8) + ev * __builtin_convertvector(sz * ez[1], d8)
             + ew * __builtin_convertvector(sz * ez[2], d8)) / det;
    f8 t = __builtin_convertvector(tt, f8);
    i8 in = __builtin_convertvector(ok, i8) & (t > tlo) & (t <= best);
    unsigned int m = 0;
    for (int j = 0; j < 8; ++j) m |= (in[j] != 0 && b + j < k) ? (1u << j) : 0u;
    while (m) {
        int j = __builtin_ctz(m);
        m &= m - 1;
        int f = P[b + j];
        float tj = t[j];
        if (tj <= best && (tj < best || f < prim)) {
            best = tj;
            prim = f;
            found = b + j;
            ev_found = ev[j];
            ew_found = ew[j];
            det_found = det[j];
            if (any_hit) { m = 0; b = k; }
        }
    }
}
"""


@wp.func_native("#if defined(__CUDA_ARCH__)\nreturn -2;\n#else\n" + _LEAF_SIMD + "return found;\n#endif\n")
def leaf_pick(refs: wp.array(dtype=float), first: int, k: int, o: wp.vec3, kx: int, ky: int, kz: int, sx: float,
              sy: float, sz: float, tlo: float, best_t: float, prim: int, any_hit: int) -> int:
    """Which of a leaf's ``k`` triangles (its block at word ``first`` of ``refs``) :func:`intersect_leaf`'s
    loop would end on: Woop's test for 8 triangles at a time as SIMD lanes, in the loop's float32 and
    float64 operations per triangle, then the hits in the triangles' order under its rule (closer,
    or as close with a lower index than the best so far, ``best_t`` and ``prim``; the first such for
    ``any_hit``). Returns the triangle's place in the leaf, -1 if none beats the best so far, and -2
    on CUDA, where the loop runs as it is."""
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


@wp.func
def leaf_hits(
    tree: KdTreeData,
    first_ref: int,
    count: int,
    o: wp.vec3,
    d: wp.vec3,
    tlo: float,
    best_t: float,
    prim: int,
    hit_u: float,
    hit_v: float,
    any_hit: bool,
):
    """:func:`intersect_leaf` for the interleaved kernels, which make Woop's set-up again here (one
    leaf per ray or so) rather than keep it per slot."""
    kx, ky, kz, sx, sy, sz = setup_ray(d)
    return intersect_leaf(tree, first_ref, count, o, kx, ky, kz, sx, sy, sz, tlo, best_t, prim, hit_u, hit_v,
                          any_hit)


# ----------------------------------------------------------------------------------------------
# kernels
# ----------------------------------------------------------------------------------------------


@wp.func
def origin_cell(o: float, lo: float, scale: float) -> int:
    """The cell of coordinate ``o`` on the sort grid of one axis, ``scale`` = cells / the box's extent
    (outside the box, or NaN: the border cell)."""
    f = (o - lo) * scale
    f = wp.where(f >= 0.0, f, 0.0)
    return int(wp.min(f, _SORT_CELLS - 1.0))


# The Morton spreads of the sort key: one BMI2 ``pdep`` each where the CPU has it (the module is
# compiled for the host CPU), else shifts and masks (CUDA, other CPUs). As loops over the bits they
# took 15 ms for the keys of a 0.92 M-ray batch on one thread, pdep 10 ms: clang turned the loops
# into chains of vector shuffles.


#: the Morton spreads' masks: (the pdep mask, then (shift, mask) per step of the portable spread) for
#: 2 and 3 coordinates; bits b < 5 of the coordinate go to bit 2b or 3b
_SPREAD = {
    2: (0x55555555, ((8, 0x00FF00FF), (4, 0x0F0F0F0F), (2, 0x33333333), (1, 0x55555555))),
    3: (0x49249249, ((16, 0x030000FF), (8, 0x0300F00F), (4, 0x030C30C3), (2, 0x09249249))),
}
assert SORT_ORIGIN_BITS <= 5 and SORT_DIRECTION_BITS <= 5


def _spread_c(var: str, axes: int, suffix: str = "u") -> str:
    """C that spreads the low bits of ``var`` (already masked to them) for a Morton code of ``axes``
    coordinates, by shifts and masks (scalar with ``suffix`` "u", or a vector of ints with "")."""
    steps = _SPREAD[axes][1]
    return "\n".join(f"{var} = ({var} | ({var} << {shift})) & 0x{mask:08X}{suffix};" for shift, mask in steps)


def _spread_native(bits: int, axes: int) -> str:
    """The body of :func:`spread_bits` / :func:`spread_bits2`: one BMI2 ``pdep`` where the CPU has
    it, else :func:`_spread_c`."""
    return f"""
#if defined(__BMI2__) && !defined(__CUDA_ARCH__)
return (int)__builtin_ia32_pdep_si((unsigned int)q & {(1 << bits) - 1}u, 0x{_SPREAD[axes][0]:08X}u);
#else
unsigned int x = (unsigned int)q & {(1 << bits) - 1}u;
{_spread_c("x", axes)}
return (int)x;
#endif
"""


@wp.func_native(_spread_native(SORT_ORIGIN_BITS, 3))
def spread_bits(q: int) -> int:
    """Bit b of ``q`` (b < SORT_ORIGIN_BITS) moved to bit 3b: one axis' share of a Morton code."""
    ...


@wp.func_native(_spread_native(SORT_DIRECTION_BITS, 2))
def spread_bits2(q: int) -> int:
    """Bit b of ``q`` (b < SORT_DIRECTION_BITS) moved to bit 2b: one coordinate's share of a 2-D
    Morton code."""
    ...


@wp.func
def ray_sort_key(box_lo: wp.vec3, scale: wp.vec3, o: wp.vec3, d: wp.vec3) -> int:
    """The reordering key of a ray (``SORT_KEY_BITS`` bits, high to low): the Morton code of its
    origin's cell on a 2^SORT_COARSE_BITS grid per axis over the root box, its direction's octant,
    the Morton code of its origin's cell on the 2^SORT_ORIGIN_BITS grid within that coarse cell
    (``scale`` = fine cells / the box's extent per axis, :func:`sort_scale`; origins outside the box,
    or NaN, clamp to the border cells), then the Morton code of the direction's cell on a
    2^SORT_DIRECTION_BITS grid per coordinate of the octahedral map of its octant
    (|d| / (|dx| + |dy| + |dz|), x and y). So rays of
    one coarse cell heading into one octant are together, and within them rays from nearby points
    in nearby directions: 16 neighbours in the order make a packet whose lanes share nodes
    (docs/kdtree.md, "Ray reordering"). Straight-line code: loops over the axes with a run-time
    index take about twice as long."""
    origin = (spread_bits(origin_cell(o[0], box_lo[0], scale[0]))
              | (spread_bits(origin_cell(o[1], box_lo[1], scale[1])) << 1)
              | (spread_bits(origin_cell(o[2], box_lo[2], scale[2])) << 2))
    ax = wp.abs(d[0])
    ay = wp.abs(d[1])
    octant = wp.where(d[0] < 0.0, 1, 0) | wp.where(d[1] < 0.0, 2, 0) | wp.where(d[2] < 0.0, 4, 0)
    l1 = ax + ay + wp.abs(d[2])
    # zero, NaN or infinite (a miss anyway): cell 0
    s = wp.where((wp.where(l1 > 0.0, 1, 0) & wp.where(l1 <= _FLT_MAX, 1, 0)) != 0, _SORT_DIR_CELLS / l1, 0.0)
    qu = int(wp.min(wp.where(s > 0.0, ax * s, 0.0), _SORT_DIR_CELLS - 1.0))
    qv = int(wp.min(wp.where(s > 0.0, ay * s, 0.0), _SORT_DIR_CELLS - 1.0))
    direction = spread_bits2(qu) | (spread_bits2(qv) << 1)
    coarse = origin >> _SORT_FINE
    fine = origin & ((1 << _SORT_FINE) - 1)
    return (((((coarse << 3) | octant) << _SORT_FINE) | fine) << wp.static(2 * SORT_DIRECTION_BITS)) | direction


def sort_scale(box_lo: wp.vec3, box_hi: wp.vec3) -> wp.vec3:
    """:func:`ray_sort_key`'s ``scale``: the sort grid's cells per unit length on each axis (float32,
    as the kernels compute)."""
    lo = np.array(box_lo, np.float32)
    hi = np.array(box_hi, np.float32)
    return wp.vec3(*(np.float32(1 << SORT_ORIGIN_BITS) / (hi - lo)).tolist())


@wp.kernel(enable_backward=False)
def sort_keys(
    # inputs
    box_lo: wp.vec3,
    scale: wp.vec3,
    origins: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    # outputs
    keys: wp.array(dtype=wp.uint32),
    offset: int,
):
    i = wp.tid() + offset
    keys[i] = wp.uint32(ray_sort_key(box_lo, scale, origins[i], directions[i]))


#: rays per thread of the CPU's key kernel (:func:`sort_keys_simd`)
KEY_LANES = 16
_KEY_FINE_MASK = (1 << (3 * (SORT_ORIGIN_BITS - SORT_COARSE_BITS))) - 1
#: float32's largest finite value as a C literal, for the SIMD snippets' finiteness tests (:func:`finite`)
_FLT_MAX_C = f"{float(np.finfo(np.float32).max)!r}f"


def _deinterleave(out: str, ptr: str, lanes: int, vtype: str) -> str:
    """C for the SIMD snippets: ``lanes`` vec3 from the float pointer ``ptr`` (x, y, z of each in
    turn), loaded as three vectors of type ``vtype`` and split by shuffles into ``out[0]``,
    ``out[1]``, ``out[2]`` (x, y, z of every lane)."""
    n = lanes
    lines = [f"{{ {vtype} v0_, v1_, v2_; const float* p_ = {ptr};",
             f"__builtin_memcpy(&v0_, p_, sizeof({vtype})); __builtin_memcpy(&v1_, p_ + {n}, sizeof({vtype}));",
             f"__builtin_memcpy(&v2_, p_ + {2 * n}, sizeof({vtype}));"]
    for a in range(3):
        idx = [3 * r + a for r in range(n)]
        head = [i for i in idx if i < 2 * n]
        tail = [i - 2 * n + n for i in idx if i >= 2 * n]
        first_pass = ", ".join(str(i) for i in head + [0] * (n - len(head)))
        second = ", ".join([str(i) for i in range(len(head))] + [str(i) for i in tail])
        lines.append(f"{{ {vtype} t_ = __builtin_shufflevector(v0_, v1_, {first_pass});"
                     f" {out}[{a}] = __builtin_shufflevector(t_, v2_, {second}); }}")
    lines.append("}")
    return "\n".join(lines)


@wp.func_native(f"""
#if !defined(__CUDA_ARCH__)
typedef float kf __attribute__((ext_vector_type({KEY_LANES})));
typedef int ki __attribute__((ext_vector_type({KEY_LANES})));
kf o[3], d[3];
{_deinterleave("o", "(const float*)origins.data + 3 * (size_t)first", KEY_LANES, "kf")}
{_deinterleave("d", "(const float*)directions.data + 3 * (size_t)first", KEY_LANES, "kf")}
const kf zero = 0.0f;
const kf cells = {float((1 << SORT_ORIGIN_BITS) - 1)!r}f;
const kf dcells = {float((1 << SORT_DIRECTION_BITS) - 1)!r}f;
ki q[3];
for (int a = 0; a < 3; ++a) {{
    kf f = (o[a] - box_lo.c[a]) * scale.c[a];
    f = f >= zero ? f : zero;
    f = f < cells ? f : cells;
    ki x = __builtin_convertvector(f, ki) & {(1 << SORT_ORIGIN_BITS) - 1};
{_spread_c("x", 3, "")}
    q[a] = x;
}}
ki origin = q[0] | (q[1] << 1) | (q[2] << 2);
kf ax = (kf)((ki)d[0] & 0x7FFFFFFF);
kf ay = (kf)((ki)d[1] & 0x7FFFFFFF);
kf az = (kf)((ki)d[2] & 0x7FFFFFFF);
ki octant = ((d[0] < zero) & 1) | ((d[1] < zero) & 2) | ((d[2] < zero) & 4);
kf l1 = (ax + ay) + az;
kf s = ((l1 > zero) & (l1 <= {_FLT_MAX_C})) ? {float(1 << SORT_DIRECTION_BITS)!r}f / l1 : zero;
kf fu = s > zero ? ax * s : zero;
kf fv = s > zero ? ay * s : zero;
fu = fu < dcells ? fu : dcells;
fv = fv < dcells ? fv : dcells;
ki uv[2] = {{__builtin_convertvector(fu, ki), __builtin_convertvector(fv, ki)}};
for (int a = 0; a < 2; ++a) {{
    ki x = uv[a] & {(1 << SORT_DIRECTION_BITS) - 1};
{_spread_c("x", 2, "")}
    uv[a] = x;
}}
ki direction = uv[0] | (uv[1] << 1);
ki coarse = origin >> {3 * (SORT_ORIGIN_BITS - SORT_COARSE_BITS)};
ki key = ((((coarse << 3) | octant) << {3 * (SORT_ORIGIN_BITS - SORT_COARSE_BITS)}) | (origin & {_KEY_FINE_MASK}))
         << {2 * SORT_DIRECTION_BITS} | direction;
__builtin_memcpy((unsigned int*)keys.data + (size_t)first, &key, sizeof(key));
#endif
""")
def keys_simd(box_lo: wp.vec3, scale: wp.vec3, origins: wp.array(dtype=wp.vec3), directions: wp.array(dtype=wp.vec3),
              keys: wp.array(dtype=wp.uint32), first: int):
    """:func:`ray_sort_key` of rays ``first`` … ``first + KEY_LANES - 1`` into ``keys``, the rays as
    SIMD lanes (clang's vector extensions; CPU only, contiguous arrays): the same float32
    operations and the same bits (tests), the Morton spreads as shifts and masks of all lanes."""
    ...


@wp.kernel(enable_backward=False)
def sort_keys_simd(
    # inputs
    box_lo: wp.vec3,
    scale: wp.vec3,
    origins: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    # outputs
    keys: wp.array(dtype=wp.uint32),
    offset: int,
):
    """:func:`sort_keys` for ``KEY_LANES`` rays per thread (:func:`keys_simd`; CPU)."""
    keys_simd(box_lo, scale, origins, directions, keys, (wp.tid() + offset) * KEY_LANES)


@wp.kernel(enable_backward=False)
def sample_key_changes(
    # inputs
    box_lo: wp.vec3,
    scale: wp.vec3,
    origins: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    stride: int,
    # outputs
    changes: wp.array(dtype=wp.int32),
    offset: int,
):
    """Whether the sort key changes between rays ``a`` and ``a + 1``, ``a = (tid + offset) · stride``:
    a sample of consecutive pairs, from which :func:`ray_order` estimates how coherent a batch is."""
    j = wp.tid() + offset
    a = j * stride
    ka = ray_sort_key(box_lo, scale, origins[a], directions[a]) >> _SORT_SAMPLE_SHIFT
    kb = ray_sort_key(box_lo, scale, origins[a + 1], directions[a + 1]) >> _SORT_SAMPLE_SHIFT
    changes[j] = wp.where(ka != kb, 1, 0)


@wp.kernel(enable_backward=False)
def count_keys(
    # inputs
    keys: wp.array(dtype=wp.uint32),
    n: int,
    per_run: int,
    # outputs
    counts: wp.array(dtype=wp.int32),
    offset: int,
):
    """Run r = tid + offset of :func:`counting_order`: how many of keys ``[r·per_run, (r+1)·per_run)``
    have each low digit, into ``counts[2r·B + digit]``, and each high digit, into
    ``counts[(2r+1)·B + digit]``, B = 2^SORT_DIGIT_BITS (its own bins: zeroed first, no atomics)."""
    r = wp.tid() + offset
    low = 2 * r * _SORT_BINS
    high = low + _SORT_BINS
    for b in range(2 * _SORT_BINS):
        counts[low + b] = 0
    for i in range(r * per_run, wp.min(n, (r + 1) * per_run)):
        k = int(keys[i])
        a = low + (k & _SORT_DIGIT_MASK)
        counts[a] = counts[a] + 1
        c = high + (k >> _SORT_DIGIT)
        counts[c] = counts[c] + 1


#: how many keys ahead the counting sort's placing passes prefetch, for writing, the line of the place
#: a key will take (its bin's next free place now; 0: none): on one thread the placing of the
#: benchmark's incoherent rays' keys is a few per cent faster with cold caches, on two within the
#: noise; 32 or 64 ahead alike, 16 gains nothing
SORT_PREFETCH = 32


@wp.func_native("""
#if !defined(__CUDA_ARCH__)
if (ahead < keys.shape[0] && ahead < end) {
    const int b = base + (int)(keys.data[ahead] & mask);
    const int j = starts.data[b];
    __builtin_prefetch(first.data + j, 1, 3);
    __builtin_prefetch(high.data + j, 1, 3);
}
#endif
""")
def prefetch_low_place(keys: wp.array(dtype=wp.uint32), starts: wp.array(dtype=wp.int32),
                       first: wp.array(dtype=wp.int32), high: wp.array(dtype=wp.uint16), base: int, mask: int,
                       ahead: int, end: int):
    """Prefetch, for writing, the places in ``first`` and ``high`` that key ``ahead`` would take now."""
    ...


@wp.func_native("""
#if !defined(__CUDA_ARCH__)
if (ahead < end) __builtin_prefetch(order.data + starts.data[base + (int)high.data[ahead]], 1, 3);
#endif
""")
def prefetch_high_place(high: wp.array(dtype=wp.uint16), starts: wp.array(dtype=wp.int32),
                        order: wp.array(dtype=wp.int32), base: int, ahead: int, end: int):
    """Prefetch, for writing, the place in ``order`` that the key at ``ahead`` would take now."""
    ...


@wp.kernel(enable_backward=False)
def place_keys(
    # inputs
    keys: wp.array(dtype=wp.uint32),
    n: int,
    # outputs
    starts: wp.array(dtype=wp.int32),
    first: wp.array(dtype=wp.int32),
    high: wp.array(dtype=wp.uint16),
    order: wp.array(dtype=wp.int32),
    offset: int,
):
    """The placing passes of :func:`counting_order`, on one thread (a stable LSD radix sort of two
    digits): each key's index, in the keys' order, at the next free place of its low digit's bin
    (``starts[digit]``, advanced), into ``first``, its high digit beside it into ``high`` (so that the
    second pass reads them in order, not at random); then each of those, in that order, at the next
    free place of its high digit's bin (``starts[2^SORT_DIGIT_BITS + digit]``), into ``order``."""
    for i in range(n):
        if wp.static(SORT_PREFETCH > 0):
            prefetch_low_place(keys, starts, first, high, 0, _SORT_DIGIT_MASK, i + SORT_PREFETCH, n)
        k = int(keys[i])
        b = k & _SORT_DIGIT_MASK
        j = starts[b]
        first[j] = i
        high[j] = wp.uint16(k >> _SORT_DIGIT)
        starts[b] = j + 1
    for j in range(n):
        if wp.static(SORT_PREFETCH > 0):
            prefetch_high_place(high, starts, order, _SORT_BINS, j + SORT_PREFETCH, n)
        b = _SORT_BINS + int(high[j])
        p = starts[b]
        order[p] = first[j]
        starts[b] = p + 1


@wp.kernel(enable_backward=False)
def place_low_runs(
    # inputs
    keys: wp.array(dtype=wp.uint32),
    n: int,
    per_run: int,
    owner: wp.array(dtype=wp.int32),
    # outputs
    starts: wp.array(dtype=wp.int32),
    first: wp.array(dtype=wp.int32),
    high: wp.array(dtype=wp.uint16),
    high_counts: wp.array(dtype=wp.int32),
    offset: int,
):
    """:func:`place_keys`' first pass for run r = tid + offset of the keys, within the run's own
    places ``[r·per_run, (r+1)·per_run)``: its keys sorted by their low digit there (bin b's next free
    place ``starts[r·B + b]``, advanced), so that no two threads write one cache line. For the second
    pass, whose thread q takes the low digits' bins ``owner[b] = q``, it also counts the high digits
    of this run's keys by that thread, into ``high_counts[(r·R + q)·B + digit]`` (R runs; zeroed by
    the caller)."""
    r = wp.tid() + offset
    base = r * _SORT_BINS
    runs = (n + per_run - 1) // per_run
    hbase = r * runs * _SORT_BINS
    end = wp.min(n, (r + 1) * per_run)
    for i in range(r * per_run, end):
        if wp.static(SORT_PREFETCH > 0):
            prefetch_low_place(keys, starts, first, high, base, _SORT_DIGIT_MASK, i + SORT_PREFETCH, end)
        k = int(keys[i])
        b = k & _SORT_DIGIT_MASK
        j = starts[base + b]
        first[j] = i
        h = k >> _SORT_DIGIT
        high[j] = wp.uint16(h)
        starts[base + b] = j + 1
        c = hbase + owner[b] * _SORT_BINS + h
        high_counts[c] = high_counts[c] + 1


@wp.kernel(enable_backward=False)
def place_high_runs(
    # inputs
    first: wp.array(dtype=wp.int32),
    high: wp.array(dtype=wp.uint16),
    runs: int,
    bin_lo: wp.array(dtype=wp.int32),
    seg_lo: wp.array(dtype=wp.int32),
    seg_hi: wp.array(dtype=wp.int32),
    # outputs
    starts: wp.array(dtype=wp.int32),
    order: wp.array(dtype=wp.int32),
    offset: int,
):
    """:func:`place_keys`' second pass for thread q = tid + offset: the low digits' bins
    ``[bin_lo[q], bin_lo[q+1])``, each bin's keys run after run (run r's at places
    ``[seg_lo[r·B + b], seg_hi[r·B + b])`` of the first pass, :func:`place_low_runs`): the keys in
    the order of a one-thread first pass, each placed at the next free place of its high digit's
    bin among thread q's (``starts[q·B + digit]``)."""
    q = wp.tid() + offset
    base = q * _SORT_BINS
    for b in range(bin_lo[q], bin_lo[q + 1]):
        for r in range(runs):
            end = seg_hi[r * _SORT_BINS + b]
            for j in range(seg_lo[r * _SORT_BINS + b], end):
                if wp.static(SORT_PREFETCH > 0):
                    prefetch_high_place(high, starts, order, base, j + SORT_PREFETCH, end)
                c = base + int(high[j])
                p = starts[c]
                order[p] = first[j]
                starts[c] = p + 1


@wp.kernel(enable_backward=False)
def sort_starts_one(
    # inputs
    counts: wp.array(dtype=wp.int32),
    # outputs
    starts: wp.array(dtype=wp.int32),
    offset: int,
):
    """:func:`counting_order` on one thread: where each bin of each digit starts (exclusive prefix
    sums of one run's counts, :func:`count_keys`)."""
    for digit in range(2):
        acc = int(0)
        for b in range(_SORT_BINS):
            starts[digit * _SORT_BINS + b] = acc
            acc += counts[digit * _SORT_BINS + b]


@wp.kernel(enable_backward=False)
def sort_starts_low(
    # inputs
    counts: wp.array(dtype=wp.int32),
    n: int,
    runs: int,
    per_run: int,
    # outputs
    seg: wp.array(dtype=wp.int32),
    starts: wp.array(dtype=wp.int32),
    owner: wp.array(dtype=wp.int32),
    bin_lo: wp.array(dtype=wp.int32),
    high_counts: wp.array(dtype=wp.int32),
    offset: int,
):
    """:func:`counting_order` on several threads, before the first pass (one kernel thread): each
    run's first place of each low bin within its own places (``seg`` and ``starts``, which the pass
    advances); the low bins' shares of the second pass's threads — thread q takes bins
    ``[bin_lo[q], bin_lo[q+1])`` (``owner[b] = q``), whose keys before them number about q·n / runs;
    and ``high_counts`` zeroed."""
    for r in range(runs):
        acc = r * per_run
        for b in range(_SORT_BINS):
            seg[r * _SORT_BINS + b] = acc
            starts[r * _SORT_BINS + b] = acc
            acc += counts[2 * r * _SORT_BINS + b]
    bin_lo[0] = 0
    last = int(0)
    before = wp.int64(0)  # keys in the bins before b
    for b in range(_SORT_BINS):
        q = int(wp.min(wp.int64(runs - 1), before * wp.int64(runs) // wp.int64(n)))
        for k in range(last + 1, q + 1):
            bin_lo[k] = b
        last = wp.max(last, q)
        owner[b] = last
        for r in range(runs):
            before += wp.int64(counts[2 * r * _SORT_BINS + b])
    for k in range(last + 1, runs + 1):
        bin_lo[k] = _SORT_BINS
    for i in range(runs * runs * _SORT_BINS):
        high_counts[i] = 0


@wp.kernel(enable_backward=False)
def sort_starts_high(
    # inputs
    high_counts: wp.array(dtype=wp.int32),
    runs: int,
    # outputs
    starts: wp.array(dtype=wp.int32),
    offset: int,
):
    """:func:`counting_order` on several threads, before the second pass (one kernel thread): where
    thread q's keys of each high digit go, ``starts[q·B + digit]``: after every key of a lower digit,
    and after those of that digit of the threads before q (counted by :func:`place_low_runs`)."""
    acc = int(0)
    for h in range(_SORT_BINS):
        for q in range(runs):
            starts[q * _SORT_BINS + h] = acc
            for r in range(runs):
                acc += high_counts[(r * runs + q) * _SORT_BINS + h]


def counting_order(keys: wp.array, n: int, threads: int | None = None, workspace: Staging | None = None) -> wp.array:
    """The stable ascending order of ``n`` 32-bit ``keys`` (below 2^(2·SORT_DIGIT_BITS)) on the CPU:
    a radix sort of two digits by counting. The threads count contiguous runs of the keys per digit
    and bin (:func:`count_keys`), a one-thread kernel sums the runs' counts into each bin's first
    place (:func:`sort_starts_one`, :func:`sort_starts_low`, :func:`sort_starts_high`), and one
    thread places the keys by the low digit, then by the high one (:func:`place_keys`). On several
    threads each run of keys is sorted by its low digit within its own places
    (:func:`place_low_runs`), then each thread takes a share of the low digits' bins and places their
    keys, run after run, by the high digit (:func:`place_high_runs`: the order a one-thread first
    pass gives, so the same result). The same order as ``np.argsort(keys, kind="stable")`` (tests).
    On one thread it takes about half the time of numpy's radix sort of the same keys. Each run's
    keys are placed within the run's own places so that two threads' writes do not meet at every
    bin's border and share the cache lines of the 2-byte high digits (placed at the run's places in
    every global bin, the first pass on two threads took as long as the one-thread sort's two
    passes). Split by spans of bins instead (each thread reading every key and placing its own) it
    is no faster than one thread; three digits of 9-10 bits are slower (docs/kdtree.md)."""
    runs = max(1, min(threads or cpu_threads(), n // SORT_MIN_KEYS_PER_THREAD))
    per_run = -(-n // runs)
    bins = 1 << SORT_DIGIT_BITS
    counts = workspace_buffer(workspace, "sort_counts", runs * 2 * bins, wp.int32, "cpu")
    launch(count_keys, runs, [keys, n, per_run, counts], device="cpu", threads=runs, min_items=1)
    first = workspace_buffer(workspace, "sort_first", n, wp.int32, "cpu")
    high = workspace_buffer(workspace, "sort_high", n, wp.uint16, "cpu")
    order = workspace_buffer(workspace, "order", n, wp.int32, "cpu")
    starts = workspace_buffer(workspace, "sort_starts", max(runs, 2) * bins, wp.int32, "cpu")  # one run: both digits
    if runs == 1:
        wp.launch(sort_starts_one, 1, [counts, starts, 0], device="cpu")
        wp.launch(place_keys, 1, [keys, n, starts, first, high, order, 0], device="cpu")
        return order
    # several runs: each sorts its own keys by the low digit within its own places, then thread q
    # places the keys of its share of the low digits' bins, run after run, by the high digit; the
    # prefix sums between the passes are one-thread kernels (numpy's took ~0.6 ms per step with
    # its array views, all of it time the other thread waits)
    seg = workspace_buffer(workspace, "sort_seg", runs * bins, wp.int32, "cpu")
    owner = workspace_buffer(workspace, "sort_owner", bins, wp.int32, "cpu")
    bin_lo = workspace_buffer(workspace, "sort_bin_lo", runs + 1, wp.int32, "cpu")
    hc = workspace_buffer(workspace, "sort_high_counts", runs * runs * bins, wp.int32, "cpu")
    wp.launch(sort_starts_low, 1, [counts, n, runs, per_run, seg, starts, owner, bin_lo, hc, 0], device="cpu")
    launch(place_low_runs, runs, [keys, n, per_run, owner, starts, first, high, hc], device="cpu", threads=runs,
           min_items=1)
    starts2 = workspace_buffer(workspace, "sort_starts2", runs * bins, wp.int32, "cpu")
    wp.launch(sort_starts_high, 1, [hc, runs, starts2, 0], device="cpu")
    launch(place_high_runs, runs, [first, high, runs, bin_lo, seg, starts, starts2, order], device="cpu",
           threads=runs, min_items=1)
    return order


@wp.kernel(enable_backward=False)
def gather_array(
    # inputs
    order: wp.array(dtype=wp.int32),
    src: wp.array(dtype=Any),
    # outputs
    dst: wp.array(dtype=Any),
    offset: int,
):
    """``dst[i] = src[order[i]]``: a per-ray array in the traced order (:func:`gather_in_order`;
    compiled for the ray input types in ``GATHER_DTYPES``)."""
    i = wp.tid() + offset
    dst[i] = src[order[i]]


#: the per-ray input types :func:`gather_array` is compiled for (origins, directions, tmax, cones)
GATHER_DTYPES = (wp.vec3, wp.float32)
for _dtype in GATHER_DTYPES:
    wp.overload(gather_array, {"src": wp.array(dtype=_dtype), "dst": wp.array(dtype=_dtype)})


@wp.kernel(enable_backward=False)
def scatter_array(
    # inputs
    order: wp.array(dtype=wp.int32),
    src: wp.array(dtype=Any),
    # outputs
    dst: wp.array(dtype=Any),
    offset: int,
):
    """``dst[order[i]] = src[i]``: a per-ray result traced in the order of :func:`ray_order` back in
    the caller's (:func:`scatter_in_order`; compiled for the result types in ``SCATTER_DTYPES``)."""
    i = wp.tid() + offset
    dst[order[i]] = src[i]


#: rays per kernel thread of the CPU's reordering passes (:func:`move_in_order`, :func:`scatter_hits`),
#: and how many rays ahead each prefetches the lines it will read or write at random: the
#: out-of-order core alone keeps too few of those misses in flight (on the benchmark's 0.92 M
#: incoherent rays with cold caches the gather takes about 1/6 less time and the scatter 1/4 less,
#: against one ray per kernel thread without prefetches; docs/kdtree.md, "Reordering")
REORDER_BLOCK = 4096
GATHER_PREFETCH = 64
SCATTER_PREFETCH = 128

_MOVE_C = f"""
#if !defined(__CUDA_ARCH__)
const int* ord = order.data;
const char* S = (const char*)src;
char* D = (char*)dst;
const int n = order.shape[0];
const int end = first + count;
/* gather: D[i] = S[ord[i]], the source prefetched; scatter: D[ord[i]] = S[i], the target prefetched
   for writing; the element's size a constant in the common cases */
#define SERENITY_MOVE(SIZE)                                                                      \\
    for (int i = first; i < end; ++i) {{                                                          \\
        if (scatter) {{                                                                           \\
            if (i + {SCATTER_PREFETCH} < n)                                                        \\
                __builtin_prefetch(D + (SIZE) * (size_t)ord[i + {SCATTER_PREFETCH}], 1, 3);        \\
            __builtin_memcpy(D + (SIZE) * (size_t)ord[i], S + (SIZE) * (size_t)i, (SIZE));         \\
        }} else {{                                                                                \\
            if (i + {GATHER_PREFETCH} < n)                                                         \\
                __builtin_prefetch(S + (SIZE) * (size_t)ord[i + {GATHER_PREFETCH}], 0, 3);         \\
            __builtin_memcpy(D + (SIZE) * (size_t)i, S + (SIZE) * (size_t)ord[i], (SIZE));         \\
        }}                                                                                       \\
    }}
switch (size) {{
    case 4: SERENITY_MOVE(4) break;
    case 12: SERENITY_MOVE(12) break;
    case 16: SERENITY_MOVE(16) break;
    default: SERENITY_MOVE(size) break;
}}
#undef SERENITY_MOVE
#endif
"""


@wp.func_native(_MOVE_C)
def move_range(order: wp.array(dtype=wp.int32), src: wp.uint64, dst: wp.uint64, size: int, scatter: int,
               first: int, count: int):
    """For i in ``[first, first + count)``: element ``order[i]`` of ``src`` to element i of ``dst``
    (a gather), or element i to element ``order[i]`` (``scatter``); elements of ``size`` bytes,
    contiguous arrays at the addresses ``src``, ``dst`` (CPU; nothing on CUDA)."""
    ...


@wp.kernel(enable_backward=False)
def move_in_order(
    # inputs
    order: wp.array(dtype=wp.int32),
    src: wp.uint64,
    size: int,
    scatter: int,
    # outputs
    dst: wp.uint64,
    offset: int,
):
    """:func:`gather_in_order`'s and :func:`scatter_in_order`'s pass on the CPU, ``REORDER_BLOCK`` rays
    per kernel thread, each ray's line prefetched ``GATHER_PREFETCH`` (``SCATTER_PREFETCH``, for
    writing) rays ahead (:func:`move_range`)."""
    first = (wp.tid() + offset) * REORDER_BLOCK
    move_range(order, src, dst, size, scatter, first, wp.min(REORDER_BLOCK, order.shape[0] - first))


_SCATTER_HITS_C = f"""
#if !defined(__CUDA_ARCH__)
const int* ord = order.data;
char* R = (char*)records.data;
const int n = order.shape[0];
const int end = first + count;
for (int i = first; i < end; ++i) {{
    if (i + {SCATTER_PREFETCH} < n)
        __builtin_prefetch(R + 16 * (size_t)ord[i + {SCATTER_PREFETCH}], 1, 3);
    float rec[4];
    rec[0] = t.data[i];
    __builtin_memcpy(rec + 1, prim.data + i, 4);
    rec[2] = u.data[i];
    rec[3] = v.data[i];
    __builtin_memcpy(R + 16 * (size_t)ord[i], rec, 16);
}}
#endif
"""


@wp.func_native(_SCATTER_HITS_C)
def scatter_hits_range(order: wp.array(dtype=wp.int32), t: wp.array(dtype=float), prim: wp.array(dtype=wp.int32),
                       u: wp.array(dtype=float), v: wp.array(dtype=float), records: wp.array(dtype=wp.vec4),
                       first: int, count: int):
    """``records[order[i]] = (t[i], prim[i]'s bits, u[i], v[i])`` for i in ``[first, first + count)``
    (CPU, contiguous arrays; nothing on CUDA)."""
    ...


@wp.kernel(enable_backward=False)
def scatter_hits(
    # inputs
    order: wp.array(dtype=wp.int32),
    t: wp.array(dtype=float),
    prim: wp.array(dtype=wp.int32),
    u: wp.array(dtype=float),
    v: wp.array(dtype=float),
    # outputs
    records: wp.array(dtype=wp.vec4),
    offset: int,
):
    """The closest-hit query's four results, traced in the order of :func:`ray_order`, back at their
    rays' own indices in one 16-byte record per ray (t, prim's bits, u, v; :func:`hit_outputs`),
    ``REORDER_BLOCK`` rays per kernel thread, each record's line prefetched for writing
    ``SCATTER_PREFETCH`` rays ahead (CPU only)."""
    first = (wp.tid() + offset) * REORDER_BLOCK
    scatter_hits_range(order, t, prim, u, v, records, first, wp.min(REORDER_BLOCK, order.shape[0] - first))


#: the per-ray result types :func:`scatter_array` is compiled for (hits, flags, ray-traced G-buffers)
SCATTER_DTYPES = (wp.int32, wp.float32, wp.vec4)
for _dtype in SCATTER_DTYPES:
    wp.overload(scatter_array, {"src": wp.array(dtype=_dtype), "dst": wp.array(dtype=_dtype)})


@wp.kernel(enable_backward=False)
def intersect_rays(
    # inputs
    tree: KdTreeData,
    origins: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    tmin: float,
    tmax: wp.array(dtype=float),
    # outputs
    hit_t: wp.array(dtype=float),
    hit_prim: wp.array(dtype=wp.int32),
    hit_u: wp.array(dtype=float),
    hit_v: wp.array(dtype=float),
    offset: int,
):
    i = wp.tid() + offset
    prim, t, u, v = trace_kd(tree, origins[i], directions[i], tmin, tmax[i], False)
    hit_t[i] = t
    hit_prim[i] = prim
    hit_u[i] = u
    hit_v[i] = v


@wp.kernel(enable_backward=False)
def occlude_rays(
    # inputs
    tree: KdTreeData,
    origins: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    tmin: float,
    tmax: wp.array(dtype=float),
    # outputs
    occluded: wp.array(dtype=wp.int32),
    offset: int,
):
    i = wp.tid() + offset
    prim, t, u, v = trace_kd(tree, origins[i], directions[i], tmin, tmax[i], True)
    occluded[i] = wp.where(prim >= 0, 1, 0)


@kernel_factory(rays=INTERLEAVE_FACTORS, any_hit=(False, True))
def trace_rays_kernel(rays: int, any_hit: bool):
    """The CPU query kernel with ``rays`` interleaved slots per kernel thread (module docstring,
    "Interleaved rays"): thread g traces rays g·per_thread … (g + 1)·per_thread − 1 of the batch,
    one step of each slot's ray in turn, each slot with its own state and stack, a slot taking the
    next ray when its ray is done, so that the out-of-order core overlaps the slots' chains of
    dependent node loads. The inner-node step is branch-free (:func:`inner_step_flat`). Every ray
    visits the nodes and triangles ``trace_kd`` visits, in its order: the same hits, bit for bit.
    ``any_hit``: occlusion (output ``occluded``), else closest hits (``hit_t`` … ``hit_v``)."""
    vec_i = wp.types.vector(length=rays, dtype=wp.int32)
    vec_f = wp.types.vector(length=rays, dtype=wp.float32)
    mat_3 = wp.types.matrix(shape=(rays, 3), dtype=wp.float32)
    mat_3i = wp.types.matrix(shape=(rays, 3), dtype=wp.int32)
    stack_i = wp.types.matrix(shape=(rays, STACK_SIZE), dtype=wp.int32)
    stack_f = wp.types.matrix(shape=(rays, STACK_SIZE), dtype=wp.float32)

    @wp.func
    def trace_range(
        tree: KdTreeData,
        origins: wp.array(dtype=wp.vec3),
        directions: wp.array(dtype=wp.vec3),
        tmin: float,
        tmax: wp.array(dtype=float),
        first: int,
        end: int,
        hit_t: wp.array(dtype=float),
        hit_prim: wp.array(dtype=wp.int32),
        hit_u: wp.array(dtype=float),
        hit_v: wp.array(dtype=float),
        occluded: wp.array(dtype=wp.int32),
    ):
        """:func:`trace_kd` of rays first … end − 1 over the slots (the loops over slots are
        unrolled: each slot's state lives in registers or at fixed places); writes ray i's result
        at index i."""
        o_m = mat_3()
        d_m = mat_3()
        inv_m = mat_3()
        flags_m = mat_3i()
        t0 = vec_f()
        t1 = vec_f()
        teps = vec_f()
        best_t = vec_f()
        hu = vec_f()
        hv = vec_f()
        prim = vec_i()
        node = vec_i()
        sp = vec_i()
        ray = vec_i()  # the slot's ray; -1 before its first, -2 when no rays are left
        fin = vec_i()  # 1: the slot's ray is done (write it out, take the next)
        st_node = stack_i()
        st_t0 = stack_f()
        st_t1 = stack_f()
        nxt = first
        tlo = wp.max(tmin, 0.0)  # as start_ray's
        alive = int(rays)
        for r in range(wp.static(rays)):
            ray[r] = -1
            fin[r] = 1
        while alive > 0:
            for r in range(wp.static(rays)):
                if fin[r] == 0:
                    nd = node[r]
                    head = node_head(tree.nodes, nd)
                    axis = head & 3
                    leaf_end = False
                    if axis != 3:
                        nn, new_t1, push, pushed, pushed_t0, empty = inner_step_flat(
                            head, node_split(tree.nodes, nd), o_m[r, axis], inv_m[r, axis], flags_m[r, axis],
                            t0[r], t1[r], teps[r])
                        k = sp[r] & _STACK_MASK  # written whether pushed or not: above the top, unused
                        st_node[r, k] = pushed
                        st_t0[r, k] = pushed_t0
                        st_t1[r, k] = t1[r]
                        sp[r] = sp[r] + push
                        node[r] = nn
                        t1[r] = new_t1
                        leaf_end = empty != 0
                    else:
                        rprim, rt, ru, rv = leaf_hits(tree, head >> 2, int(node_split(tree.nodes, nd)), o_m[r],
                                                      d_m[r], tlo, best_t[r], prim[r], hu[r], hv[r],
                                                      wp.static(any_hit))
                        prim[r] = rprim
                        best_t[r] = rt
                        hu[r] = ru
                        hv[r] = rv
                        leaf_end = True
                    if leaf_end:
                        # a branch: rarer than the steps and mostly predicted (a branch-free pop
                        # lengthens every step's chain: slower)
                        if prim[r] >= 0 and (wp.static(any_hit) or best_t[r] <= t1[r]):
                            fin[r] = 1
                        else:
                            popped = int(0)
                            s = sp[r]
                            while s > 0 and popped == 0:
                                s -= 1
                                k = s & _STACK_MASK
                                node[r] = st_node[r, k]
                                t0[r] = st_t0[r, k]
                                t1[r] = st_t1[r, k]
                                if t0[r] <= best_t[r]:
                                    popped = 1
                            sp[r] = s
                            fin[r] = 1 - popped
                elif ray[r] >= -1:
                    i = ray[r]
                    if i >= 0:
                        if wp.static(any_hit):
                            occluded[i] = wp.where(prim[r] >= 0, 1, 0)
                        else:
                            hit_prim[i] = prim[r]
                            hit_t[i] = wp.where(prim[r] >= 0, best_t[r], _INF)
                            hit_u[i] = hu[r]
                            hit_v[i] = hv[r]
                    if nxt < end:
                        o = origins[nxt]
                        d = directions[nxt]
                        tm = tmax[nxt]
                        _kx, _ky, _kz, _sx, _sy, _sz, rinv, rt0, rt1, rteps, _tlo, rdone = start_ray(
                            tree, o, d, tmin, tm)
                        o_m[r] = o
                        d_m[r] = d
                        inv_m[r] = rinv
                        for a in range(3):
                            flags_m[r, a] = wp.where(d[a] > 0.0, 1, 0) | wp.where(rinv[a] == 0.0, 2, 0)
                        t0[r] = rt0
                        t1[r] = rt1
                        teps[r] = rteps
                        best_t[r] = tm
                        prim[r] = -1
                        hu[r] = 0.0
                        hv[r] = 0.0
                        node[r] = 0
                        sp[r] = 0
                        ray[r] = nxt
                        fin[r] = wp.where(rdone, 1, 0)
                        nxt += 1
                    else:
                        ray[r] = -2
                        alive -= 1

    @wp.kernel(enable_backward=False, module="unique")
    def trace_rays(
        # inputs
        tree: KdTreeData,
        origins: wp.array(dtype=wp.vec3),
        directions: wp.array(dtype=wp.vec3),
        tmin: float,
        tmax: wp.array(dtype=float),
        n: int,
        per_thread: int,
        # outputs
        hit_t: wp.array(dtype=float),
        hit_prim: wp.array(dtype=wp.int32),
        hit_u: wp.array(dtype=float),
        hit_v: wp.array(dtype=float),
        occluded: wp.array(dtype=wp.int32),
        offset: int,
    ):
        first = (wp.tid() + offset) * per_thread
        trace_range(tree, origins, directions, tmin, tmax, first, wp.min(first + per_thread, n),
                    hit_t, hit_prim, hit_u, hit_v, occluded)

    return trace_rays


# ----------------------------------------------------------------------------------------------
# packets (CPU: reordered batches and batches in a coherent order)
# ----------------------------------------------------------------------------------------------

#: rays per packet (docs/kdtree.md, "Packets"): the lanes of one SIMD node step, and the bits of
#: the lane masks (an int32 holds them)
PACKET_LANES = 16
#: a batch left in the caller's order is traced in packets when it has at least this many rays and
#: is coherent (:func:`batch_is_coherent`, the test ``ray_order`` makes; else one ray per thread)
PACKET_MIN_RAYS = 4 * PACKET_LANES
# a packet's workspace (float32 per lane, per worker thread): origin and inverse direction per axis,
# interval tolerance, current interval (t0, t1), best hit t, then a (t0, t1) pair per stack level
_PK_O = 0
_PK_IA = 3 * PACKET_LANES
_PK_TE = 6 * PACKET_LANES
_PK_T0 = 7 * PACKET_LANES
_PK_T1 = 8 * PACKET_LANES
_PK_BT = 9 * PACKET_LANES
# ... the lanes' set-up (packet_setup): interval at the root box (t0, t1), Woop's axes (kx, ky, kz,
# as floats) and shears (sx, sy, sz), the octant (as a float), then the stack
_PK_S0 = 10 * PACKET_LANES
_PK_S1 = 11 * PACKET_LANES
_PK_KX = 12 * PACKET_LANES
_PK_SX = 15 * PACKET_LANES
_PK_OCT = 18 * PACKET_LANES
_PK_HIT = 19 * PACKET_LANES  # leaf_simd's best hit: t, u, v (3 floats)
_PK_STACK = 20 * PACKET_LANES
PACKET_WORKSPACE = _PK_STACK + 2 * STACK_SIZE * PACKET_LANES  # floats per worker
_PK_ALL = wp.constant(wp.int32((1 << PACKET_LANES) - 1))
_PK_LANE_MASK = wp.constant(wp.int32(PACKET_LANES - 1))
_PK_FIELD = (1 << 20) - 1  # one lane mask in packet_step's result
assert PACKET_LANES & (PACKET_LANES - 1) == 0 and PACKET_LANES <= 16 and PACKET_WORKSPACE % 16 == 0

# The packet's lane arithmetic as native snippets: Warp's CPU code is scalar, and clang's vector
# extensions (``ext_vector_type``; the module is compiled for the host CPU, so AVX2/AVX-512 where
# there is one) do one node's step for all lanes in a few vector instructions. The arithmetic is
# inner_step_flat's, lane by lane, in the same float32 operations (no contraction: the module's
# ``fuse_fp`` is off), so every lane makes trace_kd's choices. CPU only (the CUDA branch is never
# launched: CUDA traces one ray per thread; it exists so that the module compiles there).
_PK_VEC = f"""
typedef float pk_f __attribute__((ext_vector_type({PACKET_LANES})));
typedef bool pk_b __attribute__((ext_vector_type({PACKET_LANES})));
#define PK_LD(off) ({{ pk_f v_; __builtin_memcpy(&v_, &s.data[base + (off)], sizeof(pk_f)); v_; }})
#define PK_ST(off, v) do {{ pk_f w_ = (v); __builtin_memcpy(&s.data[base + (off)], &w_, sizeof(pk_f)); }} while (0)
#define PK_MASK(c) ({{ pk_b b_ = __builtin_convertvector((c), pk_b); unsigned int r_ = 0; \\
    __builtin_memcpy(&r_, &b_, sizeof(b_)); (long long)r_; }})
"""
_PK_VEC_END = "\n#undef PK_LD\n#undef PK_ST\n#undef PK_MASK\n"


@wp.func_native(f"""
#if defined(__CUDA_ARCH__)
return 0;
#else
{_PK_VEC}
pk_f o = PK_LD({_PK_O} + axis * {PACKET_LANES});
pk_f ia = PK_LD({_PK_IA} + axis * {PACKET_LANES});
pk_f te = PK_LD({_PK_TE});
pk_f t0 = PK_LD({_PK_T0});
pk_f t1 = PK_LD({_PK_T1});
pk_f bt = PK_LD({_PK_BT});
pk_f ts = (split - o) * ia;
pk_f tn = ts + te;
pk_f tf = ts - te;
auto near_only = (ts <= 0.0f) | (ts > t1 + te);
auto far_only = ~near_only & (ts < t0 - te);
auto both = ~(near_only | far_only);
float sgn = a_side ? -1.0f : 1.0f;
auto origin_b = (o - split) * sgn >= 0.0f;
auto go_a = (near_only & ~origin_b) | both;
auto go_b = ~go_a | both;
pk_f a_t1 = (both & (tn < t1)) ? tn : t1;
pk_f b_t0 = (both & (tf > t0)) ? tf : t0;
PK_ST({_PK_STACK} + level * {2 * PACKET_LANES}, b_t0);
PK_ST({_PK_STACK} + level * {2 * PACKET_LANES} + {PACKET_LANES}, t1);
PK_ST({_PK_T1}, a_t1);
pk_f first_t1 = go_a ? a_t1 : t1;
long long m = PK_MASK(go_a) | (PK_MASK(go_b) << 20) | (PK_MASK(bt <= first_t1) << 40);
{_PK_VEC_END}
return m;
#endif
""")
def packet_step(s: wp.array(dtype=float), base: int, axis: int, split: float, a_side: int, level: int) -> wp.int64:
    """One inner node's step for a packet's lanes (workspace ``s`` from ``base``): each lane's
    :func:`inner_step_flat` on the node's ``axis`` and ``split``, the packet's first child being the
    left one (``a_side`` 0) or the right one (1). Writes the second child's intervals (t0, t1) at stack
    ``level`` and the first child's t1 as the lanes' current one; returns three lane masks, bits 0,
    20 and 40 on: the lanes whose next node is the first child, those that go to the second child
    (next or pushed), and those whose best hit lies within their next node's interval (t ≤ t1)."""
    ...


@wp.func_native(f"""
#if defined(__CUDA_ARCH__)
return 0;
#else
{_PK_VEC}
pk_f t0 = PK_LD({_PK_STACK} + level * {2 * PACKET_LANES});
pk_f t1 = PK_LD({_PK_STACK} + level * {2 * PACKET_LANES} + {PACKET_LANES});
pk_f bt = PK_LD({_PK_BT});
PK_ST({_PK_T0}, t0);
PK_ST({_PK_T1}, t1);
int m = (int)PK_MASK(t0 <= bt);
{_PK_VEC_END}
return m;
#endif
""")
def packet_pop(s: wp.array(dtype=float), base: int, level: int) -> int:
    """The lanes' intervals of stack ``level`` made current; returns the mask of lanes whose entry
    still lies before their best hit (t0 ≤ best t: trace_kd's pop test)."""
    ...


@wp.func_native("""
#if defined(__CUDA_ARCH__)
return __ffs(x) - 1;
#else
return __builtin_ctz((unsigned)x);
#endif
""")
def lowest_lane(x: int) -> int:
    """The index of the lowest set bit of a non-zero lane mask."""
    ...


@wp.func_native(f"""
#if defined(__CUDA_ARCH__)
return 0;
#else
{_PK_VEC}
typedef int pk_i __attribute__((ext_vector_type({PACKET_LANES})));
pk_f o[3], d[3], tm;
if (count == {PACKET_LANES}) {{
{_deinterleave("o", "(const float*)origins.data + 3 * (size_t)first", PACKET_LANES, "pk_f")}
{_deinterleave("d", "(const float*)directions.data + 3 * (size_t)first", PACKET_LANES, "pk_f")}
    __builtin_memcpy(&tm, (const float*)tmax.data + (size_t)first, sizeof(pk_f));
}} else {{
    float ob[3 * {PACKET_LANES}] = {{0}}, db[3 * {PACKET_LANES}] = {{0}}, tb[{PACKET_LANES}] = {{0}};
    __builtin_memcpy(ob, (const float*)origins.data + 3 * (size_t)first, 12 * (size_t)count);
    __builtin_memcpy(db, (const float*)directions.data + 3 * (size_t)first, 12 * (size_t)count);
    __builtin_memcpy(tb, (const float*)tmax.data + (size_t)first, 4 * (size_t)count);
{_deinterleave("o", "ob", PACKET_LANES, "pk_f")}
{_deinterleave("d", "db", PACKET_LANES, "pk_f")}
    __builtin_memcpy(&tm, tb, sizeof(pk_f));
}}
const pk_f zero = 0.0f, one = 1.0f, fmax_ = {_FLT_MAX_C}, inf_ = __builtin_inff();
pk_i lane;
for (int r = 0; r < {PACKET_LANES}; ++r) lane[r] = r;
#define PK_ABS(x) ((pk_f)((pk_i)(x) & 0x7FFFFFFF))
#define PK_FINITE(x) (PK_ABS(x) <= fmax_)
pk_f ad[3] = {{PK_ABS(d[0]), PK_ABS(d[1]), PK_ABS(d[2])}};
/* setup_ray: the dominant axis kz, kx and ky after it (swapped when d[kz] < 0), the shears */
pk_i c0 = (ad[0] >= ad[1]) & (ad[0] >= ad[2]);
pk_i c1 = ~c0 & (ad[1] >= ad[2]);
pk_i kz = (~c0 & ~c1 & 2) | (c1 & 1);
pk_i kx = (kz == 2) ? 0 : kz + 1;
pk_i ky = (kx == 2) ? 0 : kx + 1;
#define PK_PICK(v, k) (((k) == 0) ? (v)[0] : (((k) == 1) ? (v)[1] : (v)[2]))
pk_f dkz = PK_PICK(d, kz);
pk_i neg = dkz < zero;
pk_i kx2 = neg ? ky : kx;
pk_i ky2 = neg ? kx : ky;
pk_f sx = PK_PICK(d, kx2) / dkz;
pk_f sy = PK_PICK(d, ky2) / dkz;
pk_f sz = one / dkz;
/* start_ray: validity, the inverse direction (0 where parallel), the root box clip */
pk_f tlo = tmin_ > 0.0f ? tmin_ : 0.0f;
pk_f t0 = tlo, t1 = tm;
pk_i valid = lane < count;
valid &= PK_FINITE(o[0]) & PK_FINITE(o[1]) & PK_FINITE(o[2]) & PK_FINITE(d[0]) & PK_FINITE(d[1]) & PK_FINITE(d[2]);
valid &= (PK_ABS(dkz) >= {float(np.float32(TINY_DIRECTION))!r}f) & PK_FINITE(sz) & (t1 > t0);
pk_f inv[3];
pk_i clip = valid;
for (int a = 0; a < 3; ++a) {{
    pk_f r = one / d[a];
    inv[a] = (clip & (d[a] != zero) & PK_FINITE(r)) ? r : zero;
}}
for (int a = 0; a < 3; ++a) {{
    pk_i par = inv[a] == zero;
    valid &= ~(clip & par & ((o[a] < lo.c[a]) | (o[a] > hi.c[a])));
    pk_f ta = (lo.c[a] - o[a]) * inv[a];
    pk_f tb = (hi.c[a] - o[a]) * inv[a];
    pk_f mn = ta < tb ? ta : tb;
    pk_f mx = ta > tb ? ta : tb;
    pk_i upd = clip & ~par;
    t0 = (upd & (mn > t0)) ? mn : t0;
    t1 = (upd & (mx < t1)) ? mx : t1;
}}
pk_f ao = PK_ABS(o[0]) > PK_ABS(o[1]) ? PK_ABS(o[0]) : PK_ABS(o[1]);
ao = PK_ABS(o[2]) > ao ? PK_ABS(o[2]) : ao;
pk_f te = ({float(np.float32(T_TOLERANCE))!r}f * (scale + ao)) * PK_ABS(sz);
pk_i live = valid & ~(t0 > t1 + te);
/* the packet's lanes: child order (octant) per axis, inverse direction +-inf where parallel */
pk_i oc = 0;
for (int a = 0; a < 3; ++a) {{
    pk_i side = (inv[a] != zero) ? ((inv[a] < zero) & 1) : ((d[a] > zero) & 1);
    oc |= side << a;
    PK_ST({_PK_O} + a * {PACKET_LANES}, o[a]);
    PK_ST({_PK_IA} + a * {PACKET_LANES}, (inv[a] != zero) ? inv[a] : ((side != 0) ? -inf_ : inf_));
}}
PK_ST({_PK_TE}, te);
PK_ST({_PK_BT}, tm);
PK_ST({_PK_S0}, t0);
PK_ST({_PK_S1}, t1);
PK_ST({_PK_KX}, __builtin_convertvector(kx2, pk_f));
PK_ST({_PK_KX} + {PACKET_LANES}, __builtin_convertvector(ky2, pk_f));
PK_ST({_PK_KX} + {2 * PACKET_LANES}, __builtin_convertvector(kz, pk_f));
PK_ST({_PK_SX}, sx);
PK_ST({_PK_SX} + {PACKET_LANES}, sy);
PK_ST({_PK_SX} + {2 * PACKET_LANES}, sz);
PK_ST({_PK_OCT}, __builtin_convertvector(oc, pk_f));
long long octants = (long long)__builtin_reduce_or(live ? (1 << oc) : 0);
long long m = PK_MASK(live) | (octants << 20);
#undef PK_ABS
#undef PK_FINITE
#undef PK_PICK
{_PK_VEC_END}
return m;
#endif
""")
def packet_setup(lo: wp.vec3, hi: wp.vec3, scale: float, origins: wp.array(dtype=wp.vec3),
                 directions: wp.array(dtype=wp.vec3), tmax: wp.array(dtype=float), tmin_: float, first: int,
                 count: int, s: wp.array(dtype=float), base: int) -> wp.int64:
    """:func:`start_ray` for a packet's ``count`` rays from ``first`` on (contiguous arrays), the rays
    as SIMD lanes: the same float32 operations lane by lane (tests: the packets' hits are the one-ray
    traversal's bit for bit). Writes each lane's origin, inverse direction (+-inf where parallel,
    see the kernel), tolerance, tmax as its best t, interval at the root box, Woop's axes and
    shears and octant into the workspace ``s`` from ``base``; returns the mask of the lanes with
    something to trace (bits 0 …) and, from bit 20, the octants among them (a bit per octant)."""
    ...


@wp.func_native(f"""
#if defined(__CUDA_ARCH__)
return 0;
#else
{_PK_VEC}
PK_ST({_PK_T0}, PK_LD({_PK_S0}));
PK_ST({_PK_T1}, PK_LD({_PK_S1}));
int m = (int)PK_MASK(PK_LD({_PK_OCT}) == (float)oc);
{_PK_VEC_END}
return m;
#endif
""")
def packet_octant(s: wp.array(dtype=float), base: int, oc: int) -> int:
    """Start the trace of octant ``oc``'s lanes: every lane's interval reset to the root box's
    (:func:`packet_setup`); returns the mask of the lanes whose octant is ``oc``."""
    ...


@wp.func_native("#if defined(__CUDA_ARCH__)\nreturn prim;\n#else\n" + _LEAF_SIMD + f"""
if (found >= 0) {{
    s.data[base + {_PK_HIT}] = best;
    s.data[base + {_PK_HIT} + 1] = (float)(ev_found / det_found);
    s.data[base + {_PK_HIT} + 2] = (float)(ew_found / det_found);
}}
return prim;
#endif
""")
def leaf_simd(refs: wp.array(dtype=float), first: int, k: int, o: wp.vec3, kx: int, ky: int, kz: int, sx: float,
              sy: float, sz: float, tlo: float, best_t: float, prim: int, any_hit: int, s: wp.array(dtype=float),
              base: int) -> int:
    """:func:`intersect_leaf` for one ray, 8 triangles at a time as SIMD lanes (the leaf's block at
    word ``first`` of ``refs``, ``k`` triangles): Woop's test in the same float32 and float64
    operations per triangle, then the hits in the triangles' order under intersect_leaf's rule
    (closer, or as close with a lower index; the first one for ``any_hit``), so the same triangle,
    t, u and v (:func:`leaf_pick` for the one-ray traversal, which takes the winner's t, u, v from
    its own test instead: slower for packets, whose lanes have their workspace). Returns the best
    triangle after the leaf (``prim`` if none beat it) and, when one did, writes its t, u, v at the
    packet workspace's ``_PK_HIT``. CPU only."""
    ...


@kernel_factory(any_hit=(False, True))
def trace_packets_kernel(any_hit: bool):
    """The CPU query kernel for batches in a coherent order (docs/kdtree.md, "Packets"): kernel
    thread g traces rays g·PACKET_LANES … as one packet through the tree, the lanes' node steps as
    SIMD (:func:`packet_step`), a leaf's triangles lane by lane (:func:`leaf_simd`), each lane
    with its own interval, best hit and entries on the packet's stack, so that every ray visits the
    nodes and triangles :func:`trace_kd` visits, in its order: the same hits, bit for bit. A packet
    whose lanes head into different octants is traced once per octant, with those lanes.
    ``workspace``: ``PACKET_WORKSPACE`` floats per worker thread (``launch(..., worker_arg=True)``)."""
    vec_i = wp.types.vector(length=PACKET_LANES, dtype=wp.int32)
    vec_f = wp.types.vector(length=PACKET_LANES, dtype=wp.float32)
    stack_v = wp.types.vector(length=STACK_SIZE, dtype=wp.int32)

    @wp.kernel(enable_backward=False, module="unique")
    def trace_packets(
        # inputs
        tree: KdTreeData,
        origins: wp.array(dtype=wp.vec3),
        directions: wp.array(dtype=wp.vec3),
        tmin: float,
        tmax: wp.array(dtype=float),
        n: int,
        workspace: wp.array(dtype=float),
        # outputs
        hit_t: wp.array(dtype=float),
        hit_prim: wp.array(dtype=wp.int32),
        hit_u: wp.array(dtype=float),
        hit_v: wp.array(dtype=float),
        occluded: wp.array(dtype=wp.int32),
        worker: int,
        offset: int,
    ):
        first = (wp.tid() + offset) * PACKET_LANES
        count = wp.min(PACKET_LANES, n - first)
        base = worker * PACKET_WORKSPACE
        prim = vec_i()
        hu = vec_f()
        hv = vec_f()
        st_node = stack_v()
        st_lanes = stack_v()
        tlo = wp.max(tmin, 0.0)
        m0 = packet_setup(tree.box_lo, tree.box_hi, tree.scale, origins, directions, tmax, tmin, first, count,
                          workspace, base)
        live = wp.int32(m0 & wp.int64(_PK_FIELD))  # lanes with a ray to trace
        octants = wp.int32(m0 >> wp.int64(20))  # the octants among them (bit per octant)
        for r in range(PACKET_LANES):
            prim[r] = -1
        hits = int(0)  # lanes with a hit
        finished = int(0)  # lanes whose search is over
        oc = int(0)
        while octants != 0:
            if (octants & 1) != 0:
                lanes = packet_octant(workspace, base, oc) & live
                node = int(0)
                sp = int(0)
                tracing = int(1)
                while tracing != 0:
                    head = node_head(tree.nodes, node)
                    axis = head & 3
                    descend = int(0)
                    if axis != 3:
                        a_side = (oc >> axis) & 1
                        m = packet_step(workspace, base, axis, node_split(tree.nodes, node), a_side, sp & _STACK_MASK)
                        to_a = wp.int32(m & wp.int64(_PK_FIELD)) & lanes
                        to_b = wp.int32((m >> wp.int64(20)) & wp.int64(_PK_FIELD)) & lanes
                        within = wp.int32((m >> wp.int64(40)) & wp.int64(_PK_FIELD))
                        child = head >> 4
                        empty_a = (head >> (2 + a_side)) & 1
                        empty_b = (head >> (3 - a_side)) & 1
                        # lanes whose next node is an empty leaf: trace_kd's end-of-leaf test there
                        at_empty = (to_a & (0 - empty_a)) | (lanes & (to_a ^ _PK_ALL) & (0 - empty_b))
                        if wp.static(any_hit):
                            finished = finished | (at_empty & hits)
                        else:
                            finished = finished | (at_empty & hits & within)
                        pushed = to_b & ((empty_b ^ 1) * _PK_ALL)
                        if pushed != 0:
                            k = sp & _STACK_MASK
                            st_node[k] = child + 1 - a_side
                            st_lanes[k] = pushed
                            sp += 1
                        nxt = to_a & ((empty_a ^ 1) * _PK_ALL)
                        if nxt != 0:
                            node = child + a_side
                            lanes = nxt
                            descend = 1
                    else:
                        count_tris = int(node_split(tree.nodes, node))
                        first_ref = head >> 2
                        todo = lanes
                        while todo != 0:
                            r = lowest_lane(todo) & _PK_LANE_MASK
                            todo = todo & (todo - 1)
                            rt = workspace[base + _PK_BT + r]
                            rp = leaf_simd(tree.refs, first_ref, count_tris, origins[first + r],
                                           int(workspace[base + _PK_KX + r]),
                                           int(workspace[base + _PK_KX + PACKET_LANES + r]),
                                           int(workspace[base + _PK_KX + 2 * PACKET_LANES + r]),
                                           workspace[base + _PK_SX + r], workspace[base + _PK_SX + PACKET_LANES + r],
                                           workspace[base + _PK_SX + 2 * PACKET_LANES + r], tlo, rt, prim[r],
                                           wp.static(1 if any_hit else 0), workspace, base)
                            ru = hu[r]
                            rv = hv[r]
                            if rp != prim[r]:
                                rt = workspace[base + _PK_HIT]
                                ru = workspace[base + _PK_HIT + 1]
                                rv = workspace[base + _PK_HIT + 2]
                            prim[r] = rp
                            workspace[base + _PK_BT + r] = rt
                            hu[r] = ru
                            hv[r] = rv
                            if rp >= 0:
                                hits = hits | (1 << r)
                                if wp.static(any_hit):
                                    finished = finished | (1 << r)
                                elif rt <= workspace[base + _PK_T1 + r]:
                                    finished = finished | (1 << r)
                    while descend == 0:
                        if sp == 0:
                            tracing = 0
                            descend = 1
                        else:
                            sp -= 1
                            k = sp & _STACK_MASK
                            popped = st_lanes[k] & (finished ^ _PK_ALL)
                            if popped != 0:
                                popped = popped & packet_pop(workspace, base, k)
                                if popped != 0:
                                    node = st_node[k]
                                    lanes = popped
                                    descend = 1
            octants = octants >> 1
            oc += 1
        for r in range(PACKET_LANES):
            if r < count:
                i = first + r
                if wp.static(any_hit):
                    occluded[i] = wp.where(prim[r] >= 0, 1, 0)
                else:
                    hit_prim[i] = prim[r]
                    hit_t[i] = wp.where(prim[r] >= 0, workspace[base + _PK_BT + r], _INF)
                    hit_u[i] = hu[r]
                    hit_v[i] = hv[r]

    return trace_packets


# ----------------------------------------------------------------------------------------------
# host
# ----------------------------------------------------------------------------------------------


@dataclass
class Hits:
    """Closest hits of N rays: ``t`` (N,) float32 (inf = miss), ``prim`` (N,) int32 (−1 = miss),
    barycentrics ``u``, ``v`` (N,) float32 (p = (1−u−v)·v0 + u·v1 + v·v2; 0 on a miss). From
    :meth:`KdTree.intersect` of a reordered batch on the CPU the four are the columns of one (N, 4)
    block of records (views with a 16-byte stride: :func:`hit_outputs`; ``np.ascontiguousarray``
    packs one)."""

    t: np.ndarray
    prim: np.ndarray
    u: np.ndarray
    v: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        return self.prim >= 0


def hit_outputs(n: int, device: str, reordered: bool) -> tuple[list, wp.array | None]:
    """The closest-hit query's outputs for ``n`` rays: [t, prim, u, v], and for a ``reordered`` batch
    on the CPU the (n,) vec4 array of 16-byte records (t, prim's bits, u, v) whose columns they are
    (prim's viewed as int32); else four arrays and None (CUDA: coalesced per array). A reordered
    batch's results are scattered back as records (:func:`scatter_hits`): one random store of 16
    bytes per ray, where four arrays take four of 4 bytes to four cache lines, the store buffer
    filling with misses (the scatter of the benchmark's incoherent rays takes about a third less
    time). A batch traced in its own order writes its results in order: there the columns of
    records make camera rays' traversal 1.5-2.5 % slower, so it keeps four arrays."""
    if not (reordered and device.startswith("cpu")):
        return [wp.empty(n, dtype=dt, device=device) for dt in (float, wp.int32, float, float)], None
    records = wp.empty(n, dtype=wp.vec4, device=device)  # Warp's allocator: numpy's fresh pages cost faults
    block = records.numpy()  # (n, 4) float32, the same memory
    columns = [wp.array(block[:, 0], dtype=float, device=device, copy=False),
               wp.array(block[:, 1].view(np.int32), dtype=wp.int32, device=device, copy=False),
               wp.array(block[:, 2], dtype=float, device=device, copy=False),
               wp.array(block[:, 3], dtype=float, device=device, copy=False)]
    return columns, records


def _ray_arrays(o: np.ndarray, d: np.ndarray, tm: np.ndarray, dev: str, tmin: float, workspace: Staging) -> list:
    """The kernels' ray inputs (origins, directions, tmin, tmax): views of the numpy arrays on the CPU
    (no copy: serial work before the threads start), copies on a GPU; a scalar tmax (0-d ``tm``) is
    ``workspace``'s buffer filled with it (:meth:`Staging.filled`: refilled only when it changes)."""
    copy = not dev.startswith("cpu")
    if np.ndim(tm) == 0:
        tmax = workspace.filled("tmax_uniform", len(o), float, float(tm))
    else:
        tmax = wp.array(tm, dtype=float, device=dev, copy=copy)
    return [wp.array(o, dtype=wp.vec3, device=dev, copy=copy), wp.array(d, dtype=wp.vec3, device=dev, copy=copy),
            float(tmin), tmax]


def ray_order(box_lo: wp.vec3, box_hi: wp.vec3, origins: wp.array, directions: wp.array, n: int, sort: bool | None,
              device: str, threads: int | None = None, workspace: Staging | None = None) -> wp.array:
    """The order in which to trace ``n`` rays: their indices sorted by :func:`ray_sort_key` (stable:
    ties keep the caller's order), or an empty array = as they come. ``sort=None`` sorts batches of
    ≥ ``SORT_MIN_RAYS`` whose keys change, in the caller's order, on average more often than every
    ``SORT_MIN_RUN`` rays (already coherent batches — camera rays, reflections of a smooth surface in
    pixel order — are left as they are), estimated on ``SORT_SAMPLE_PAIRS`` evenly spaced pairs of
    consecutive rays before any key per ray is made; ``True`` always, ``False`` never. The keys come from a Warp
    kernel (over all cores on the CPU) and are sorted by a counting sort on the CPU
    (:func:`counting_order`), by numpy's radix sort of 16-bit integers on the host on CUDA (the keys
    and the order make a round trip). ``workspace``:
    where the keys go (a grow-only buffer, :meth:`KdTree.workspace`), else a new array."""
    if (sort is False) or n < 2 or (sort is None and n < SORT_MIN_RAYS):
        return wp.empty(0, dtype=wp.int32, device=device)
    if sort is None and batch_is_coherent(box_lo, box_hi, origins, directions, n, device, threads):
        return wp.empty(0, dtype=wp.int32, device=device)
    scale = sort_scale(box_lo, box_hi)
    keys = workspace_buffer(workspace, "keys", n, wp.uint32, device)
    simd = 0
    if device.startswith("cpu") and origins.is_contiguous and directions.is_contiguous:
        simd = n // KEY_LANES
        launch(sort_keys_simd, simd, [box_lo, scale, origins, directions, keys], device=device, threads=threads)
    launch(sort_keys, n - simd * KEY_LANES, [box_lo, scale, origins, directions, keys], device=device, threads=threads,
           start=simd * KEY_LANES)
    if device.startswith("cpu"):
        return counting_order(keys, n, threads, workspace)
    order = np.argsort(keys.numpy(), kind="stable").astype(np.int32)
    return wp.array(order, dtype=wp.int32, device=device)


def batch_is_coherent(box_lo: wp.vec3, box_hi: wp.vec3, origins: wp.array, directions: wp.array, n: int,
                      device: str, threads: int | None = None) -> bool:
    """Are ``n`` rays (n ≥ 2) already in a coherent order? True when :func:`ray_sort_key` changes, on
    ``SORT_SAMPLE_PAIRS`` evenly spaced pairs of consecutive rays, less often than every
    ``SORT_MIN_RUN`` rays (camera rays, reflections of a smooth surface in pixel order): such a batch
    is not reordered (:func:`ray_order`) and is traced in packets on the CPU (``_launch_query``)."""
    m = min(SORT_SAMPLE_PAIRS, n - 1)
    changes = wp.empty(m, dtype=wp.int32, device=device)
    launch(sample_key_changes, m, [box_lo, sort_scale(box_lo, box_hi), origins, directions, (n - 1) // m, changes],
           device=device, threads=threads)
    return int(np.count_nonzero(changes.numpy())) * SORT_MIN_RUN < m


def gather_in_order(order: wp.array, arrays: list, device: str, threads: int | None = None,
                    workspace: Staging | None = None) -> list:
    """Per-ray arrays (vec3 or float) in the traced order of :func:`ray_order`: ``out[i] = a[order[i]]``
    (a separate pass: a random read per ray inside the traversal costs more). ``workspace``: the
    outputs are its grow-only buffers (:func:`buffers_like`), else new arrays."""
    out = buffers_like(arrays, "gather", device, workspace)
    for a, b in zip(arrays, out, strict=True):
        _move(order, a, b, False, device, threads)
    return out


def _move(order: wp.array, src: wp.array, dst: wp.array, scatter: bool, device: str, threads: int | None) -> None:
    """One array's pass of :func:`gather_in_order` (``scatter`` False) or :func:`scatter_in_order`:
    on the CPU the prefetching loops of :func:`move_in_order` (contiguous arrays), else one element
    per kernel thread (:func:`gather_array`, :func:`scatter_array`)."""
    n = order.shape[0]
    if device.startswith("cpu") and src.is_contiguous and dst.is_contiguous:
        size = wp.types.type_size_in_bytes(src.dtype)
        launch(move_in_order, -(-n // REORDER_BLOCK), [order, src.ptr, size, int(scatter), dst.ptr], device=device,
               threads=threads, min_items=1)
    else:
        launch(scatter_array if scatter else gather_array, n, [order, src, dst], device=device, threads=threads)


def scatter_in_order(order: wp.array, arrays: list, outs: list, device: str, threads: int | None = None) -> None:
    """The inverse of :func:`gather_in_order`: ``out[order[i]] = a[i]`` for each pair, results traced
    in the reordered order written back at their rays' own indices (a pass of its own: random stores
    from inside the traversal compete with its loads, module docstring, "Ray reordering"). Empty
    arrays are skipped."""
    for a, b in zip(arrays, outs, strict=True):
        if a.shape[0]:
            _move(order, a, b, True, device, threads)


def workspace_buffer(workspace: Staging | None, name: str, n: int, dtype, device: str) -> wp.array:
    """``n`` elements of ``dtype``: ``workspace``'s grow-only buffer ``name`` (valid until its next use;
    :meth:`KdTree.workspace`), or a new array without one."""
    return wp.empty(n, dtype=dtype, device=device) if workspace is None else workspace.buffer(name, n, dtype)


def buffers_like(arrays: list, prefix: str, device: str, workspace: Staging | None = None) -> list:
    """An array of the shape and dtype of each of ``arrays`` (:func:`workspace_buffer`: ``workspace``'s
    buffers ``prefix``0, ``prefix``1, ..., or new ones)."""
    return [workspace_buffer(workspace, f"{prefix}{k}", a.shape[0], a.dtype, device) for k, a in enumerate(arrays)]


def _slot_rays(n: int, slots: int, threads: int | None) -> int:
    """Rays per slot and kernel thread for ``n`` rays on ``slots`` slots: ``RAYS_PER_SLOT``, fewer
    when the launch would otherwise have fewer than ``CHUNKS_PER_THREAD`` chunks of
    ``MIN_ITEMS_PER_CHUNK`` kernel threads per worker (``serenity.kernels.launch``)."""
    workers = threads or cpu_threads()
    return max(1, min(RAYS_PER_SLOT, n // (slots * MIN_ITEMS_PER_CHUNK * workers * CHUNKS_PER_THREAD)))


def _launch_query(any_hit: bool, n: int, inputs: list, order: wp.array, outputs: list, device: str,
                  threads: int | None, rays_per_thread: int | None, workspace: Staging | None = None,
                  coherent: bool = False, records: wp.array | None = None) -> None:
    """Launch the closest-hit (``any_hit=False``; outputs t, prim, u, v) or occlusion query (outputs
    [occluded]) over ``n`` rays ``inputs`` (tree, origins, directions, tmin, tmax) given in the trace
    order ``order`` (empty: the caller's; else ray i is the caller's ray ``order[i]``: the results
    are traced into workspace arrays in that order and scattered back by :func:`scatter_in_order`).
    On the CPU a reordered batch and a ``coherent`` one in the caller's order (camera rays:
    :func:`batch_is_coherent`) go to packets of ``PACKET_LANES`` rays (:func:`trace_packets_kernel`),
    any other batch to one ray per kernel thread (``intersect_rays`` / ``occlude_rays``; module
    docstring); ``rays_per_thread`` forces 1 (one ray), a slot count of ``INTERLEAVE_FACTORS``
    (interleaved rays, :func:`trace_rays_kernel`) or ``PACKET_LANES`` (packets). CUDA traces one
    ray per thread (its parallelism is threads).
    ``workspace``: where the reordered results are traced and the packets keep their lanes
    (:meth:`KdTree.workspace`), else new arrays. ``records``: the closest-hit outputs' record array
    (:func:`hit_outputs`), into which a reordered batch's results are scattered in one pass."""
    one_ray = occlude_rays if any_hit else intersect_rays
    on_cpu = device.startswith("cpu")
    reordered = order.shape[0] > 0
    k = rays_per_thread
    if k is None:
        k = (PACKET_LANES if reordered or coherent else 1) if on_cpu else 1
    if k != 1 and k not in INTERLEAVE_FACTORS and k != PACKET_LANES:
        raise SerenityError(f"rays_per_thread={k}: 1, one of {INTERLEAVE_FACTORS} or {PACKET_LANES} (packets)")
    if k == PACKET_LANES and not all(a.is_contiguous for a in inputs[1:3] + inputs[4:5]):
        k = 1  # packet_setup loads its lanes' rays as contiguous vectors
    traced = buffers_like(outputs, "traced", device, workspace) if reordered else outputs
    none_f = wp.empty(0, dtype=float, device=device)
    none_i = wp.empty(0, dtype=wp.int32, device=device)
    outs = [none_f, none_i, none_f, none_f, *traced] if any_hit else [*traced, none_i]
    if k == 1 or not on_cpu:
        launch(one_ray, n, [*inputs, *traced], device=device, threads=threads, balanced=True)
    elif k == PACKET_LANES:
        workers = threads or cpu_threads()
        lanes = workspace_buffer(workspace, "packets", workers * PACKET_WORKSPACE, float, device)
        lanes.zero_()
        launch(trace_packets_kernel(any_hit), -(-n // PACKET_LANES), [*inputs, n, lanes, *outs], device=device,
               threads=threads, balanced=True, worker_arg=True,
               min_chunk=MIN_ITEMS_PER_CHUNK // PACKET_LANES)  # a packet is 16 rays' work
    else:
        per = k * _slot_rays(n, k, threads)
        launch(trace_rays_kernel(k, any_hit), -(-n // per), [*inputs, n, per, *outs], device=device,
               threads=threads, balanced=True)
    if reordered and records is not None:  # traced into new or workspace arrays: contiguous
        launch(scatter_hits, -(-n // REORDER_BLOCK), [order, *traced, records], device=device, threads=threads,
               min_items=1)
    elif reordered:
        scatter_in_order(order, traced, outputs, device, threads)


class KdTree:
    """An SAH kd-tree over a static triangle mesh, traversed by Warp kernels.

    Build with :meth:`build`; query with :meth:`intersect` (closest hit) and :meth:`occluded`
    (any hit). Device arrays are created on first use per device and kept.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, arrays: dict, stats: KdStats):
        self.vertices = vertices
        self.faces = faces
        self.node_head = arrays["node_head"]
        self.node_split = arrays["node_split"]
        self.prims = arrays["prims"]
        self.box = arrays["box"]
        self.stats = stats
        self._device_data: dict[str, KdTreeData] = {}
        self._workspace = threading.local()  # per thread: workspace()
        self._masked: np.ndarray | None = None  # (F,) bool: triangles the alpha test applies to
        self._coverage = None

    def set_alpha_test(self, masked: np.ndarray, coverage) -> None:
        """Cut-outs for :meth:`intersect` and :meth:`occluded`: ``masked`` (F,) bool marks the
        triangles of alpha-tested materials, ``coverage(prim, u, v)`` → (N,) bool says whether such a
        triangle is there at a hit. A rejected hit is not a hit: the ray goes on beyond it. The
        traversal kernels are unchanged — the test runs on the host over the hits on masked
        triangles only (a tree without masked triangles queries exactly as before)."""
        masked = np.asarray(masked, bool).reshape(-1)
        if masked.shape != (len(self.faces),):
            raise SerenityError(f"alpha test: {masked.shape[0]} flags for {len(self.faces)} triangles")
        self._masked = masked if masked.any() else None
        self._coverage = coverage if masked.any() else None

    # -- build and cache ------------------------------------------------------------------------

    @classmethod
    def build(cls, vertices, faces, *, config: KdBuildConfig | None = None, cache: bool | None = None,
              progress: bool | None = None) -> KdTree:
        """Build (or load from the disk cache) the tree of ``vertices`` (V,3) float32 and ``faces``
        (F,3) int32. ``cache=None`` caches meshes of ≥ ``CACHE_MIN_TRIANGLES`` triangles;
        ``progress=None`` shows a bar for ≥ ``PROGRESS_MIN_TRIANGLES``. An empty mesh raises
        :class:`SerenityError`."""
        v, f = validate_mesh(vertices, faces)
        cfg = config or KdBuildConfig()
        use_cache = len(f) >= CACHE_MIN_TRIANGLES if cache is None else bool(cache)
        show = len(f) >= PROGRESS_MIN_TRIANGLES if progress is None else bool(progress)
        path = None
        if use_cache:
            path = cache_dir() / f"kdtree-{geometry_key(v, f, cfg)}.npz"
            cached = load_tree(path, len(f))
            if cached is not None:
                return cls(v, f, *cached)
        t_start = time.perf_counter()
        arrays = build_arrays(v, f, cfg, show)
        seconds = time.perf_counter() - t_start
        stats = KdStats(triangles=len(f), build_seconds=seconds, **arrays.pop("stats"))
        if path is not None:
            save_tree(path, arrays, stats)
        return cls(v, f, arrays, stats)

    # -- device data ----------------------------------------------------------------------------

    def device_data(self, device: str) -> KdTreeData:
        """The tree's Warp arrays on ``device`` (created once per device)."""
        data = self._device_data.get(device)
        if data is None:
            wp_ = init_warp()
            data = KdTreeData()
            head = self.node_head
            leaf = (head & 3) == 3
            off = head >> 2
            count = np.where(leaf, self.prims[np.where(leaf, off, 0)], 0)  # the empty leaf's block: prims[0] = 0
            nodes = np.zeros(len(head), dtype=KdNode.numpy_dtype())
            child = np.where(leaf, 0, off)
            empty = leaf & (count == 0)
            if len(head) >= 1 << 27:
                raise SerenityError(f"kd-tree of {len(head):,} nodes: at most 2^27 fit the 8-byte node")
            if self.stats.depth >= STACK_SIZE:
                raise SerenityError(f"kd-tree of depth {self.stats.depth}: the traversal stack has {STACK_SIZE} slots")
            right = np.minimum(child + 1, len(head) - 1)
            flags = (empty[child].astype(np.int64) << 2) | (empty[right].astype(np.int64) << 3)
            tri = np.ascontiguousarray(self.vertices[self.faces], np.float32)  # (F, 3, 3)
            # each non-empty leaf's block of 10 k words: its k triangles' 9 vertex coordinates, one
            # coordinate after the other (x of v0 for all k, y of v0, ...), then their indices
            full = np.flatnonzero(leaf & (count > 0))
            k = count[full].astype(np.int64)
            block = np.concatenate([[0], np.cumsum(10 * k)]).astype(np.int64)
            if block[-1] >= 1 << 29:
                raise SerenityError(f"kd-tree of {block[-1]:,} leaf words: at most 2^29 fit the 8-byte node")
            leaf_word = np.zeros(len(head), np.int64)
            leaf_word[full] = block[:-1]
            nodes["head"] = np.where(leaf, (leaf_word << 2) | 3, (child << 4) | flags | (head & 3))
            nodes["split"] = np.where(leaf, count, self.node_split).astype(np.float32)
            data.nodes = wp_.array(nodes, dtype=KdNode, device=device)
            j = np.arange(k.sum()) - np.repeat(block[:-1] // 10, k)  # the triangle's place in its leaf
            tri_ids = self.prims[np.repeat(off[full] + 1, k) + j]
            at = np.repeat(block[:-1], k) + j
            kk = np.repeat(k, k)
            words = np.zeros(block[-1] + REF_PAD, np.float32)  # padded: SIMD loads may read past a leaf
            coords = tri[tri_ids].reshape(-1, 9)
            for c in range(9):
                words[at + c * kk] = coords[:, c]
            words.view(np.int32)[at + 9 * kk] = tri_ids
            data.refs = wp_.array(words, dtype=wp.float32, device=device)
            data.tri_verts = wp_.array(tri.reshape(-1, 3), dtype=wp.vec3, device=device)
            lo = self.box[0].astype(np.float64)
            hi = self.box[1].astype(np.float64)
            pad = BOX_PADDING * float(np.max(hi - lo)) + 1e-30
            data.box_lo = wp.vec3(*(lo - pad).tolist())
            data.box_hi = wp.vec3(*(hi + pad).tolist())
            data.scale = float(np.max(np.abs(np.concatenate([lo - pad, hi + pad]))))
            self._device_data[device] = data
        return data

    def workspace(self, device: str) -> Staging:
        """The calling thread's grow-only workspace buffers on ``device`` for queries of this tree (the
        reordered rays, their keys, the results traced in their order; the ray tracer's queries use
        them too), reused from one query to the next. New arrays each query cost first-touch page
        faults: ~3,000 per 0.92 M-ray batch, 1-2 ms per 11 MB array on the 2-core machine. Per
        thread, because a tree may be queried from several threads at once."""
        bufs = getattr(self._workspace, "buffers", None)
        if bufs is None:
            bufs = self._workspace.buffers = {}
        staging = bufs.get(device)
        if staging is None:
            staging = bufs[device] = Staging(device)
        return staging

    # -- queries --------------------------------------------------------------------------------

    @staticmethod
    def _rays(origins, directions, tmax) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        o = np.ascontiguousarray(np.asarray(origins, np.float32).reshape(-1, 3))
        d = np.ascontiguousarray(np.asarray(directions, np.float32).reshape(-1, 3))
        if len(o) != len(d):
            raise SerenityError(f"{len(o)} ray origins but {len(d)} directions")
        if np.ndim(tmax) == 0:
            return o, d, np.float32(tmax)  # one value: a filled workspace buffer (_ray_arrays)
        tm = np.ascontiguousarray(np.broadcast_to(np.asarray(tmax, np.float32), (len(o),)))
        return o, d, tm

    def _query_inputs(self, o, d, tm, dev: str, tmin: float, sort: bool | None,
                      threads: int | None) -> tuple[list, wp.array, bool]:
        """The query kernels' inputs (the tree, the rays in their traced order) and that order (empty:
        as given; else ray i of the kernel is the caller's ray ``order[i]``). ``tm``: :meth:`_rays`'
        tmax, 0-d when every ray has the same (then it needs no reordering). Third: whether a batch
        left in its order is coherent (:func:`batch_is_coherent`; on the CPU it is traced in packets)."""
        data = self.device_data(dev)
        workspace = self.workspace(dev)
        origins, directions, tmin, tmax = _ray_arrays(o, d, tm, dev, tmin, workspace)
        n = len(o)
        order = ray_order(data.box_lo, data.box_hi, origins, directions, n, sort, dev, threads, workspace)
        coherent = False
        if order.shape[0]:
            origins, directions = gather_in_order(order, [origins, directions], dev, threads, workspace)
            if np.ndim(tm) > 0:  # a scalar tmax (0-d ``tm``, :meth:`_rays`) needs no reordering
                (tmax,) = gather_in_order(order, [tmax], dev, threads, workspace)
        elif dev.startswith("cpu") and n >= PACKET_MIN_RAYS:
            # with sort=None, ray_order leaves a big batch in its order only when it found it coherent
            coherent = (sort is None and n >= SORT_MIN_RAYS) or batch_is_coherent(
                data.box_lo, data.box_hi, origins, directions, n, dev, threads)
        return [data, origins, directions, tmin, tmax], order, coherent

    def intersect(self, origins, directions, tmax=np.inf, device: str | None = None, *, tmin: float = 0.0,
                  threads: int | None = None, sort: bool | None = None, rays_per_thread: int | None = None) -> Hits:
        """Closest hits of rays ``origins`` (N,3), ``directions`` (N,3) with tmin < t < tmax
        (scalar or (N,)); t in units of |direction|. ``sort``: trace the rays in the reordered
        order (:func:`ray_order`; None = for batches of ≥ ``SORT_MIN_RAYS``); ``rays_per_thread``:
        1 (one ray per kernel thread), a slot count of ``INTERLEAVE_FACTORS`` (interleaved rays) or
        ``PACKET_LANES`` (packets), CPU only; None = interleaved when reordered, packets when
        coherent, else one ray (``_launch_query``). The results are the same
        either way, in the caller's order."""
        dev = resolve_device(device)
        o, d, tm = self._rays(origins, directions, tmax)
        hits = self._closest(o, d, tm, dev, tmin, threads, sort, rays_per_thread)
        if self._masked is not None and len(o):
            self._through_cutouts(hits, o, d, tm, dev, tmin, threads)
        return hits

    def _closest(self, o, d, tm, dev: str, tmin: float, threads: int | None, sort: bool | None,
                 rays_per_thread: int | None) -> Hits:
        """The closest-hit query of :meth:`intersect` without the alpha test."""
        n = len(o)
        if n:
            args, order, coherent = self._query_inputs(o, d, tm, dev, tmin, sort, threads)
            columns, records = hit_outputs(n, dev, order.shape[0] > 0)
            _launch_query(False, n, args, order, columns, dev, threads, rays_per_thread, self.workspace(dev), coherent,
                          records)
        else:
            columns, _ = hit_outputs(0, dev, False)
        out_t, out_p, out_u, out_v = (a.numpy() for a in columns)
        return Hits(t=out_t, prim=out_p, u=out_u, v=out_v)

    def _through_cutouts(self, hits: Hits, o, d, tm, dev: str, tmin: float, threads: int | None) -> None:
        """Replace, in place, the hits the alpha test rejects by what lies beyond them: those rays
        are traced again from their hit point on (origin moved to it, t measured from the original
        origin), up to ``MAX_CUTOUT_LAYERS`` times; a ray still on a rejected hit then misses."""
        eps = T_TOLERANCE * float(self.device_data(dev).scale)
        for layer in range(MAX_CUTOUT_LAYERS + 1):
            idx = np.flatnonzero(hits.prim >= 0)
            idx = idx[self._masked[hits.prim[idx]]]
            if len(idx):
                idx = idx[~self._coverage(hits.prim[idx], hits.u[idx], hits.v[idx])]
            if not len(idx):
                return
            if layer == MAX_CUTOUT_LAYERS:
                hits.t[idx], hits.prim[idx], hits.u[idx], hits.v[idx] = np.inf, -1, 0.0, 0.0
                return
            t0 = hits.t[idx].astype(np.float64)
            di = d[idx].astype(np.float64)
            step = eps / np.maximum(np.linalg.norm(di, axis=1), 1e-30)
            oi = (o[idx] + t0[:, None] * di).astype(np.float32)
            tmax_i = (np.broadcast_to(tm, (len(o),))[idx] - t0).astype(np.float32)
            oi, di32, tmax_i = self._rays(oi, d[idx], tmax_i)
            again = self._closest(oi, di32, tmax_i, dev, float(step.min()), threads, None, None)
            hit = again.prim >= 0
            hits.t[idx] = np.where(hit, (t0 + again.t).astype(np.float32), np.inf)
            hits.prim[idx], hits.u[idx], hits.v[idx] = again.prim, again.u, again.v

    def occluded(self, origins, directions, tmax=np.inf, device: str | None = None, *, tmin: float = 0.0,
                 threads: int | None = None, sort: bool | None = None,
                 rays_per_thread: int | None = None) -> np.ndarray:
        """(N,) bool: does anything lie on each ray with tmin < t < tmax? (any hit: the traversal
        stops at the first one; ``sort`` and ``rays_per_thread`` as for :meth:`intersect`)"""
        dev = resolve_device(device)
        o, d, tm = self._rays(origins, directions, tmax)
        n = len(o)
        out = wp.zeros(n, dtype=wp.int32, device=dev)
        if n:
            args, order, coherent = self._query_inputs(o, d, tm, dev, tmin, sort, threads)
            _launch_query(True, n, args, order, [out], dev, threads, rays_per_thread, self.workspace(dev), coherent)
        occ = out.numpy().astype(bool)
        if self._masked is not None and occ.any():
            # an any hit may be a rejected cut-out: the occluded rays look for their nearest kept hit
            idx = np.flatnonzero(occ)
            tmi = tm if np.ndim(tm) == 0 else tm[idx]
            occ[idx] = self.intersect(o[idx], d[idx], tmi, dev, tmin=tmin, threads=threads).prim >= 0
        return occ


__all__ = ["CACHE_MIN_TRIANGLES", "CHUNKS_PER_THREAD", "CPU_RAYS_PER_THREAD", "INTERLEAVE_FACTORS", "KEY_LANES",
           "PACKET_LANES", "PACKET_MIN_RAYS", "PACKET_WORKSPACE", "PROGRESS_MIN_TRIANGLES", "SORT_DIRECTION_BITS",
           "SORT_MIN_RAYS", "SORT_ORIGIN_BITS", "Hits", "KdBuildConfig", "KdNode", "KdStats", "KdTree",
           "KdTreeData", "batch_is_coherent", "buffers_like", "cache_dir", "finite", "gather_array",
           "gather_in_order", "hit_outputs", "inner_step_flat", "intersect_rays",
           "intersect_triangle", "intersect_triangle_fixed",
           "leaf_hits", "lowest_lane", "move_in_order", "node_head", "node_split", "occlude_rays", "origin_cell",
           "packet_pop",
           "packet_step", "ray_order", "ray_sort_key", "ref_prim", "ref_vertex",
           "sample_key_changes", "scatter_array", "scatter_hits", "scatter_in_order", "setup_ray", "sort_keys",
           "sort_keys_simd",
           "sort_scale",
           "spread_bits", "start_ray", "trace_kd", "trace_packets_kernel", "trace_rays_kernel"]

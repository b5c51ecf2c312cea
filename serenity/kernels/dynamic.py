"""Dynamic geometry for the ray tracer: rigid objects that move every frame, traced beside the static
kd-tree in two levels (the paper's "Conclusions and Future Work": its §9 kd-tree is too costly to
rebuild in real time, which limits the ray tracer to static geometry).

:class:`DynamicGeometry` holds rigid objects, each a triangle mesh in its own object space:

- bottom level: an object's triangles in a Warp BVH of their (padded) boxes in object space
  (``wp.Bvh``, SAH), built once by :meth:`DynamicGeometry.add` and never rebuilt or refit while the
  object only moves;
- top level: the objects' world boxes (the object-space box's 8 corners through the object's
  transform, padded by ``BOX_PADDING`` of their size) in a balanced tree over their Morton order
  (``top_level_tree``), built anew by every :meth:`DynamicGeometry.set_transforms` and traversed
  front to back (``TOP_LEVELS``: or every box in turn; ``TOP_LEVEL`` says which is the default and
  why).

A ray visits the objects whose world box it enters before its best hit so far, nearest box first.
For each one it is turned into the object's space by the inverse transform (float64, then rounded to
float32) with its direction *not* renormalised: the affine map takes the world point o + t·d to o' + t·d', so t stays
the world ray's parameter (units of |d|) and the best hit so far bounds every object's query as it
is, under any invertible affine transform — rotation, translation, uniform or non-uniform scale,
shear, mirror. The object's BVH yields the triangles whose boxes the ray enters before its best hit so
far (``wp.bvh_query_ray``), and each goes through the kd-tree's own triangle test
(``kdtree.triangle.intersect_triangle``: Woop's watertight test, edge functions in float64) under the
kd-tree's rule (the closest hit; equal t resolve to the lower triangle index).

Why not ``wp.Mesh`` and its ``mesh_query_ray``: Warp's test computes its edge functions in float32
(a float64 fallback only where one is exactly 0), so a ray through a shared edge or vertex can pass
between two triangles: rays from inside closed meshes aimed at their vertices and edges (the
kd-tree's watertightness test) escaped 48 of 76,806 times through an icosphere and 102 of 17,286
through a capsule, where this test lets none through (``tests/kernels/test_dynamic.py``). It also has
no tmin (its hits start at t = 0) and gives Warp's barycentrics. Its traversal is faster (near child
first, packed nodes): the same rays took 1.1-1.5× its CPU time here (one thread; 64k random rays
into a 328k-triangle sphere 24.5 ms against 16.4, 58k camera rays 27.7 against 24.1).

Rays: origins ``o`` (N,3) and directions ``d`` (N,3) float32, hits with tmin < t < tmax (tmin a scalar,
tmax a scalar or (N,)), numpy or Warp arrays on the geometry's device, as ``KdTree.intersect``
takes them. Degenerate rays (a zero, NaN or infinite direction, a NaN or infinite origin, tmax ≤ tmin
or NaN) are misses, as in the kd-tree. The objects' BVH queries take the direction with its zero components
made 1e-30 (``query_direction``): their slab test multiplies by 1/d, and 0·inf would be NaN for an
origin on a box's face.

Results (:class:`serenity.kernels.kdtree.Hits`): t (inf on a miss), prim = ``prim_base`` + the
object's first triangle (objects numbered in the order they were added, each after the triangles of
those before it) + the face's index in the object (−1 on a miss), and the barycentrics in the
kd-tree's convention p = (1−u−v)·v0 + u·v1 + v·v2 (those of an affine image are the object-space
ones). A caller puts the dynamic triangles after the static ones with ``prim_base`` = the static
triangle count (``two_level.TwoLevelTracer`` does). There is no alpha test for dynamic triangles.

:class:`serenity.kernels.two_level.TwoLevelTracer` traces a static kd-tree and a
:class:`DynamicGeometry` as one scene.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from serenity.device import init_warp, resolve_device
from serenity.errors import SerenityError
from serenity.kernels.factory import kernel_factory
from serenity.kernels.kdtree import Hits, KdTree
from serenity.kernels.kdtree.layout import INF, TINY, TRACE_MODULE_OPTIONS, finite
from serenity.kernels.kdtree.triangle import intersect_triangle_fixed, setup_ray
from serenity.kernels.launch import launch

wp.set_module_options(TRACE_MODULE_OPTIONS)

# ----------------------------------------------------------------------------------------------
# constants
# ----------------------------------------------------------------------------------------------

#: the top level's forms: "bvh" (``top_level_tree``, traversed front to back) and "linear" (every
#: object's world box tested in turn)
TOP_LEVELS = ("bvh", "linear")
#: the top level's traversal stack: one entry per level and one, enough for 2^30 objects (``MAX_OBJECTS``)
TOP_STACK = 32
MAX_OBJECTS = 1 << 30
top_stack_i = wp.types.vector(length=TOP_STACK, dtype=wp.int32)
top_stack_f = wp.types.vector(length=TOP_STACK, dtype=wp.float32)
#: the top level a :class:`DynamicGeometry` uses by default: "bvh", as fast as "linear" or faster at
#: every object count measured (spheres of 1k triangles in front of the courtyard's camera, CPU seconds
#: on one thread; 320x180 camera rays / 64k random rays among the objects, ms): 1 object 1.5 / 1.9
#: against 1.8 / 2.2, 10 objects 4.7 / 13.6 against 9.3 / 13.2, 100 objects 31 / 132 against 115 / 192
#: (``benchmarks/bench_dynamic.py``'s ``objects`` figures compare them too)
TOP_LEVEL = "bvh"
#: boxes (an object's world box, a triangle's box in object space) are padded by this fraction of the
#: largest extent plus the largest |coordinate| (of the object): the float32 ray–box tests must never
#: cull a triangle the exact box holds
BOX_PADDING = 1e-5
#: triangles per leaf of an object's BVH: 4 and 8 traced the benchmark's rays ~5 % faster than 1 (CPU
#: seconds, one thread, 5k-330k-triangle spheres; 4 and 8 alike within the noise)
BVH_LEAF_SIZE = 4
#: a BVH query's direction has its zero components made this (``query_direction``)
TINY_COMPONENT = wp.constant(1e-30)
#: a transform whose linear part has a condition number (largest / smallest singular value) above
#: this is refused: the object-space ray, rounded to float32, would lose its precision
MAX_CONDITION = 1e6
#: an affine transform's last row is (0, 0, 0, 1) within this
AFFINE_TOLERANCE = 1e-9
#: a box's 8 corners: which coordinates come from its upper corner (``world_boxes``)
_CORNERS = np.stack(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij"), -1).reshape(8, 3) == 1


# ----------------------------------------------------------------------------------------------
# structs
# ----------------------------------------------------------------------------------------------


@wp.struct
class DynamicData:
    """The objects on a device: ``count`` objects; the top level (``top_level_tree``): node boxes
    ``node_lo``/``node_hi`` (2L−1,) in heap order (node n's children 2n+1 and 2n+2), leaves from
    ``leaf_first`` = L−1 on, leaf j holding object ``leaf_object[j]`` (j < count); each object's BVH id
    (``bvhs``: its triangles' boxes in object space), world → object transform (``to_object`` linear
    part, ``to_object_offset``: x' = to_object·x + offset, float64) and first triangle (``first``,
    without ``prim_base``); the triangles' object-space vertices ``tri_verts`` (3F,): triangle f's at
    3f, 3f+1, 3f+2."""

    count: wp.int32
    leaf_first: wp.int32
    node_lo: wp.array(dtype=wp.vec3)
    node_hi: wp.array(dtype=wp.vec3)
    leaf_object: wp.array(dtype=wp.int32)
    bvhs: wp.array(dtype=wp.uint64)
    tri_verts: wp.array(dtype=wp.vec3)
    to_object: wp.array(dtype=wp.mat33d)
    to_object_offset: wp.array(dtype=wp.vec3d)
    first: wp.array(dtype=wp.int32)


# ----------------------------------------------------------------------------------------------
# functions
# ----------------------------------------------------------------------------------------------


@wp.func
def vec3d_of(a: wp.vec3):
    return wp.vec3d(wp.float64(a[0]), wp.float64(a[1]), wp.float64(a[2]))


@wp.func
def query_direction(d: wp.vec3):
    """``d`` for a BVH query: zero components made ``TINY_COMPONENT`` (module docstring)."""
    return wp.vec3(wp.where(d[0] == 0.0, TINY_COMPONENT, d[0]), wp.where(d[1] == 0.0, TINY_COMPONENT, d[1]),
                   wp.where(d[2] == 0.0, TINY_COMPONENT, d[2]))


@wp.func
def object_ray(data: DynamicData, k: int, o: wp.vec3d, d: wp.vec3d):
    """The world ray (o, d) in object ``k``'s space, float32: the origin through the full inverse
    transform, the direction through its linear part (not renormalised)."""
    m = data.to_object[k]
    p = m * o + data.to_object_offset[k]
    q = m * d
    return wp.vec3(float(p[0]), float(p[1]), float(p[2])), wp.vec3(float(q[0]), float(q[1]), float(q[2]))


@wp.func
def inverse_direction(d: wp.vec3) -> wp.vec3:
    """1/d per axis, 0 on an axis the ray is parallel to (``box_entry`` tests that axis apart)."""
    inv = wp.vec3(0.0, 0.0, 0.0)
    for a in range(3):
        if d[a] != 0.0:
            inv[a] = 1.0 / d[a]
    return inv


@wp.func
def box_entry(lo: wp.vec3, hi: wp.vec3, o: wp.vec3, inv: wp.vec3, tlo: float, tmax: float) -> float:
    """Where the ray (origin ``o``, ``inv`` = ``inverse_direction``) enters the box within (tlo, tmax):
    its entry t (≥ tlo), or inf if it misses it or the box is empty (lo > hi). An axis the ray is
    parallel to bounds it by the origin's side of the slab (no 0·inf)."""
    t0 = tlo
    t1 = tmax
    if lo[0] > hi[0]:
        t1 = -1.0
    for a in range(3):
        if inv[a] == 0.0:
            if o[a] < lo[a] or o[a] > hi[a]:
                t1 = -1.0
        else:
            ta = (lo[a] - o[a]) * inv[a]
            tb = (hi[a] - o[a]) * inv[a]
            t0 = wp.max(t0, wp.min(ta, tb))
            t1 = wp.min(t1, wp.max(ta, tb))
    out = float(INF)
    if t0 <= t1:
        out = t0
    return out


@wp.func
def visit_closest(data: DynamicData, k: int, o: wp.vec3d, d: wp.vec3d, tlo: float, best: float, prim: int,
                  hit_u: float, hit_v: float):
    """Object ``k``'s triangles against the best hit so far (best, prim: t and the dynamic triangle
    index, −1 for none; u, v), which it returns updated under the kd-tree's rule."""
    po, pd = object_ray(data, k, o, d)
    kx, ky, kz, sx, sy, sz = setup_ray(pd)
    base = data.first[k]
    query = wp.bvh_query_ray(data.bvhs[k], po, query_direction(pd))
    f = int(0)
    while wp.bvh_query_next(query, f, best):
        j = 3 * (base + f)
        hit, t, u, v = intersect_triangle_fixed(po, kx, ky, kz, sx, sy, sz, data.tri_verts[j], data.tri_verts[j + 1],
                                                data.tri_verts[j + 2], tlo, best)
        if hit and (t < best or base + f < prim):
            best = t
            prim = base + f
            hit_u = u
            hit_v = v
    return best, prim, hit_u, hit_v


@wp.func
def visit_any(data: DynamicData, k: int, o: wp.vec3d, d: wp.vec3d, tlo: float, tmax: float) -> bool:
    """Whether object ``k`` has a triangle at tlo < t < tmax (world t)."""
    po, pd = object_ray(data, k, o, d)
    kx, ky, kz, sx, sy, sz = setup_ray(pd)
    base = data.first[k]
    query = wp.bvh_query_ray(data.bvhs[k], po, query_direction(pd))
    f = int(0)
    found = bool(False)
    while wp.bvh_query_next(query, f, tmax):
        j = 3 * (base + f)
        hit, t, u, v = intersect_triangle_fixed(po, kx, ky, kz, sx, sy, sz, data.tri_verts[j], data.tri_verts[j + 1],
                                                data.tri_verts[j + 2], tlo, tmax)
        if hit and t < tmax:
            found = True
            break
    return found


@wp.func
def valid_ray(o: wp.vec3, d: wp.vec3, tlo: float, tmax: float) -> bool:
    """The kd-tree's rule: finite origin and direction, a direction not below ``TINY``, tmax > tlo."""
    ok = finite(o[0]) and finite(o[1]) and finite(o[2]) and finite(d[0]) and finite(d[1]) and finite(d[2])
    big = wp.max(wp.max(wp.abs(d[0]), wp.abs(d[1])), wp.abs(d[2]))
    return ok and big >= TINY and tmax > tlo


# ----------------------------------------------------------------------------------------------
# kernels
# ----------------------------------------------------------------------------------------------


@kernel_factory(any_hit=(False, True), top=TOP_LEVELS)
def trace_dynamic_kernel(any_hit: bool, top: str):
    """The dynamic query's kernel: closest hit (``any_hit=False``: in/out ``hit_*``, each ray's hit so
    far bounding its search, replaced where an object is nearer) or any hit (in/out ``occluded``: a
    ray already occluded is skipped), over the top level ``top`` (``TOP_LEVELS``). ``tmax``: per ray,
    or empty for ``tmax_all``. Rays ``i = tid + offset`` (``launch``)."""

    @wp.kernel(enable_backward=False, module="unique", module_options=TRACE_MODULE_OPTIONS)
    def trace_dynamic(
        # inputs
        data: DynamicData,
        prim_base: int,
        origins: wp.array(dtype=wp.vec3),
        directions: wp.array(dtype=wp.vec3),
        tmin: float,
        tmax_all: float,
        tmax: wp.array(dtype=float),
        # outputs (in/out)
        hit_t: wp.array(dtype=float),
        hit_prim: wp.array(dtype=wp.int32),
        hit_u: wp.array(dtype=float),
        hit_v: wp.array(dtype=float),
        occluded: wp.array(dtype=wp.int32),
        offset: int,
    ):
        i = wp.tid() + offset
        o = origins[i]
        d = directions[i]
        tm = tmax_all
        if tmax.shape[0] > 0:
            tm = tmax[i]
        tlo = wp.max(tmin, 0.0)
        if not valid_ray(o, d, tlo, tm):  # before the min below, which would turn a NaN tmax into a number
            return
        if wp.static(any_hit):
            if occluded[i] != 0:
                return
        else:
            tm = wp.min(tm, hit_t[i])
            if not (tm > tlo):
                return
        d64 = vec3d_of(d)
        o64 = vec3d_of(o)
        best = tm
        prim = int(-1)
        u = float(0.0)
        v = float(0.0)
        found = int(0)
        inv = inverse_direction(d)
        if wp.static(top == "bvh"):
            # the balanced tree front to back: the nearer child popped first, a node skipped once the
            # best hit is nearer than its box
            stack = top_stack_i()
            entry = top_stack_f()
            sp = int(0)
            t_root = box_entry(data.node_lo[0], data.node_hi[0], o, inv, tlo, best)
            if t_root < best:
                stack[0] = 0
                entry[0] = t_root
                sp = 1
            while sp > 0:
                sp -= 1
                node = stack[sp]
                if entry[sp] < best:
                    if node >= data.leaf_first:
                        k = data.leaf_object[node - data.leaf_first]
                        if wp.static(any_hit):
                            if visit_any(data, k, o64, d64, tlo, tm):
                                found = 1
                                break
                        else:
                            best, prim, u, v = visit_closest(data, k, o64, d64, tlo, best, prim, u, v)
                    else:
                        left = 2 * node + 1
                        t_left = box_entry(data.node_lo[left], data.node_hi[left], o, inv, tlo, best)
                        t_right = box_entry(data.node_lo[left + 1], data.node_hi[left + 1], o, inv, tlo, best)
                        near = left
                        t_near = t_left
                        far = left + 1
                        t_far = t_right
                        if t_right < t_left:
                            near = left + 1
                            t_near = t_right
                            far = left
                            t_far = t_left
                        if t_far < best:
                            stack[sp] = far
                            entry[sp] = t_far
                            sp += 1
                        if t_near < best:
                            stack[sp] = near
                            entry[sp] = t_near
                            sp += 1
        else:
            for j in range(data.count):
                node = data.leaf_first + j
                if box_entry(data.node_lo[node], data.node_hi[node], o, inv, tlo, best) < best:
                    k = data.leaf_object[j]
                    if wp.static(any_hit):
                        if visit_any(data, k, o64, d64, tlo, tm):
                            found = 1
                            break
                    else:
                        best, prim, u, v = visit_closest(data, k, o64, d64, tlo, best, prim, u, v)
        if wp.static(any_hit):
            if found != 0:
                occluded[i] = 1
        elif prim >= 0:
            hit_t[i] = best
            hit_prim[i] = prim_base + prim
            hit_u[i] = u
            hit_v[i] = v

    return trace_dynamic


# ----------------------------------------------------------------------------------------------
# host
# ----------------------------------------------------------------------------------------------


def check_transforms(matrices, count: int) -> np.ndarray:
    """``matrices`` as (count, 4, 4) float64 object → world transforms, or a one-line error: not
    (count, 4, 4), not finite, not affine (last row (0, 0, 0, 1)), or a linear part that is singular or
    whose condition number passes ``MAX_CONDITION`` (a zero or near-zero scale)."""
    try:
        m = np.array(matrices, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise SerenityError(f"dynamic transforms: not an array of numbers ({e})") from None
    if m.shape == (4, 4) and count == 1:
        m = m[None]
    if m.ndim != 3 or m.shape[1:] != (4, 4):
        raise SerenityError(f"dynamic transforms: ({count}, 4, 4) matrices expected, got shape {m.shape}")
    if len(m) != count:
        raise SerenityError(f"dynamic transforms: {len(m)} matrices for {count} objects")
    bad = np.flatnonzero(~np.isfinite(m).all(axis=(1, 2)))
    if len(bad):
        raise SerenityError(f"dynamic transforms: object {bad[0]}'s matrix is not finite (NaN or inf)")
    bad = np.flatnonzero(np.abs(m[:, 3] - (0.0, 0.0, 0.0, 1.0)).max(axis=1) > AFFINE_TOLERANCE)
    if len(bad):
        raise SerenityError(f"dynamic transforms: object {bad[0]}'s matrix is not affine (last row "
                            f"{m[bad[0], 3].tolist()}, expected [0, 0, 0, 1])")
    if count:
        s = np.linalg.svd(m[:, :3, :3], compute_uv=False)
        cond = np.where(s[:, 2] > 0, s[:, 0] / np.maximum(s[:, 2], 1e-300), np.inf)
        bad = np.flatnonzero(~(cond <= MAX_CONDITION))
        if len(bad):
            k = bad[0]
            raise SerenityError(f"dynamic transforms: object {k}'s matrix is degenerate (scales {s[k, 0]:.3g} to "
                                f"{s[k, 2]:.3g}, at most {MAX_CONDITION:.0e} apart)")
    return m


def _spread_bits(x: np.ndarray) -> np.ndarray:
    """10-bit integers with two zero bits after each bit (a Morton code's one axis)."""
    x = x.astype(np.uint32) & 0x3FF
    x = (x | (x << 16)) & 0x030000FF
    x = (x | (x << 8)) & 0x0300F00F
    x = (x | (x << 4)) & 0x030C30C3
    return (x | (x << 2)) & 0x09249249


def top_level_tree(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The top level over K world boxes ``lo``/``hi`` (K,3): a balanced binary tree in heap order whose
    L = 2^⌈log2 K⌉ leaves hold the objects in the Morton order of their boxes' centres (the last L − K
    empty: lo > hi), each inner node the box of its two children. Returns the node boxes (2L−1, 3)
    float32 and the leaves' objects (L,) int32 (−1 for none). Numpy, O(K log K): 0.05-0.2 ms for 1-100
    objects, 0.7 ms for 1000. Warp's own BVH is not used here: its queries share one stack per kernel
    on CUDA (``bvh_query`` keeps it in ``__shared__`` memory), so a query inside another — the top
    level's around an object's — would have its stack overwritten."""
    k = len(lo)
    leaves = 1 << max(0, (k - 1).bit_length())
    c = 0.5 * (lo.astype(np.float64) + hi)
    c_lo, c_hi = c.min(axis=0), c.max(axis=0)
    q = ((c - c_lo) / np.maximum(c_hi - c_lo, 1e-30) * 1023).astype(np.uint32)
    code = _spread_bits(q[:, 0]) | (_spread_bits(q[:, 1]) << 1) | (_spread_bits(q[:, 2]) << 2)
    order = np.argsort(code, kind="stable")
    big = np.float32(np.finfo(np.float32).max)
    node_lo = np.full((2 * leaves - 1, 3), big, np.float32)
    node_hi = np.full((2 * leaves - 1, 3), -big, np.float32)
    node_lo[leaves - 1:leaves - 1 + k] = lo[order]
    node_hi[leaves - 1:leaves - 1 + k] = hi[order]
    n = leaves
    while n > 1:  # one level up: nodes n/2 − 1 … n − 2 from their children n − 1 … 2n − 2
        kids = slice(n - 1, 2 * n - 1)
        node_lo[n // 2 - 1:n - 1] = node_lo[kids].reshape(-1, 2, 3).min(axis=1)
        node_hi[n // 2 - 1:n - 1] = node_hi[kids].reshape(-1, 2, 3).max(axis=1)
        n //= 2
    objects = np.full(leaves, -1, np.int32)
    objects[:k] = order
    return node_lo, node_hi, objects


def world_boxes(lo: np.ndarray, hi: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K,3) float32 world boxes of object-space boxes ``lo``/``hi`` (K,3) under ``m`` (K,4,4): their
    corners transformed (float64), padded by ``BOX_PADDING`` of their size."""
    pts = np.where(_CORNERS[None], hi[:, None], lo[:, None])  # (K, 8, 3)
    w = np.einsum("kij,kcj->kci", m[:, :3, :3], pts) + m[:, None, :3, 3]
    wlo, whi = w.min(axis=1), w.max(axis=1)
    pad = BOX_PADDING * ((whi - wlo).max(axis=1) + np.abs(w).max(axis=(1, 2)))[:, None]
    return (wlo - pad).astype(np.float32), (whi + pad).astype(np.float32)


def triangle_bvh(tris: np.ndarray, device: str) -> wp.Bvh:
    """A ``wp.Bvh`` (SAH) over triangles ``tris`` (F,3,3) float32: their boxes, padded by
    ``BOX_PADDING`` of the object's size."""
    t = tris.astype(np.float64)
    size = float(np.ptp(t.reshape(-1, 3), axis=0).max() + np.abs(t).max())
    pad = BOX_PADDING * size
    lo = wp.array((t.min(axis=1) - pad).astype(np.float32), dtype=wp.vec3, device=device)
    hi = wp.array((t.max(axis=1) + pad).astype(np.float32), dtype=wp.vec3, device=device)
    return wp.Bvh(lo, hi, constructor="sah", leaf_size=BVH_LEAF_SIZE)


def ray_batch(origins, directions, tmax, device: str) -> tuple:
    """(origins, directions, tmax, whether the rays are Warp arrays): the kd-tree's checks
    (``KdTree.host_rays`` / ``KdTree.device_rays``); numpy rays become Warp arrays on ``device`` (a view
    on the CPU, a copy on a GPU), a numpy (N,) tmax too."""
    if isinstance(origins, wp.array) or isinstance(directions, wp.array):
        o, d, tm, _ = KdTree.device_rays(origins, directions, tmax, device)
        on_device = True
    else:
        o, d, tm = KdTree.host_rays(origins, directions, tmax)
        copy = not device.startswith("cpu")
        o = wp.array(o, dtype=wp.vec3, device=device, copy=copy)
        d = wp.array(d, dtype=wp.vec3, device=device, copy=copy)
        on_device = False
    if not isinstance(tm, wp.array) and np.ndim(tm) > 0:
        tm = wp.array(tm, dtype=float, device=device, copy=not device.startswith("cpu"))
    return o, d, tm, on_device


class DynamicGeometry:
    """Rigid objects traced in two levels (module docstring) on one device.

    ``add(positions, faces)`` an object (object space; id = its index), ``set_transforms(matrices)``
    each frame, then :meth:`intersect` (closest hit) and :meth:`occluded` (any hit), or both beside a
    kd-tree through ``two_level.TwoLevelTracer``. ``prim_base`` is added to every hit's triangle index.
    """

    def __init__(self, device: str | None = None, *, prim_base: int = 0, top_level: str = TOP_LEVEL):
        init_warp()
        if top_level not in TOP_LEVELS:
            raise SerenityError(f"dynamic top level {top_level!r}: one of {', '.join(TOP_LEVELS)}")
        self.device = resolve_device(device)
        self.prim_base = int(prim_base)
        self.top_level = top_level
        self._bvhs: list[wp.Bvh] = []  # each object's, over its triangles' boxes in object space
        self._positions: list[np.ndarray] = []
        self._faces: list[np.ndarray] = []
        self._first: list[int] = []
        self._lo = np.zeros((0, 3))
        self._hi = np.zeros((0, 3))
        self._matrices = np.zeros((0, 4, 4))
        self._data: DynamicData | None = None  # the device data, remade when objects are added
        self._stale = True  # the top level and the transforms on the device need an update

    # -- objects --------------------------------------------------------------------------------

    @property
    def object_count(self) -> int:
        return len(self._bvhs)

    @property
    def triangle_count(self) -> int:
        return sum(len(f) for f in self._faces)

    @property
    def first_triangles(self) -> np.ndarray:
        """(K,) int64: each object's first triangle in the dynamic numbering (before ``prim_base``)."""
        return np.asarray(self._first, np.int64)

    @property
    def transforms(self) -> np.ndarray:
        """(K, 4, 4) float64: the objects' object → world transforms (identity until set)."""
        return self._matrices.copy()

    def add(self, positions, faces) -> int:
        """Add an object: ``positions`` (V,3) in object space, ``faces`` (F,3) vertex indices. Its BVH is
        built now, once; its transform is the identity until :meth:`set_transforms`. Returns its id."""
        v = np.asarray(positions)
        f = np.asarray(faces)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
            raise SerenityError(f"dynamic object positions: a (V, 3) array expected, got shape {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
            raise SerenityError(f"dynamic object faces: an (F, 3) array expected, got shape {f.shape}")
        if not np.issubdtype(f.dtype, np.integer):
            raise SerenityError(f"dynamic object faces: integer vertex indices expected, got {f.dtype}")
        if f.min() < 0 or f.max() >= len(v):
            raise SerenityError(f"dynamic object faces: indices out of range 0..{len(v) - 1}")
        if self.object_count >= MAX_OBJECTS:
            raise SerenityError(f"dynamic geometry: at most {MAX_OBJECTS} objects")
        v = np.ascontiguousarray(v, np.float32)
        if not np.isfinite(v).all():
            raise SerenityError("dynamic object positions: NaN or infinite coordinates")
        f = np.ascontiguousarray(f, np.int32)
        used = v[np.unique(f)].astype(np.float64)
        self._bvhs.append(triangle_bvh(v[f], self.device))
        self._first.append(self.triangle_count)
        self._positions.append(v)
        self._faces.append(f)
        self._lo = np.vstack([self._lo, used.min(axis=0)])
        self._hi = np.vstack([self._hi, used.max(axis=0)])
        self._matrices = np.concatenate([self._matrices, np.eye(4)[None]])
        self._data = None
        self._stale = True
        return len(self._bvhs) - 1

    def set_transforms(self, matrices) -> None:
        """Pose every object: ``matrices`` (K,4,4) object → world, float64 (a (4,4) for one object).
        Any invertible affine transform (rotation, translation, uniform or non-uniform scale, shear,
        mirror; ``check_transforms`` says what is refused). The objects' BVHs are untouched; the top
        level is rebuilt over their new world boxes."""
        self._matrices = check_transforms(matrices, self.object_count)
        self._stale = True
        self.update()

    def update(self) -> None:
        """Bring the device's transforms and top level up to date (done by :meth:`set_transforms` and by
        a query after :meth:`add`)."""
        if not self._stale:
            return
        k = self.object_count
        dev = self.device
        if k and self._data is None:
            leaves = 1 << max(0, (k - 1).bit_length())
            data = DynamicData()
            data.count = k
            data.leaf_first = leaves - 1
            data.node_lo = wp.empty(2 * leaves - 1, dtype=wp.vec3, device=dev)
            data.node_hi = wp.empty(2 * leaves - 1, dtype=wp.vec3, device=dev)
            data.leaf_object = wp.empty(leaves, dtype=wp.int32, device=dev)
            data.bvhs = wp.array([b.id for b in self._bvhs], dtype=wp.uint64, device=dev)
            data.tri_verts = wp.array(np.concatenate([v[f] for v, f in zip(self._positions, self._faces, strict=True)])
                                      .reshape(-1, 3), dtype=wp.vec3, device=dev)
            data.first = wp.array(np.asarray(self._first, np.int32), dtype=wp.int32, device=dev)
            data.to_object = wp.empty(k, dtype=wp.mat33d, device=dev)
            data.to_object_offset = wp.empty(k, dtype=wp.vec3d, device=dev)
            self._data = data
        if k:
            m = self._matrices
            inv = np.linalg.inv(m)
            node_lo, node_hi, objects = top_level_tree(*world_boxes(self._lo, self._hi, m))
            data = self._data
            data.to_object.assign(np.ascontiguousarray(inv[:, :3, :3]))
            data.to_object_offset.assign(np.ascontiguousarray(inv[:, :3, 3]))
            data.node_lo.assign(node_lo)
            data.node_hi.assign(node_hi)
            data.leaf_object.assign(objects)
        self._stale = False

    def posed_triangles(self) -> tuple[np.ndarray, np.ndarray]:
        """Every object's triangles in world space, in the dynamic numbering: vertices (V,3) float32
        (transformed in float64) and faces (F,3) int32 — for a reference kd-tree of the posed scene,
        or for shading a hit."""
        if not self.object_count:
            return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32)
        verts, faces, base = [], [], 0
        for v, f, m in zip(self._positions, self._faces, self._matrices, strict=True):
            verts.append((v.astype(np.float64) @ m[:3, :3].T + m[:3, 3]).astype(np.float32))
            faces.append(f + base)
            base += len(v)
        return np.concatenate(verts), np.concatenate(faces)

    # -- queries --------------------------------------------------------------------------------

    def intersect(self, origins, directions, tmax=np.inf, *, tmin: float = 0.0, threads: int | None = None) -> Hits:
        """Closest hits among the objects (module docstring): numpy rays give numpy :class:`Hits`,
        Warp rays on this device Warp ones."""
        o, d, tm, on_device = ray_batch(origins, directions, tmax, self.device)
        n = o.shape[0]
        dev = self.device
        hits = Hits(t=wp.full(n, np.inf, dtype=float, device=dev), prim=wp.full(n, -1, dtype=wp.int32, device=dev),
                    u=wp.zeros(n, dtype=float, device=dev), v=wp.zeros(n, dtype=float, device=dev))
        self.trace_into(hits, o, d, tm, tmin, self.prim_base, threads)
        return hits if on_device else hits.numpy()

    def occluded(self, origins, directions, tmax=np.inf, *, tmin: float = 0.0,
                 threads: int | None = None) -> np.ndarray | wp.array:
        """(N,) bool: does an object lie on each ray with tmin < t < tmax? Warp rays give an (N,) int32
        Warp array on this device, 1 where occluded."""
        o, d, tm, on_device = ray_batch(origins, directions, tmax, self.device)
        out = wp.zeros(o.shape[0], dtype=wp.int32, device=self.device)
        self.occlude_into(out, o, d, tm, tmin, threads)
        return out if on_device else out.numpy().astype(bool)

    def _launch(self, any_hit: bool, n: int, o, d, tm, tmin: float, prim_base: int, outputs: list,
                threads: int | None) -> None:
        self.update()
        if not (n and self.object_count):
            return
        dev = self.device
        if isinstance(tm, wp.array):
            tmax_all, tmax = 0.0, tm
        else:
            tmax_all, tmax = float(tm), wp.empty(0, dtype=float, device=dev)
        launch(trace_dynamic_kernel(any_hit, self.top_level), n,
               [self._data, int(prim_base), o, d, float(tmin), tmax_all, tmax, *outputs], device=dev, threads=threads,
               balanced=True)

    def trace_into(self, hits: Hits, o: wp.array, d: wp.array, tm, tmin: float, prim_base: int,
                   threads: int | None = None) -> None:
        """Closest hits into ``hits`` (Warp arrays on this device), in place: each ray's hit there
        bounds its search (t inf and prim −1 for none) and is replaced where an object is nearer.
        ``o``, ``d``: (N,) ``wp.vec3`` here; ``tm`` a scalar or an (N,) float32 Warp array."""
        none = wp.empty(0, dtype=wp.int32, device=self.device)
        self._launch(False, o.shape[0], o, d, tm, tmin, prim_base, [hits.t, hits.prim, hits.u, hits.v, none],
                     threads)

    def occlude_into(self, occluded: wp.array, o: wp.array, d: wp.array, tm, tmin: float,
                     threads: int | None = None) -> None:
        """Any hits into ``occluded`` ((N,) int32 here), in place: rays already 1 are skipped, the others
        set to 1 where an object lies on them (``trace_into``'s rays)."""
        dev = self.device
        none_f = wp.empty(0, dtype=float, device=dev)
        none_i = wp.empty(0, dtype=wp.int32, device=dev)
        self._launch(True, o.shape[0], o, d, tm, tmin, 0, [none_f, none_i, none_f, none_f, occluded], threads)


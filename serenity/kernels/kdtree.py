"""SAH kd-tree over a triangle mesh: an O(N log N) build in numpy, traversal in Warp kernels (paper §9).

The paper's CPU ray tracer follows Wald's thesis ("Realtime Ray Tracing and Interactive Global
Illumination", 2004): a kd-tree whose split planes minimise the surface area heuristic (SAH), and
a front-to-back stack traversal that stops at the first leaf whose hit lies inside it.

Build — *binned SAH, vectorised with numpy one tree level at a time* (not Wald & Havran 2006's
sorted event sweep). Why: Wald & Havran reach O(N log N) with per-node event lists that are
swept one node at a time; in Python that is millions of interpreter-level steps for a 1M-triangle
mesh. Binning evaluates every node of a level at once with a handful of whole-array numpy
operations (``bincount`` of the triangles' min/max bins, prefix sums, the SAH of every bin plane),
so each level costs O(R) vectorised work for its R triangle references and there are O(log N)
levels: O(N log N) with O(depth) Python overhead. The price is that split candidates are the
``bins - 1`` equally spaced planes over each node's geometry bounds (plus those bounds themselves),
not every triangle boundary — a slightly worse tree than an exact sweep.
Details:
- Cost = C_trav + C_isect·(SA_L·N_L + SA_R·N_R)/SA, with the *empty-space bonus*: a split with an
  empty side costs (1 − ``empty_bonus``) of that. The node's tight geometry bounds are always
  candidates, so empty space around geometry is cut off first (Wald thesis §7.3; Havran).
  A node becomes a leaf when no split is cheaper than C_isect·N or at ``max_depth``.
- Triangles that straddle a split are *clipped* to each side ("split clipping"): the bounding box
  of the triangle ∩ half-space, computed in float64 and rounded outwards to float32, intersected
  with the reference's previous box and the child's cell. Conservative, so no triangle is ever
  missing from a cell it overlaps.
- Triangles with a non-finite vertex or zero area (exactly, in float64) are left out: never hit.
- Built trees are cached on disk (``.npz``, no pickle) keyed by a hash of the vertices, faces and
  build settings, in ``$SERENITY_CACHE`` or ``~/.cache/serenity`` (``kdtree-<hash>.npz``). Builds of
  more than ``PROGRESS_MIN_TRIANGLES`` triangles show a tqdm progress bar (one step per level).

Layout (numpy at build; on a device :class:`KdTreeData`, the two node fields interleaved in one
8-byte :class:`KdNode` per node):
    node_head (nodes,) int32: inner = (first child << 2) | axis (children are consecutive: left at
        first child, right at first child + 1); leaf = (offset into ``prims`` << 2) | 3.
    node_split (nodes,) float32: the split position of an inner node (world units).
    prims (P,) int32: per leaf a count then that many triangle indices; ``prims[0] = 0`` is the
        shared empty leaf.
    tri_verts (3F,) vec3: the three vertices of triangle f at 3f, 3f+1, 3f+2.

Traversal (Warp, ``trace_kd``): rays with origin ``o`` (N,3) and direction ``d`` (N,3) float32,
t in units of |d| (directions need not be unit). Hits are 0 ≤ tmin < t < tmax. Front-to-back with
a stack of (node, t_near, t_far); near/far intervals overlap by a small tolerance (1e-6 of the scene
scale) so that rays through split planes, cell corners and box faces never skip a cell; a hit in
a leaf ends the search once it lies before the leaf's far end. Ray–triangle test: Woop, Benthin &
Wald, "Watertight Ray/Triangle Intersection" (JCGT 2013), with the edge functions evaluated in
float64 (products of float32 values are exact there), so shared edges and vertices are hit by one
of their triangles and no ray leaks through a closed mesh. Closest-hit results: ``t`` (N,) float32
(inf on a miss), ``prim`` (N,) int32 (−1), barycentrics ``u``, ``v`` (N,) float32 with
p = (1−u−v)·v0 + u·v1 + v·v2 (Embree's convention); equal t resolve to the lower triangle index
within a leaf. Any-hit (``occluded``): (N,) bool, a hit with tmin < t < tmax.
Degenerate rays — a zero, NaN or infinite direction (or a direction whose largest component is
below ~1e-30), a NaN origin, tmax ≤ tmin or NaN — are misses.

On the CPU the launches are split over all cores with :func:`serenity.kernels.launch.launch`.
"""

from __future__ import annotations

import hashlib
import math
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import warp as wp

from serenity.device import init_warp, resolve_device
from serenity.errors import SerenityError
from serenity.kernels.launch import launch

wp.set_module_options({"enable_backward": False})

# ----------------------------------------------------------------------------------------------
# constants
# ----------------------------------------------------------------------------------------------

FORMAT_VERSION = 1  # bump when the build or the cached layout changes
STACK_SIZE = 64  # traversal stack entries; max_depth is capped below it
MAX_DEPTH_CAP = STACK_SIZE - 2
CACHE_MIN_TRIANGLES = 10_000  # cache=None caches builds of at least this many triangles
PROGRESS_MIN_TRIANGLES = 200_000  # progress=None shows a bar from this many triangles
T_TOLERANCE = 1e-6  # relative (to the scene scale) overlap of near/far traversal intervals
BOX_PADDING = 1e-5  # the root box is padded by this fraction of its largest extent
TINY_DIRECTION = 1e-30  # a direction whose largest |component| is below this is a miss

_stack_i = wp.types.vector(length=STACK_SIZE, dtype=wp.int32)
_stack_f = wp.types.vector(length=STACK_SIZE, dtype=wp.float32)

_INF = wp.constant(math.inf)
_TOL = wp.constant(T_TOLERANCE)
_TINY = wp.constant(TINY_DIRECTION)
_STACK = wp.constant(STACK_SIZE)


@dataclass(frozen=True)
class KdBuildConfig:
    """Settings of the SAH build (they are part of the cache key)."""

    traversal_cost: float = 2.0
    """C_trav: cost of one inner-node step, relative units (2:1 measured best on the benchmark scene:
    shallower trees, fewer references, no slower traversal than 1:1.5)."""
    intersection_cost: float = 1.0
    """C_isect: cost of one ray–triangle test, same units."""
    empty_bonus: float = 0.8
    """Fraction of a split's cost removed when one side is empty (empty-space cut-off)."""
    min_empty_fraction: float = 0.0
    """The bonus applies only when the empty side is at least this fraction of the node's extent."""
    bins: int = 32
    """SAH bins per axis per node."""
    max_depth: int | None = None
    """Depth limit; None = 8 + 1.3·log2(N) (pbrt's rule), capped at ``MAX_DEPTH_CAP``."""

    def depth_limit(self, n: int) -> int:
        d = self.max_depth if self.max_depth is not None else int(round(8 + 1.3 * math.log2(max(n, 1))))
        return int(max(0, min(d, MAX_DEPTH_CAP)))


# ----------------------------------------------------------------------------------------------
# structs
# ----------------------------------------------------------------------------------------------


@wp.struct
class KdNode:
    """One node, 8 bytes: ``head`` = (first child << 2) | axis, or (prims offset << 2) | 3 for a
    leaf; ``split`` = the split position of an inner node."""

    head: wp.int32
    split: wp.float32


@wp.struct
class KdTreeData:
    """The tree on one device (see the module docstring for the layout)."""

    nodes: wp.array(dtype=KdNode)
    prims: wp.array(dtype=wp.int32)
    tri_verts: wp.array(dtype=wp.vec3)
    box_lo: wp.vec3  # padded root box
    box_hi: wp.vec3
    scale: float  # largest |coordinate| of the root box, for the t tolerance


# ----------------------------------------------------------------------------------------------
# functions
# ----------------------------------------------------------------------------------------------


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
    eu = wp.float64(c_x) * wp.float64(b_y) - wp.float64(c_y) * wp.float64(b_x)
    ev = wp.float64(a_x) * wp.float64(c_y) - wp.float64(a_y) * wp.float64(c_x)
    ew = wp.float64(b_x) * wp.float64(a_y) - wp.float64(b_y) * wp.float64(a_x)
    zero = wp.float64(0.0)
    hit = True
    t = float(0.0)
    u = float(0.0)
    v = float(0.0)
    if (eu < zero or ev < zero or ew < zero) and (eu > zero or ev > zero or ew > zero):
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
def trace_kd(tree: KdTreeData, o: wp.vec3, d: wp.vec3, tmin: float, tmax: float, any_hit: bool):
    """Front-to-back kd-tree traversal. Returns (prim, t, u, v); prim = −1 and t = inf on a miss.
    ``any_hit`` stops at the first hit in (tmin, tmax) (occlusion); otherwise the closest hit."""
    prim = int(-1)
    best_t = tmax
    hit_u = float(0.0)
    hit_v = float(0.0)
    kx, ky, kz, sx, sy, sz = setup_ray(d)
    tlo = wp.max(tmin, 0.0)
    t0 = tlo
    t1 = tmax
    valid = wp.isfinite(o[0]) and wp.isfinite(o[1]) and wp.isfinite(o[2])
    valid = valid and wp.isfinite(d[0]) and wp.isfinite(d[1]) and wp.isfinite(d[2])
    valid = valid and wp.abs(d[kz]) >= _TINY and wp.isfinite(sz) and t1 > t0
    inv = wp.vec3(0.0, 0.0, 0.0)  # 0 marks an axis the ray is parallel to
    if valid:
        for a in range(3):
            if d[a] != 0.0:
                r = 1.0 / d[a]
                if wp.isfinite(r):
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
    node = int(0)
    sp = int(0)
    st_node = _stack_i()
    st_t0 = _stack_f()
    st_t1 = _stack_f()
    while not done:
        nd = tree.nodes[node]
        head = nd.head
        axis = head & 3
        if axis != 3:
            split = nd.split
            child = head >> 2
            oa = o[axis]
            first = child
            second = child + 1
            if oa > split or (oa == split and d[axis] > 0.0):
                first = child + 1
                second = child
            ia = inv[axis]
            if ia == 0.0:
                # parallel to the plane: only the side of the origin, both when on the plane
                if oa == split and sp < _STACK:
                    st_node[sp] = second
                    st_t0[sp] = t0
                    st_t1[sp] = t1
                    sp += 1
                node = first
            else:
                ts = (split - oa) * ia
                if ts <= 0.0 or ts > t1 + teps:
                    node = first
                elif ts < t0 - teps:
                    node = second
                else:
                    if sp < _STACK:
                        st_node[sp] = second
                        st_t0[sp] = wp.max(t0, ts - teps)
                        st_t1[sp] = t1
                        sp += 1
                    node = first
                    t1 = wp.min(t1, ts + teps)
        else:
            off = head >> 2
            n = tree.prims[off]
            for j in range(n):
                f = tree.prims[off + 1 + j]
                hit, t, u, v = intersect_triangle(
                    o, kx, ky, kz, sx, sy, sz,
                    tree.tri_verts[3 * f], tree.tri_verts[3 * f + 1], tree.tri_verts[3 * f + 2],
                    tlo, best_t,
                )
                if hit and (t < best_t or f < prim):
                    best_t = t
                    prim = f
                    hit_u = u
                    hit_v = v
                    if any_hit:
                        break
            if prim >= 0 and (any_hit or best_t <= t1):
                done = True
            else:
                popped = int(0)
                while sp > 0 and popped == 0:
                    sp -= 1
                    node = st_node[sp]
                    t0 = st_t0[sp]
                    t1 = st_t1[sp]
                    if t0 <= best_t:
                        popped = 1
                if popped == 0:
                    done = True
    if prim < 0:
        best_t = _INF
    return prim, best_t, hit_u, hit_v


# ----------------------------------------------------------------------------------------------
# kernels
# ----------------------------------------------------------------------------------------------


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


# ----------------------------------------------------------------------------------------------
# host: build (numpy), cache, traversal
# ----------------------------------------------------------------------------------------------


@dataclass
class Hits:
    """Closest hits of N rays: ``t`` (N,) float32 (inf = miss), ``prim`` (N,) int32 (−1 = miss),
    barycentrics ``u``, ``v`` (N,) float32 (p = (1−u−v)·v0 + u·v1 + v·v2; 0 on a miss)."""

    t: np.ndarray
    prim: np.ndarray
    u: np.ndarray
    v: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        return self.prim >= 0


@dataclass
class KdStats:
    triangles: int
    valid_triangles: int
    nodes: int
    leaves: int
    empty_leaves: int
    references: int
    depth: int
    build_seconds: float
    from_cache: bool = False


def cache_dir() -> Path:
    """Where built trees are cached: ``$SERENITY_CACHE`` or ``~/.cache/serenity``."""
    env = os.environ.get("SERENITY_CACHE")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "serenity"


def geometry_key(vertices: np.ndarray, faces: np.ndarray, config: KdBuildConfig) -> str:
    """Hash of the geometry and the build settings (the cache key)."""
    h = hashlib.blake2b(digest_size=20)
    h.update(f"kdtree-v{FORMAT_VERSION}|{sorted(asdict(config).items())}|{vertices.shape}|{faces.shape}".encode())
    h.update(np.ascontiguousarray(vertices, np.float32).tobytes())
    h.update(np.ascontiguousarray(faces, np.int32).tobytes())
    return h.hexdigest()


def _validate_mesh(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(vertices)
    f = np.asarray(faces)
    if v.size == 0 or f.size == 0:
        raise SerenityError(f"cannot build a kd-tree of an empty mesh ({v.size // 3 if v.ndim else 0} vertices, "
                            f"{f.size // 3 if f.ndim else 0} triangles)")
    if v.ndim != 2 or v.shape[1] != 3:
        raise SerenityError(f"kd-tree vertices must be a (V, 3) array, got shape {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3:
        raise SerenityError(f"kd-tree faces must be an (F, 3) array, got shape {f.shape}")
    if not np.issubdtype(f.dtype, np.integer):
        raise SerenityError(f"kd-tree faces must be integer vertex indices, got {f.dtype}")
    if f.min() < 0 or f.max() >= len(v):
        raise SerenityError(f"kd-tree face indices out of range 0..{len(v) - 1}")
    return np.ascontiguousarray(v, np.float32), np.ascontiguousarray(f, np.int32)


def _round_out(lo64: np.ndarray, hi64: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float32 boxes that contain the float64 boxes."""
    lo = lo64.astype(np.float32)
    hi = hi64.astype(np.float32)
    lo = np.where(lo.astype(np.float64) > lo64, np.nextafter(lo, np.float32(-np.inf)), lo)
    hi = np.where(hi.astype(np.float64) < hi64, np.nextafter(hi, np.float32(np.inf)), hi)
    return lo, hi


def _clip_to_halfspaces(tri: np.ndarray, axis: np.ndarray, pos: np.ndarray):
    """Bounding boxes of each triangle ∩ {x_axis ≤ pos} and ∩ {x_axis ≥ pos} (float64, K×3 each;
    inf/−inf where the part is empty)."""
    nxt = [1, 2, 0]
    x = np.take_along_axis(tri, axis[:, None, None], axis=2)[:, :, 0]  # (K, 3) along the split axis
    dx = x - pos[:, None]
    dxn = dx[:, nxt]
    crosses = dx * dxn < 0.0
    s = np.where(crosses, dx / np.where(crosses, dx - dxn, 1.0), 0.0)
    q = tri + s[:, :, None] * (tri[:, nxt] - tri)  # edge ∩ plane
    np.put_along_axis(q, np.broadcast_to(axis[:, None, None], (len(tri), 3, 1)), pos[:, None, None], axis=2)
    q_lo = np.where(crosses[:, :, None], q, np.inf).min(axis=1)
    q_hi = np.where(crosses[:, :, None], q, -np.inf).max(axis=1)
    out = []
    for side in (dx <= 0.0, dx >= 0.0):
        m = side[:, :, None]
        lo = np.minimum(np.where(m, tri, np.inf).min(axis=1), q_lo)
        hi = np.maximum(np.where(m, tri, -np.inf).max(axis=1), q_hi)
        out.append((lo, hi))
    return out


def _box_area(ext: np.ndarray) -> np.ndarray:
    """Half the surface area of boxes with extents ext (..., 3)."""
    return ext[..., 0] * ext[..., 1] + ext[..., 1] * ext[..., 2] + ext[..., 2] * ext[..., 0]


def _best_splits(nb: int, n_lo, n_hi, t_lo, t_hi, counts, r_node, r_box, cfg: KdBuildConfig):
    """The cheapest SAH split of each of M nodes over ``nb`` bins per axis plus the nodes' tight
    geometry bounds (empty-space cut-offs). Nodes: cells ``n_lo``/``n_hi`` (M,3) float32, tight
    bounds ``t_lo``/``t_hi`` (M,3), ``counts`` (M,). References: ``r_node`` (R,) node of each,
    ``r_box`` (6,R) float32 rows lo x,y,z, hi x,y,z. Returns (cost (M,), axis (M,), position (M,)
    float32); cost is inf where no plane lies strictly inside the node."""
    m = len(n_lo)
    ct, ci, bonus = cfg.traversal_cost, cfg.intersection_cost, cfg.empty_bonus
    lo64 = n_lo.astype(np.float64)
    hi64 = n_hi.astype(np.float64)
    ext = hi64 - lo64
    area = _box_area(ext)
    inv_area = 1.0 / np.where(area > 0, area, 1.0)
    b_lo = np.maximum(lo64, t_lo)
    b_hi = np.minimum(hi64, t_hi)
    plane_k = np.arange(1, nb, dtype=np.float64)
    key = r_node.astype(np.int64) * nb
    rows = np.arange(m)
    best_cost = np.full(m, np.inf)
    best_axis = np.zeros(m, np.int32)
    best_pos = np.zeros(m, np.float32)
    zeros = np.zeros((m, 1), np.int64)
    cnt = counts[:, None].astype(np.int64)
    for a in range(3):
        o1, o2 = (a + 1) % 3, (a + 2) % 3
        e1, e2 = ext[:, o1:o1 + 1], ext[:, o2:o2 + 1]
        width = b_hi[:, a] - b_lo[:, a]
        inv_w = np.where(width > 0, nb / np.where(width > 0, width, 1.0), 0.0)
        base = b_lo[:, a][r_node]
        scale = inv_w[r_node]
        b0 = np.clip(((r_box[a] - base) * scale).astype(np.int64), 0, nb - 1)
        b1 = np.clip(((r_box[a + 3] - base) * scale).astype(np.int64), 0, nb - 1)
        h_start = np.bincount(key + b0, minlength=m * nb).reshape(m, nb)
        h_end = np.bincount(key + b1, minlength=m * nb).reshape(m, nb)
        # candidates: the bin planes, then the tight bounds (nothing below / nothing above)
        nl = np.concatenate([np.cumsum(h_start, axis=1)[:, :-1], zeros, cnt], axis=1)
        nr = np.concatenate([cnt - np.cumsum(h_end, axis=1)[:, :-1], cnt, zeros], axis=1)
        pos32 = np.concatenate([b_lo[:, a:a + 1] + (width / nb)[:, None] * plane_k[None, :],
                                t_lo[:, a:a + 1], t_hi[:, a:a + 1]], axis=1).astype(np.float32)
        pos = pos32.astype(np.float64)
        el = pos - lo64[:, a:a + 1]
        er = hi64[:, a:a + 1] - pos
        perim = e1 + e2
        face = e1 * e2
        cost = ct + ci * ((el * perim + face) * nl + (er * perim + face) * nr) * inv_area[:, None]
        span = ext[:, a:a + 1] * cfg.min_empty_fraction
        empty_cut = ((nl == 0) & (el >= span)) | ((nr == 0) & (er >= span))
        cost = np.where(empty_cut, cost * (1.0 - bonus), cost)
        inside = (pos32 > n_lo[:, a:a + 1]) & (pos32 < n_hi[:, a:a + 1])
        cost = np.where(inside, cost, np.inf)
        j = np.argmin(cost, axis=1)
        c = cost[rows, j]
        better = c < best_cost
        best_cost = np.where(better, c, best_cost)
        best_axis = np.where(better, a, best_axis)
        best_pos = np.where(better, pos32[rows, j], best_pos)
    return best_cost, best_axis, best_pos


def _depth_first_layout(heads: list[np.ndarray], splits: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Reorder the level-by-level (breadth-first) nodes depth-first, children pairs kept adjacent:
    a node's pair of children is followed by the left child's subtree, then the right child's, so
    the last levels of a descent touch nearby memory. Returns (node_head, node_split)."""
    head = np.concatenate(heads).astype(np.int64)
    split = np.concatenate(splits).astype(np.float32)
    n = len(head)
    inner = (head & 3) != 3
    child = np.where(inner, head >> 2, 0)
    bounds = np.cumsum([0] + [len(h) for h in heads])
    desc = np.zeros(n, np.int64)  # number of descendants
    for k in range(len(heads) - 1, -1, -1):
        x = np.arange(bounds[k], bounds[k + 1])
        x = x[inner[x]]
        desc[x] = 2 + desc[child[x]] + desc[child[x] + 1]
    pos = np.zeros(n, np.int64)
    pair = np.zeros(n, np.int64)  # new position of each inner node's children pair
    pair[0] = 1
    for k in range(len(heads)):
        x = np.arange(bounds[k], bounds[k + 1])
        x = x[inner[x]]
        left, right = child[x], child[x] + 1
        pos[left] = pair[x]
        pos[right] = pair[x] + 1
        pair[left] = pair[x] + 2
        pair[right] = pair[x] + 2 + desc[left]
    new_head = np.empty(n, np.int64)
    new_head[pos] = np.where(inner, (pair << 2) | (head & 3), head)
    new_split = np.empty(n, np.float32)
    new_split[pos] = split
    return new_head.astype(np.int32), new_split


def _clipped_boxes(tri64, r_tri, r_box, bi, ax, p32, n_lo, n_hi, r_node_s):
    """New (6,K) boxes of the straddling references ``bi`` on the left and on the right of their
    split, and whether each part is non-empty."""
    k = len(bi)
    cols = np.arange(k)
    bax = ax[bi]
    bp = p32[bi]
    nd = r_node_s[bi]
    old = r_box[:, bi]
    (ll, lh), (rl, rh) = _clip_to_halfspaces(tri64[r_tri[bi]], bax, bp.astype(np.float64))
    out = []
    for c_lo64, c_hi64, left in ((ll, lh, True), (rl, rh, False)):
        empty = ~np.isfinite(c_lo64).all(axis=1)
        c_lo, c_hi = _round_out(np.where(empty[:, None], 0.0, c_lo64), np.where(empty[:, None], 0.0, c_hi64))
        cell_lo = n_lo[nd]
        cell_hi = n_hi[nd]
        if left:
            cell_hi[cols, bax] = bp
        else:
            cell_lo[cols, bax] = bp
        box = np.empty((6, k), np.float32)
        box[:3] = np.maximum(np.maximum(old[:3], c_lo.T), cell_lo.T)
        box[3:] = np.minimum(np.minimum(old[3:], c_hi.T), cell_hi.T)
        ok = ~empty & np.all(box[:3] <= box[3:], axis=0)
        out.append((box, ok))
    return out


def _build(vertices: np.ndarray, faces: np.ndarray, cfg: KdBuildConfig, progress: bool) -> dict:
    """The binned, level-by-level SAH build. Returns the arrays of the layout plus statistics.

    Per level: every node's references are contiguous (sorted by node). References are kept as
    triangle index ``r_tri`` (R,), node ``r_node`` (R,) and box ``r_box`` (6,R) float32."""
    tri64 = vertices.astype(np.float64)[faces]  # (F, 3, 3)
    finite = np.isfinite(tri64).all(axis=(1, 2))
    cross = np.cross(tri64[:, 1] - tri64[:, 0], tri64[:, 2] - tri64[:, 0])
    valid = finite & np.any(cross != 0.0, axis=1)
    ids = np.flatnonzero(valid).astype(np.int32)
    nvalid = len(ids)
    heads: list[np.ndarray] = []
    splits: list[np.ndarray] = []
    prims: list[np.ndarray] = [np.zeros(1, np.int32)]
    prim_len = 1
    if nvalid == 0:
        return dict(node_head=np.array([3], np.int32), node_split=np.zeros(1, np.float32), prims=prims[0],
                    box=np.zeros((2, 3), np.float32),
                    stats=dict(nodes=1, leaves=1, empty_leaves=1, references=0, depth=0, valid_triangles=0))
    t32 = vertices[faces[ids]]  # (n, 3, 3)
    r_tri = ids
    r_box = np.concatenate([t32.min(axis=1).T, t32.max(axis=1).T]).astype(np.float32)
    r_node = np.zeros(nvalid, np.int32)
    n_lo = r_box[:3].min(axis=1)[None, :]
    n_hi = r_box[3:].max(axis=1)[None, :]
    root_box = np.stack([n_lo[0], n_hi[0]])
    ci, nb = cfg.intersection_cost, int(cfg.bins)
    max_depth = cfg.depth_limit(nvalid)
    n_nodes_total = 0
    leaves = empty_leaves = refs_total = 0
    depth_reached = 0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=max_depth + 1, desc=f"kd-tree ({len(faces):,} triangles)", unit="level", leave=False)
    depth = 0
    while True:
        m = len(n_lo)
        depth_reached = depth
        counts = np.bincount(r_node, minlength=m)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        nonempty = counts > 0
        t_lo = n_lo.astype(np.float64)
        t_hi = n_hi.astype(np.float64)
        if len(r_node):
            t_lo[nonempty] = np.minimum.reduceat(r_box[:3], starts[nonempty], axis=1).T
            t_hi[nonempty] = np.maximum.reduceat(r_box[3:], starts[nonempty], axis=1).T
        area = _box_area(n_hi.astype(np.float64) - n_lo.astype(np.float64))
        leaf_cost = ci * counts
        best_cost = np.full(m, np.inf)
        best_axis = np.zeros(m, np.int32)
        best_pos = np.zeros(m, np.float32)
        can_split = nonempty & (depth < max_depth) & (area > 0)
        # bins per node: enough for its references (a few refs need few planes), at most cfg.bins
        node_bins = np.clip(2 ** np.ceil(np.log2(np.maximum(counts, 1))), 4, nb).astype(np.int64)
        node_bins[~can_split] = 0
        for g in np.unique(node_bins[node_bins > 0]):
            in_g = node_bins == g
            sel = np.flatnonzero(in_g)
            ref_idx = np.flatnonzero(in_g[r_node])
            loc = np.cumsum(in_g) - 1
            cost, axis, pos = _best_splits(int(g), n_lo[sel], n_hi[sel], t_lo[sel], t_hi[sel], counts[sel],
                                           loc[r_node[ref_idx]], np.take(r_box, ref_idx, axis=1), cfg)
            best_cost[sel] = cost
            best_axis[sel] = axis
            best_pos[sel] = pos
        split = can_split & (best_cost < leaf_cost)
        is_leaf = ~split
        n_split = int(split.sum())
        # --- emit this level's nodes
        head = np.zeros(m, np.int64)
        base_next = n_nodes_total + m
        rank = np.cumsum(split) - 1
        head[split] = ((base_next + 2 * rank[split]) << 2) | best_axis[split]
        # leaves: blocks [count, prims...] appended to the prim list
        has = is_leaf & nonempty
        block = np.where(has, counts + 1, 0)
        block_start = prim_len + np.concatenate([[0], np.cumsum(block)[:-1]])
        head[is_leaf] = (np.where(has, block_start, 0)[is_leaf] << 2) | 3
        total_block = int(block.sum())
        if total_block:
            arr = np.empty(total_block, np.int32)
            arr[(block_start - prim_len)[has]] = counts[has]
            leaf_refs = np.flatnonzero(is_leaf[r_node])
            rn = r_node[leaf_refs]
            arr[block_start[rn] - prim_len + 1 + (leaf_refs - starts[rn])] = r_tri[leaf_refs]
            prims.append(arr)
            prim_len += total_block
        heads.append(head)
        splits.append(np.where(split, best_pos, 0).astype(np.float32))
        leaves += int(is_leaf.sum())
        empty_leaves += int((is_leaf & ~nonempty).sum())
        refs_total += int(counts[is_leaf].sum())
        n_nodes_total += m
        if bar is not None:
            bar.update(1)
        if n_split == 0:
            break
        # --- distribute the references of split nodes to their children
        keep = np.flatnonzero(split[r_node])
        r_tri, r_node_s, r_box = r_tri[keep], r_node[keep], np.take(r_box, keep, axis=1)
        ax = best_axis[r_node_s]
        p32 = best_pos[r_node_s]
        cols = np.arange(len(r_tri))
        lo_a = r_box[ax, cols]
        hi_a = r_box[ax + 3, cols]
        go_r = hi_a > p32
        go_l = (lo_a < p32) | ~go_r
        il = np.flatnonzero(go_l)
        ir = np.flatnonzero(go_r)
        box_l = np.take(r_box, il, axis=1)
        box_r = np.take(r_box, ir, axis=1)
        ok_l = np.ones(len(il), bool)
        ok_r = np.ones(len(ir), bool)
        bi = np.flatnonzero(go_l & go_r)
        if len(bi):
            # straddling references: clip the triangle to each side (split clipping)
            (new_l, okl), (new_r, okr) = _clipped_boxes(tri64, r_tri, r_box, bi, ax, p32, n_lo, n_hi, r_node_s)
            pl = np.searchsorted(il, bi)
            pr = np.searchsorted(ir, bi)
            box_l[:, pl] = new_l
            box_r[:, pr] = new_r
            ok_l[pl] = okl
            ok_r[pr] = okr
        il, box_l = il[ok_l], box_l[:, ok_l]
        ir, box_r = ir[ok_r], box_r[:, ok_r]
        new_node = np.concatenate([2 * rank[r_node_s[il]], 2 * rank[r_node_s[ir]] + 1]).astype(np.int32)
        order = np.argsort(new_node, kind="stable")  # two sorted runs: a linear merge
        r_node = new_node[order]
        r_tri = np.concatenate([r_tri[il], r_tri[ir]])[order]
        r_box = np.take(np.concatenate([box_l, box_r], axis=1), order, axis=1)
        # children cells
        sidx = np.flatnonzero(split)
        c_lo = np.repeat(n_lo[sidx], 2, axis=0)
        c_hi = np.repeat(n_hi[sidx], 2, axis=0)
        k = np.arange(len(sidx))
        c_hi[2 * k, best_axis[sidx]] = best_pos[sidx]
        c_lo[2 * k + 1, best_axis[sidx]] = best_pos[sidx]
        n_lo, n_hi = c_lo, c_hi
        depth += 1
    if bar is not None:
        bar.close()
    head, split_pos = _depth_first_layout(heads, splits)
    return dict(
        node_head=head,
        node_split=split_pos,
        prims=np.concatenate(prims).astype(np.int32),
        box=root_box.astype(np.float32),
        stats=dict(nodes=n_nodes_total, leaves=leaves, empty_leaves=empty_leaves, references=refs_total,
                   depth=depth_reached, valid_triangles=nvalid),
    )


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

    # -- build and cache ------------------------------------------------------------------------

    @classmethod
    def build(cls, vertices, faces, *, config: KdBuildConfig | None = None, cache: bool | None = None,
              progress: bool | None = None) -> KdTree:
        """Build (or load from the disk cache) the tree of ``vertices`` (V,3) float32 and ``faces``
        (F,3) int32. ``cache=None`` caches meshes of ≥ ``CACHE_MIN_TRIANGLES`` triangles;
        ``progress=None`` shows a bar for ≥ ``PROGRESS_MIN_TRIANGLES``. An empty mesh raises
        :class:`SerenityError`."""
        v, f = _validate_mesh(vertices, faces)
        cfg = config or KdBuildConfig()
        use_cache = len(f) >= CACHE_MIN_TRIANGLES if cache is None else bool(cache)
        show = len(f) >= PROGRESS_MIN_TRIANGLES if progress is None else bool(progress)
        path = None
        if use_cache:
            path = cache_dir() / f"kdtree-{geometry_key(v, f, cfg)}.npz"
            tree = cls._load(path, v, f)
            if tree is not None:
                return tree
        t_start = time.perf_counter()
        arrays = _build(v, f, cfg, show)
        seconds = time.perf_counter() - t_start
        s = arrays.pop("stats")
        stats = KdStats(triangles=len(f), build_seconds=seconds, **s)
        tree = cls(v, f, arrays, stats)
        if path is not None:
            tree._save(path)
        return tree

    def _save(self, path: Path) -> None:
        st = self.stats
        meta = np.array([FORMAT_VERSION, st.triangles, st.valid_triangles, st.nodes, st.leaves, st.empty_leaves,
                         st.references, st.depth], np.int64)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
            np.savez(tmp, node_head=self.node_head, node_split=self.node_split, prims=self.prims, box=self.box,
                     meta=meta, build_seconds=np.array([st.build_seconds]))
            os.replace(tmp, path)
        except OSError:
            pass  # an unwritable cache only costs a rebuild next time

    @classmethod
    def _load(cls, path: Path, v: np.ndarray, f: np.ndarray) -> KdTree | None:
        if not path.is_file():
            return None
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: np.array(z[k]) for k in ("node_head", "node_split", "prims", "box")}
                meta = z["meta"].tolist()
                secs = float(z["build_seconds"][0])
        except (OSError, ValueError, KeyError, EOFError):
            return None
        if meta[0] != FORMAT_VERSION or meta[1] != len(f) or len(arrays["node_head"]) != len(arrays["node_split"]):
            return None
        stats = KdStats(triangles=meta[1], valid_triangles=meta[2], nodes=meta[3], leaves=meta[4],
                        empty_leaves=meta[5], references=meta[6], depth=meta[7], build_seconds=secs,
                        from_cache=True)
        return cls(v, f, arrays, stats)

    # -- device data ----------------------------------------------------------------------------

    def device_data(self, device: str) -> KdTreeData:
        """The tree's Warp arrays on ``device`` (created once per device)."""
        data = self._device_data.get(device)
        if data is None:
            wp_ = init_warp()
            data = KdTreeData()
            nodes = np.zeros(len(self.node_head), dtype=KdNode.numpy_dtype())
            nodes["head"] = self.node_head
            nodes["split"] = self.node_split
            data.nodes = wp_.array(nodes, dtype=KdNode, device=device)
            data.prims = wp_.array(self.prims, dtype=wp.int32, device=device)
            tv = np.ascontiguousarray(self.vertices[self.faces].reshape(-1, 3), np.float32)
            data.tri_verts = wp_.array(tv, dtype=wp.vec3, device=device)
            lo = self.box[0].astype(np.float64)
            hi = self.box[1].astype(np.float64)
            pad = BOX_PADDING * float(np.max(hi - lo)) + 1e-30
            data.box_lo = wp.vec3(*(lo - pad).tolist())
            data.box_hi = wp.vec3(*(hi + pad).tolist())
            data.scale = float(np.max(np.abs(np.concatenate([lo - pad, hi + pad]))))
            self._device_data[device] = data
        return data

    # -- queries --------------------------------------------------------------------------------

    @staticmethod
    def _rays(origins, directions, tmax) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        o = np.ascontiguousarray(np.asarray(origins, np.float32).reshape(-1, 3))
        d = np.ascontiguousarray(np.asarray(directions, np.float32).reshape(-1, 3))
        if len(o) != len(d):
            raise SerenityError(f"{len(o)} ray origins but {len(d)} directions")
        tm = np.ascontiguousarray(np.broadcast_to(np.asarray(tmax, np.float32), (len(o),)))
        return o, d, tm

    def intersect(self, origins, directions, tmax=np.inf, device: str | None = None, *, tmin: float = 0.0,
                  threads: int | None = None) -> Hits:
        """Closest hits of rays ``origins`` (N,3), ``directions`` (N,3) with tmin < t < tmax
        (scalar or (N,)); t in units of |direction|."""
        dev = resolve_device(device)
        o, d, tm = self._rays(origins, directions, tmax)
        n = len(o)
        out_t = wp.empty(n, dtype=float, device=dev)
        out_p = wp.empty(n, dtype=wp.int32, device=dev)
        out_u = wp.empty(n, dtype=float, device=dev)
        out_v = wp.empty(n, dtype=float, device=dev)
        if n:
            args = [self.device_data(dev), wp.array(o, dtype=wp.vec3, device=dev),
                    wp.array(d, dtype=wp.vec3, device=dev), float(tmin), wp.array(tm, dtype=float, device=dev),
                    out_t, out_p, out_u, out_v]
            launch(intersect_rays, n, args, device=dev, threads=threads)
        return Hits(t=out_t.numpy(), prim=out_p.numpy(), u=out_u.numpy(), v=out_v.numpy())

    def occluded(self, origins, directions, tmax=np.inf, device: str | None = None, *, tmin: float = 0.0,
                 threads: int | None = None) -> np.ndarray:
        """(N,) bool: does anything lie on each ray with tmin < t < tmax?"""
        dev = resolve_device(device)
        o, d, tm = self._rays(origins, directions, tmax)
        n = len(o)
        out = wp.zeros(n, dtype=wp.int32, device=dev)
        if n:
            args = [self.device_data(dev), wp.array(o, dtype=wp.vec3, device=dev),
                    wp.array(d, dtype=wp.vec3, device=dev), float(tmin), wp.array(tm, dtype=float, device=dev), out]
            launch(occlude_rays, n, args, device=dev, threads=threads)
        return out.numpy().astype(bool)

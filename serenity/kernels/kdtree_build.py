"""SAH kd-tree build over a triangle mesh: binned SAH, one tree level at a time (paper §9).

The paper's CPU ray tracer follows Wald's thesis ("Realtime Ray Tracing and Interactive Global
Illumination", 2004): a kd-tree whose split planes minimise the surface area heuristic (SAH).
Traversal lives in :mod:`serenity.kernels.kdtree`; this module makes the arrays it walks.

Build — *binned SAH, level by level* (not Wald & Havran 2006's sorted event sweep, whose per-node
event lists are millions of interpreter-level steps in Python). Every level holds its nodes'
triangle references sorted by node, so each node owns a contiguous range. Per level, three Warp
kernels run with one thread per node (split over the CPU cores by
:func:`serenity.kernels.launch.launch`; a node writes only its own outputs and its own reference
range, so the result does not depend on the thread count):
    1. ``_node_splits``: the node's tight geometry bounds, per axis a histogram of its references'
       min and max bins, and the SAH cost of every bin plane and of the tight bounds;
    2. ``_clip_refs``: for a split node, each reference's side(s), the clipped boxes of the
       straddling ones, and the children's reference counts;
    3. ``_scatter_refs``: the children's references written at their prefix-sum offsets.
numpy does the O(nodes) glue (prefix sums, child cells, leaf blocks). Each level is O(R) for its R
references and there are O(log N) levels: O(N log N). The price of binning is that split candidates
are the ``bins − 1`` equally spaced planes over each node's geometry bounds (plus those bounds),
not every triangle boundary — a slightly worse tree than an exact sweep.
Details:
- Cost = C_trav + C_isect·(SA_L·N_L + SA_R·N_R)/SA, with the *empty-space bonus*: a split with an
  empty side costs (1 − ``empty_bonus``) of that. The node's tight geometry bounds are always
  candidates, so empty space around geometry is cut off first (Wald thesis §7.3; Havran).
  A node becomes a leaf when no split is cheaper than C_isect·N or at the depth limit.
- Triangles that straddle a split are *clipped* to each side ("split clipping"): the bounding box
  of the triangle ∩ half-space, computed in float64 and rounded outwards to float32, intersected
  with the reference's previous box and the child's cell. Conservative, so no triangle is ever
  missing from a cell it overlaps.
- Triangles with a non-finite vertex or zero area (exactly, in float64) are left out: never hit.
- Built trees are cached on disk (``.npz``, no pickle) keyed by a hash of the vertices, faces and
  build settings (:class:`serenity.config.KdBuildConfig`), in ``$SERENITY_CACHE`` or
  ``~/.cache/serenity`` (``kdtree-<hash>.npz``). Builds of more than ``PROGRESS_MIN_TRIANGLES``
  triangles show a tqdm progress bar (one step per level).

Layout (numpy):
    node_head (nodes,) int32: inner = (first child << 2) | axis (children are consecutive: left at
        first child, right at first child + 1); leaf = (offset into ``prims`` << 2) | 3.
        Nodes are stored depth first, each pair of children followed by the left child's subtree.
    node_split (nodes,) float32: the split position of an inner node (world units).
    prims (P,) int32: per leaf a count then that many triangle indices; ``prims[0] = 0`` is the
        shared empty leaf.
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import warp as wp
from tqdm import tqdm

from serenity.config import KdBuildConfig
from serenity.device import init_warp
from serenity.errors import SerenityError
from serenity.kernels.launch import launch

wp.set_module_options({"enable_backward": False})

FORMAT_VERSION = 2  # bump when the build or the cached layout changes
CACHE_MIN_TRIANGLES = 10_000  # cache=None caches builds of at least this many triangles
PROGRESS_MIN_TRIANGLES = 200_000  # progress=None shows a bar from this many triangles
MAX_BINS = 64  # KdBuildConfig.bins is at most this
_CHUNKS = 8  # per-node launches: chunks per CPU thread, handed out dynamically (nodes differ in cost)

_hist = wp.types.vector(length=MAX_BINS, dtype=wp.int32)
_F32_EPS = wp.constant(1.1920929e-07)  # 2^-23
_F32_TINY = wp.constant(1.0e-37)


@dataclass
class KdStats:
    """What a build made: triangle counts, node counts, references in leaves, depth and seconds."""

    triangles: int
    valid_triangles: int
    nodes: int
    leaves: int
    empty_leaves: int
    references: int
    depth: int
    build_seconds: float
    from_cache: bool = False


# ----------------------------------------------------------------------------------------------
# Warp: per-node passes of one level
# ----------------------------------------------------------------------------------------------


@wp.func
def _split_cost(pos: float, a: int, lo: wp.vec3, hi: wp.vec3, nl: int, nr: int, inv_area: float, ct: float,
                ci: float, bonus: float, min_empty: float) -> float:
    """SAH cost of the plane x_a = pos in the cell [lo, hi] with nl / nr references on each side."""
    if not (pos > lo[a] and pos < hi[a]):
        return float(math.inf)
    e1 = hi[(a + 1) % 3] - lo[(a + 1) % 3]
    e2 = hi[(a + 2) % 3] - lo[(a + 2) % 3]
    el = pos - lo[a]
    er = hi[a] - pos
    perim = e1 + e2
    face = e1 * e2
    cost = ct + ci * ((el * perim + face) * float(nl) + (er * perim + face) * float(nr)) * inv_area
    span = (hi[a] - lo[a]) * min_empty
    if (nl == 0 and el >= span) or (nr == 0 and er >= span):
        cost = cost * (1.0 - bonus)
    return cost


@wp.kernel(enable_backward=False)
def _triangle_boxes(
    # inputs
    verts: wp.array(dtype=wp.vec3),
    faces: wp.array(dtype=wp.vec3i),
    # outputs
    valid: wp.array(dtype=wp.int32),
    lo: wp.array(dtype=wp.vec3),
    hi: wp.array(dtype=wp.vec3),
    offset: int,
):
    """Triangle f's bounding box, and whether it can be hit: finite vertices, non-zero area (the
    cross product of its edges in float64, where the products of float32 values are exact)."""
    f = wp.tid() + offset
    fv = faces[f]
    p0 = verts[fv[0]]
    p1 = verts[fv[1]]
    p2 = verts[fv[2]]
    lo[f] = wp.min(wp.min(p0, p1), p2)
    hi[f] = wp.max(wp.max(p0, p1), p2)
    ok = 1
    for k in range(3):
        if not (wp.isfinite(p0[k]) and wp.isfinite(p1[k]) and wp.isfinite(p2[k])):
            ok = 0
    e1 = wp.vec3d(p1) - wp.vec3d(p0)
    e2 = wp.vec3d(p2) - wp.vec3d(p0)
    c = wp.cross(e1, e2)
    zero = wp.float64(0.0)
    if c[0] == zero and c[1] == zero and c[2] == zero:
        ok = 0
    valid[f] = ok


@wp.kernel(enable_backward=False)
def _node_splits(
    # inputs
    ref_start: wp.array(dtype=wp.int32),
    r_lo: wp.array(dtype=wp.vec3),
    r_hi: wp.array(dtype=wp.vec3),
    n_lo: wp.array(dtype=wp.vec3),
    n_hi: wp.array(dtype=wp.vec3),
    allow_split: int,
    max_bins: int,
    ct: float,
    ci: float,
    bonus: float,
    min_empty: float,
    # outputs
    out_axis: wp.array(dtype=wp.int32),
    out_pos: wp.array(dtype=float),
    offset: int,
):
    """Best split of node i: axis (−1 = leaf) and position."""
    i = wp.tid() + offset
    s = ref_start[i]
    cnt = ref_start[i + 1] - s
    out_axis[i] = -1
    out_pos[i] = 0.0
    if cnt == 0 or allow_split == 0:
        return
    lo = n_lo[i]
    hi = n_hi[i]
    ext = hi - lo
    area = ext[0] * ext[1] + ext[1] * ext[2] + ext[2] * ext[0]
    if not (area > 0.0):
        return
    inv_area = 1.0 / area
    tl = wp.vec3(float(math.inf))
    th = wp.vec3(float(-math.inf))
    for r in range(s, s + cnt):
        tl = wp.min(tl, r_lo[r])
        th = wp.max(th, r_hi[r])
    bl = wp.max(lo, tl)
    bh = wp.min(hi, th)
    nb = int(4)
    while nb < cnt and nb < max_bins:
        nb *= 2
    nb = wp.min(nb, max_bins)
    best = ci * float(cnt)  # the leaf's cost: a split must beat it
    best_axis = int(-1)
    best_pos = float(0.0)
    # one pass over the references: per axis a histogram of their min bins and one of their max bins
    hs0 = _hist()
    he0 = _hist()
    hs1 = _hist()
    he1 = _hist()
    hs2 = _hist()
    he2 = _hist()
    width = bh - bl
    scale = wp.vec3(0.0)
    for a in range(3):
        if width[a] > 0.0:
            scale[a] = float(nb) / width[a]
    top = nb - 1
    for r in range(s, s + cnt):
        q = wp.cw_mul(r_lo[r] - bl, scale)
        p = wp.cw_mul(r_hi[r] - bl, scale)
        b = wp.clamp(int(q[0]), 0, top)
        hs0[b] = hs0[b] + 1
        b = wp.clamp(int(p[0]), 0, top)
        he0[b] = he0[b] + 1
        b = wp.clamp(int(q[1]), 0, top)
        hs1[b] = hs1[b] + 1
        b = wp.clamp(int(p[1]), 0, top)
        he1[b] = he1[b] + 1
        b = wp.clamp(int(q[2]), 0, top)
        hs2[b] = hs2[b] + 1
        b = wp.clamp(int(p[2]), 0, top)
        he2[b] = he2[b] + 1
    for a in range(3):
        # the tight bounds: nothing below / nothing above
        c = _split_cost(tl[a], a, lo, hi, 0, cnt, inv_area, ct, ci, bonus, min_empty)
        if c < best:
            best = c
            best_axis = a
            best_pos = tl[a]
        c = _split_cost(th[a], a, lo, hi, cnt, 0, inv_area, ct, ci, bonus, min_empty)
        if c < best:
            best = c
            best_axis = a
            best_pos = th[a]
        if width[a] > 0.0:
            step = width[a] / float(nb)
            nl = int(0)
            ended = int(0)
            for k in range(1, nb):
                if a == 0:
                    nl += hs0[k - 1]
                    ended += he0[k - 1]
                elif a == 1:
                    nl += hs1[k - 1]
                    ended += he1[k - 1]
                else:
                    nl += hs2[k - 1]
                    ended += he2[k - 1]
                pos = bl[a] + step * float(k)
                c = _split_cost(pos, a, lo, hi, nl, cnt - ended, inv_area, ct, ci, bonus, min_empty)
                if c < best:
                    best = c
                    best_axis = a
                    best_pos = pos
    out_axis[i] = best_axis
    out_pos[i] = best_pos


@wp.func
def _round_down(x: wp.float64) -> float:
    """A float32 ≤ x (x finite)."""
    f = float(x)
    if wp.float64(f) > x:
        f = f - wp.max(wp.abs(f) * _F32_EPS, _F32_TINY)
    return f


@wp.func
def _round_up(x: wp.float64) -> float:
    """A float32 ≥ x (x finite)."""
    f = float(x)
    if wp.float64(f) < x:
        f = f + wp.max(wp.abs(f) * _F32_EPS, _F32_TINY)
    return f


@wp.kernel(enable_backward=False)
def _clip_refs(
    # inputs
    ref_start: wp.array(dtype=wp.int32),
    r_tri: wp.array(dtype=wp.int32),
    r_lo: wp.array(dtype=wp.vec3),
    r_hi: wp.array(dtype=wp.vec3),
    n_lo: wp.array(dtype=wp.vec3),
    n_hi: wp.array(dtype=wp.vec3),
    split_axis: wp.array(dtype=wp.int32),
    split_pos: wp.array(dtype=float),
    verts: wp.array(dtype=wp.vec3),
    faces: wp.array(dtype=wp.vec3i),
    # outputs
    side: wp.array(dtype=wp.int32),
    l_lo: wp.array(dtype=wp.vec3),
    l_hi: wp.array(dtype=wp.vec3),
    r_lo_out: wp.array(dtype=wp.vec3),
    r_hi_out: wp.array(dtype=wp.vec3),
    count_l: wp.array(dtype=wp.int32),
    count_r: wp.array(dtype=wp.int32),
    offset: int,
):
    """For each reference of split node i: ``side`` bit 0 = goes left, bit 1 = goes right, and its
    box on each side (clipped where it straddles the plane); the children's counts."""
    i = wp.tid() + offset
    a = split_axis[i]
    count_l[i] = 0
    count_r[i] = 0
    if a < 0:
        return
    p = split_pos[i]
    p64 = wp.float64(p)
    s = ref_start[i]
    e = ref_start[i + 1]
    cell_lo = n_lo[i]
    cell_hi = n_hi[i]
    nl = int(0)
    nr = int(0)
    for r in range(s, e):
        blo = r_lo[r]
        bhi = r_hi[r]
        go_r = bhi[a] > p
        go_l = blo[a] < p or not go_r
        flag = int(0)
        if go_l and go_r:
            fv = faces[r_tri[r]]
            q0 = wp.vec3d(verts[fv[0]])
            q1 = wp.vec3d(verts[fv[1]])
            q2 = wp.vec3d(verts[fv[2]])
            inf64 = wp.float64(math.inf)
            llo = wp.vec3d(inf64, inf64, inf64)
            lhi = wp.vec3d(-inf64, -inf64, -inf64)
            rlo = wp.vec3d(inf64, inf64, inf64)
            rhi = wp.vec3d(-inf64, -inf64, -inf64)
            for j in range(3):
                qa = q0
                qb = q1
                if j == 1:
                    qa = q1
                    qb = q2
                elif j == 2:
                    qa = q2
                    qb = q0
                da = qa[a] - p64
                db = qb[a] - p64
                if da <= wp.float64(0.0):
                    llo = wp.min(llo, qa)
                    lhi = wp.max(lhi, qa)
                if da >= wp.float64(0.0):
                    rlo = wp.min(rlo, qa)
                    rhi = wp.max(rhi, qa)
                if da * db < wp.float64(0.0):
                    q = qa + (da / (da - db)) * (qb - qa)  # edge ∩ plane
                    q[a] = p64
                    llo = wp.min(llo, q)
                    lhi = wp.max(lhi, q)
                    rlo = wp.min(rlo, q)
                    rhi = wp.max(rhi, q)
            # left part: previous box ∩ clipped box ∩ left cell
            if llo[0] <= lhi[0]:
                nlo = wp.vec3(_round_down(llo[0]), _round_down(llo[1]), _round_down(llo[2]))
                nhi = wp.vec3(_round_up(lhi[0]), _round_up(lhi[1]), _round_up(lhi[2]))
                chi = wp.vec3(cell_hi[0], cell_hi[1], cell_hi[2])
                chi[a] = p
                nlo = wp.max(wp.max(nlo, blo), cell_lo)
                nhi = wp.min(wp.min(nhi, bhi), chi)
                if nlo[0] <= nhi[0] and nlo[1] <= nhi[1] and nlo[2] <= nhi[2]:
                    flag = flag | 1
                    l_lo[r] = nlo
                    l_hi[r] = nhi
            if rlo[0] <= rhi[0]:
                nlo = wp.vec3(_round_down(rlo[0]), _round_down(rlo[1]), _round_down(rlo[2]))
                nhi = wp.vec3(_round_up(rhi[0]), _round_up(rhi[1]), _round_up(rhi[2]))
                clo = wp.vec3(cell_lo[0], cell_lo[1], cell_lo[2])
                clo[a] = p
                nlo = wp.max(wp.max(nlo, blo), clo)
                nhi = wp.min(wp.min(nhi, bhi), cell_hi)
                if nlo[0] <= nhi[0] and nlo[1] <= nhi[1] and nlo[2] <= nhi[2]:
                    flag = flag | 2
                    r_lo_out[r] = nlo
                    r_hi_out[r] = nhi
        elif go_l:
            flag = 1
            l_lo[r] = blo
            l_hi[r] = bhi
        else:
            flag = 2
            r_lo_out[r] = blo
            r_hi_out[r] = bhi
        side[r] = flag
        if flag & 1:
            nl += 1
        if flag & 2:
            nr += 1
    count_l[i] = nl
    count_r[i] = nr


@wp.kernel(enable_backward=False)
def _scatter_refs(
    # inputs
    ref_start: wp.array(dtype=wp.int32),
    r_tri: wp.array(dtype=wp.int32),
    side: wp.array(dtype=wp.int32),
    l_lo: wp.array(dtype=wp.vec3),
    l_hi: wp.array(dtype=wp.vec3),
    r_lo: wp.array(dtype=wp.vec3),
    r_hi: wp.array(dtype=wp.vec3),
    split_axis: wp.array(dtype=wp.int32),
    first_l: wp.array(dtype=wp.int32),
    first_r: wp.array(dtype=wp.int32),
    # outputs
    new_tri: wp.array(dtype=wp.int32),
    new_lo: wp.array(dtype=wp.vec3),
    new_hi: wp.array(dtype=wp.vec3),
    offset: int,
):
    """The references of split node i, in order, into its left child's range then its right one's."""
    i = wp.tid() + offset
    if split_axis[i] < 0:
        return
    jl = first_l[i]
    jr = first_r[i]
    for r in range(ref_start[i], ref_start[i + 1]):
        flag = side[r]
        if flag & 1:
            new_tri[jl] = r_tri[r]
            new_lo[jl] = l_lo[r]
            new_hi[jl] = l_hi[r]
            jl += 1
        if flag & 2:
            new_tri[jr] = r_tri[r]
            new_lo[jr] = r_lo[r]
            new_hi[jr] = r_hi[r]
            jr += 1


@wp.kernel(enable_backward=False)
def _emit_leaves(
    # inputs
    ref_start: wp.array(dtype=wp.int32),
    r_tri: wp.array(dtype=wp.int32),
    split_axis: wp.array(dtype=wp.int32),
    block_start: wp.array(dtype=wp.int32),
    # outputs
    prims: wp.array(dtype=wp.int32),
    offset: int,
):
    """Leaf i's block in ``prims``: its reference count, then its triangles."""
    i = wp.tid() + offset
    s = ref_start[i]
    n = ref_start[i + 1] - s
    if split_axis[i] >= 0 or n == 0:
        return
    j = block_start[i]
    prims[j] = n
    for k in range(n):
        prims[j + 1 + k] = r_tri[s + k]


# ----------------------------------------------------------------------------------------------
# host: the level loop
# ----------------------------------------------------------------------------------------------


class _Scratch:
    """Warp arrays on the CPU reused from level to level (fresh memory costs page faults): ``get``
    returns the first n elements of a buffer of at least n, grown by half when too small."""

    def __init__(self, wp_):
        self.wp = wp_
        self.arrays: dict[str, object] = {}

    def get(self, name: str, n: int, dtype):
        arr = self.arrays.get(name)
        n = max(int(n), 1)
        if arr is None or arr.shape[0] < n:
            arr = self.wp.empty(n + n // 2, dtype=dtype, device="cpu")
            self.arrays[name] = arr
        return arr[:n]

    def put(self, name: str, values: np.ndarray, dtype):
        arr = self.get(name, len(values), dtype)
        if len(values):
            arr.numpy()[:len(values)] = values
        return arr


def build_arrays(vertices: np.ndarray, faces: np.ndarray, cfg: KdBuildConfig, progress: bool,
                 threads: int | None = None) -> dict:
    """The binned, level-by-level SAH build of ``vertices`` (V,3) float32 and ``faces`` (F,3) int32
    (validated). Returns ``node_head``, ``node_split``, ``prims``, ``box`` (2,3) (the geometry's
    bounds) and ``stats`` (a dict of :class:`KdStats` fields without times). ``threads``: CPU
    threads of the per-node kernels (None: all)."""
    wp_ = init_warp()
    dev = "cpu"

    def run(kernel, dim: int, inputs: list) -> None:
        launch(kernel, dim, inputs, device=dev, threads=threads, chunks_per_thread=_CHUNKS)

    w_verts = wp_.array(vertices, dtype=wp.vec3, device=dev)
    w_faces = wp_.array(faces, dtype=wp.vec3i, device=dev)
    nf = len(faces)
    valid_w = wp_.empty(nf, dtype=wp.int32, device=dev)
    lo_w = wp_.empty(nf, dtype=wp.vec3, device=dev)
    hi_w = wp_.empty(nf, dtype=wp.vec3, device=dev)
    run(_triangle_boxes, nf, [w_verts, w_faces, valid_w, lo_w, hi_w])
    ids = np.flatnonzero(valid_w.numpy()).astype(np.int32)
    nvalid = len(ids)
    if nvalid == 0:
        return dict(node_head=np.array([3], np.int32), node_split=np.zeros(1, np.float32),
                    prims=np.zeros(1, np.int32), box=np.zeros((2, 3), np.float32),
                    stats=dict(nodes=1, leaves=1, empty_leaves=1, references=0, depth=0, valid_triangles=0))
    scratch = _Scratch(wp_)
    buf = [("tri_a", "lo_a", "hi_a"), ("tri_b", "lo_b", "hi_b")]  # ping-pong reference buffers
    lo0, hi0 = lo_w.numpy()[ids], hi_w.numpy()[ids]
    root_box = np.stack([lo0.min(axis=0), hi0.max(axis=0)])
    r_tri = scratch.put("tri_a", ids, wp.int32)
    r_lo = scratch.put("lo_a", lo0, wp.vec3)
    r_hi = scratch.put("hi_a", hi0, wp.vec3)
    del lo0, hi0, valid_w, lo_w, hi_w
    ref_start = np.array([0, nvalid], np.int32)
    n_lo, n_hi = root_box[:1].copy(), root_box[1:].copy()
    ct, ci = float(cfg.traversal_cost), float(cfg.intersection_cost)
    max_depth = cfg.depth_limit(nvalid)
    heads: list[np.ndarray] = []
    splits: list[np.ndarray] = []
    prims: list[np.ndarray] = [np.zeros(1, np.int32)]
    prim_len = 1
    n_nodes_total = leaves = empty_leaves = refs_total = 0
    bar = None
    if progress:
        bar = tqdm(total=max_depth + 1, desc=f"kd-tree ({nf:,} triangles)", unit="level", leave=False)
    depth = 0
    while True:
        m = len(n_lo)
        n_ref = int(ref_start[-1])
        counts = np.diff(ref_start)
        w_start = scratch.put("start", ref_start, wp.int32)
        w_nlo = scratch.put("n_lo", n_lo, wp.vec3)
        w_nhi = scratch.put("n_hi", n_hi, wp.vec3)
        w_axis = scratch.get("axis", m, wp.int32)
        w_pos = scratch.get("pos", m, float)
        run(_node_splits, m, [w_start, r_lo, r_hi, w_nlo, w_nhi, int(depth < max_depth), int(cfg.bins), ct, ci,
                                 float(cfg.empty_bonus), float(cfg.min_empty_fraction), w_axis, w_pos])
        best_axis = w_axis.numpy()[:m].copy()
        best_pos = w_pos.numpy()[:m].copy()
        split = best_axis >= 0
        is_leaf = ~split
        n_split = int(split.sum())
        # --- emit this level's nodes
        head = np.zeros(m, np.int64)
        base_next = n_nodes_total + m
        rank = np.cumsum(split) - 1
        head[split] = ((base_next + 2 * rank[split]) << 2) | best_axis[split]
        # leaves: blocks [count, prims...] appended to the prim list
        has = is_leaf & (counts > 0)
        block = np.where(has, counts + 1, 0)
        block_start = prim_len + np.concatenate([[0], np.cumsum(block)[:-1]])
        head[is_leaf] = (np.where(has, block_start, 0)[is_leaf] << 2) | 3
        total_block = int(block.sum())
        if total_block:
            arr = wp_.empty(total_block, dtype=wp.int32, device=dev)
            run(_emit_leaves, m, [w_start, r_tri, w_axis,
                                     scratch.put("block", (block_start - prim_len).astype(np.int32), wp.int32), arr])
            prims.append(arr.numpy())
            prim_len += total_block
        heads.append(head)
        splits.append(np.where(split, best_pos, 0).astype(np.float32))
        leaves += int(is_leaf.sum())
        empty_leaves += int((is_leaf & (counts == 0)).sum())
        refs_total += int(counts[is_leaf].sum())
        n_nodes_total += m
        if bar is not None:
            bar.update(1)
        if n_split == 0:
            break
        # --- distribute the references of split nodes to their children
        side = scratch.get("side", n_ref, wp.int32)
        l_lo, l_hi = scratch.get("l_lo", n_ref, wp.vec3), scratch.get("l_hi", n_ref, wp.vec3)
        q_lo, q_hi = scratch.get("q_lo", n_ref, wp.vec3), scratch.get("q_hi", n_ref, wp.vec3)
        c_l, c_r = scratch.get("c_l", m, wp.int32), scratch.get("c_r", m, wp.int32)
        run(_clip_refs, m, [w_start, r_tri, r_lo, r_hi, w_nlo, w_nhi, w_axis, w_pos, w_verts, w_faces,
                               side, l_lo, l_hi, q_lo, q_hi, c_l, c_r])
        cl, cr = c_l.numpy()[:m].astype(np.int64), c_r.numpy()[:m].astype(np.int64)
        pair = cl + cr
        first_l = np.concatenate([[0], np.cumsum(pair)[:-1]])
        first_r = first_l + cl
        n_new = int(pair.sum())
        names = buf[(depth + 1) % 2]
        new_tri = scratch.get(names[0], n_new, wp.int32)
        new_lo = scratch.get(names[1], n_new, wp.vec3)
        new_hi = scratch.get(names[2], n_new, wp.vec3)
        run(_scatter_refs, m, [w_start, r_tri, side, l_lo, l_hi, q_lo, q_hi, w_axis,
                                  scratch.put("first_l", first_l.astype(np.int32), wp.int32),
                                  scratch.put("first_r", first_r.astype(np.int32), wp.int32),
                                  new_tri, new_lo, new_hi])
        r_tri, r_lo, r_hi = new_tri, new_lo, new_hi
        sidx = np.flatnonzero(split)
        child_counts = np.stack([cl[sidx], cr[sidx]], axis=1).reshape(-1)
        ref_start = np.concatenate([[0], np.cumsum(child_counts)]).astype(np.int32)
        # children cells
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
                   depth=depth, valid_triangles=nvalid),
    )


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


# ----------------------------------------------------------------------------------------------
# host: validation and the disk cache
# ----------------------------------------------------------------------------------------------


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


def validate_mesh(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    """``vertices`` (V,3) float32 and ``faces`` (F,3) int32, contiguous; a clear error otherwise."""
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


_ARRAYS = ("node_head", "node_split", "prims", "box")


def save_tree(path: Path, arrays: dict, stats: KdStats) -> None:
    """Write a built tree to ``path`` (an ``.npz`` of plain arrays); an unwritable cache is ignored."""
    meta = np.array([FORMAT_VERSION, stats.triangles, stats.valid_triangles, stats.nodes, stats.leaves,
                     stats.empty_leaves, stats.references, stats.depth], np.int64)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
        np.savez(tmp, **{k: arrays[k] for k in _ARRAYS}, meta=meta, build_seconds=np.array([stats.build_seconds]))
        os.replace(tmp, path)
    except OSError:
        pass  # an unwritable cache only costs a rebuild next time


def load_tree(path: Path, n_faces: int) -> tuple[dict, KdStats] | None:
    """The arrays and stats cached at ``path``, or None when absent, unreadable or stale."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: np.array(z[k]) for k in _ARRAYS}
            meta = z["meta"].tolist()
            secs = float(z["build_seconds"][0])
    except (OSError, ValueError, KeyError, EOFError, IndexError):
        return None
    if len(meta) != 8 or meta[0] != FORMAT_VERSION or meta[1] != n_faces \
            or len(arrays["node_head"]) != len(arrays["node_split"]):
        return None
    stats = KdStats(triangles=meta[1], valid_triangles=meta[2], nodes=meta[3], leaves=meta[4],
                    empty_leaves=meta[5], references=meta[6], depth=meta[7], build_seconds=secs, from_cache=True)
    return arrays, stats

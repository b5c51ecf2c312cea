"""Warp kernels of the kd-tree build: the per-node passes of one level (paper §9).

:mod:`serenity.kernels.kdtree_build` runs them once per tree level, one thread per node (a node
reads and writes only its own entries and its own contiguous range of references, so the results
do not depend on how the nodes are split over threads). Shapes, per level of M nodes and R
references sorted by node:
    ref_start (M+1,) int32: node i's references are [ref_start[i], ref_start[i+1]);
    r_tri (R,) int32 triangle of each reference; r_lo, r_hi (R,) vec3 its box (world units);
    n_lo, n_hi (M,) vec3 the nodes' cells; split_axis (M,) int32 (−1 = leaf), split_pos (M,) float32.
"""

from __future__ import annotations

import math

import warp as wp

wp.set_module_options({"enable_backward": False})

MAX_BINS = 64  # KdBuildConfig.bins is at most this

_hist = wp.types.vector(length=MAX_BINS, dtype=wp.int32)
_F32_EPS = wp.constant(1.1920929e-07)  # 2^-23
_F32_TINY = wp.constant(1.0e-37)


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
def triangle_boxes(
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
def node_splits(
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
def clip_refs(
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
def scatter_refs(
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
def emit_leaves(
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

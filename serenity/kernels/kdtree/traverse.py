"""One-ray kd-tree traversal (paper §9): front to back with a stack, one ray per kernel thread.
The whole traversal on CUDA, where a batch's parallelism is its threads; on the CPU the kernel for
batches that are neither coherent nor reordered (``query``), and the reference every other path
matches bit for bit.

Rays: origins ``o`` and directions ``d`` (vec3 float32), t in units of |d| (directions need not be
unit), hits with tmin < t < tmax. Degenerate rays (a zero, NaN or infinite direction, a NaN origin,
tmax ≤ tmin or NaN) are misses. Results: the triangle index (−1 on a miss), t (inf on a miss) and
the barycentrics u, v with p = (1−u−v)·v0 + u·v1 + v·v2 (Embree's convention); equal t resolve to
the lower triangle index.
"""

from __future__ import annotations

import warp as wp

from .layout import (
    INF,
    STACK_MASK,
    TINY,
    TOL,
    TRACE_MODULE_OPTIONS,
    KdTreeData,
    finite,
    node_head,
    node_split,
    stack_f,
    stack_i,
)
from .triangle import intersect_leaf, setup_ray

wp.set_module_options(TRACE_MODULE_OPTIONS)


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
    valid = valid and wp.abs(d[kz]) >= TINY and finite(sz) and t1 > t0
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
    teps = TOL * (tree.scale + ao) * wp.abs(sz)
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
    st_node = stack_i()
    st_t0 = stack_f()
    st_t1 = stack_f()
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
                    k = sp & STACK_MASK  # not negative: no index wrap
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
                        k = sp & STACK_MASK
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
                    k = sp & STACK_MASK
                    node = st_node[k]
                    t0 = st_t0[k]
                    t1 = st_t1[k]
                    if t0 <= best_t:
                        popped = 1
                if popped == 0:
                    done = True
    if prim < 0:
        best_t = INF
    return prim, best_t, hit_u, hit_v


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
    """Closest hits, one ray per kernel thread: ray i's triangle (−1: a miss), t (inf), u, v."""
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
    """Any hit, one ray per kernel thread: 1 where something lies on ray i within (tmin, tmax[i])."""
    i = wp.tid() + offset
    prim, t, u, v = trace_kd(tree, origins[i], directions[i], tmin, tmax[i], True)
    occluded[i] = wp.where(prim >= 0, 1, 0)

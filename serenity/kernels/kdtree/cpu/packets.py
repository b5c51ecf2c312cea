"""Packets (docs/kdtree.md, "Packets"): the CPU's traversal of batches in a coherent order (camera
rays, reflections of a smooth surface in pixel order, and every reordered batch). A kernel thread
traces ``PACKET_LANES`` rays through the tree as one packet, the lanes' node steps as SIMD
(``packets.h``), each lane with its own interval, best hit and entries on the packet's stack, so that
every ray visits the nodes and triangles the one-ray traversal (``traverse.trace_kd``) visits, in its
order: the same hits, bit for bit. CPU only: the natives are a ``__trap()`` on CUDA, where the
queries trace one ray per kernel thread.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import warp as wp

from serenity.kernels.factory import kernel_factory

from ..layout import (
    FLT_MAX,
    INF,
    STACK_MASK,
    STACK_SIZE,
    T_TOLERANCE,
    TINY_DIRECTION,
    KdTreeData,
    node_head,
    node_split,
)
from ..native import native_body

HEADER = Path(__file__).with_name("packets.h")

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
assert PACKET_WORKSPACE % 16 == 0

assert PACKET_LANES == 16  # packet_setup's loads (``lanes16.h``)

#: the C natives' constants (``packets.h``)
_C = {"PK_LANES": PACKET_LANES, "PK_O": _PK_O, "PK_IA": _PK_IA, "PK_TE": _PK_TE, "PK_T0": _PK_T0, "PK_T1": _PK_T1,
      "PK_BT": _PK_BT, "PK_S0": _PK_S0, "PK_S1": _PK_S1, "PK_KX": _PK_KX, "PK_SX": _PK_SX, "PK_OCT": _PK_OCT,
      "PK_HIT": _PK_HIT, "PK_STACK": _PK_STACK, "FLT_MAX_F": FLT_MAX,
      "T_TOLERANCE_F": float(np.float32(T_TOLERANCE)), "TINY_F": float(np.float32(TINY_DIRECTION))}


def _native(name: str) -> str:
    return native_body(HEADER, name, cpu_only=True, defines=_C)


@wp.func_native(_native("packet_step"))
def packet_step(s: wp.array(dtype=float), base: int, axis: int, split: float, a_side: int, level: int) -> wp.int64:
    """One inner node's step for a packet's lanes (workspace ``s`` from ``base``): each lane's
    step of the one-ray traversal on the node's ``axis`` and ``split``, the packet's first child being
    the left one (``a_side`` 0) or the right one (1). Writes the second child's intervals (t0, t1) at
    stack ``level`` and the first child's t1 as the lanes' current one; returns three lane masks,
    bits 0, 20 and 40 on: the lanes whose next node is the first child, those that go to the second
    child (next or pushed), and those whose best hit lies within their next node's interval (t ≤ t1)."""
    ...


@wp.func_native(_native("packet_pop"))
def packet_pop(s: wp.array(dtype=float), base: int, level: int) -> int:
    """The lanes' intervals of stack ``level`` made current; returns the mask of lanes whose entry
    still lies before their best hit (t0 ≤ best t: the one-ray traversal's pop test)."""
    ...


@wp.func_native(_native("lowest_lane"))
def lowest_lane(x: int) -> int:
    """The index of the lowest set bit of a non-zero lane mask."""
    ...


@wp.func_native(_native("packet_setup"))
def packet_setup(lo: wp.vec3, hi: wp.vec3, scale: float, origins: wp.array(dtype=wp.vec3),
                 directions: wp.array(dtype=wp.vec3), tmax: wp.array(dtype=float), tmin_: float, first: int,
                 count: int, s: wp.array(dtype=float), base: int) -> wp.int64:
    """The one-ray traversal's ``start_ray`` for a packet's ``count`` rays from ``first`` on
    (contiguous arrays), the rays as SIMD lanes: the same float32 operations lane by lane (tests: the
    packets' hits are the one-ray traversal's bit for bit). Writes each lane's origin, inverse
    direction (+-inf where parallel, see the kernel), tolerance, tmax as its best t, interval at the
    root box, Woop's axes and shears and octant into the workspace ``s`` from ``base``; returns the
    mask of the lanes with something to trace (bits 0 …) and, from bit 20, the octants among them
    (a bit per octant)."""
    ...


@wp.func_native(_native("packet_octant"))
def packet_octant(s: wp.array(dtype=float), base: int, oc: int) -> int:
    """Start the trace of octant ``oc``'s lanes: every lane's interval reset to the root box's
    (:func:`packet_setup`); returns the mask of the lanes whose octant is ``oc``."""
    ...


@wp.func_native(_native("leaf_simd"))
def leaf_simd(refs: wp.array(dtype=float), first: int, k: int, o: wp.vec3, kx: int, ky: int, kz: int, sx: float,
              sy: float, sz: float, tlo: float, best_t: float, prim: int, any_hit: int, s: wp.array(dtype=float),
              base: int) -> int:
    """``triangle.intersect_leaf`` for one ray, 8 triangles at a time as SIMD lanes (``leaf8.h``, the
    leaf's block at word ``first`` of ``refs``, ``k`` triangles): Woop's test in the same float32 and
    float64 operations per triangle, then the hits in the triangles' order under intersect_leaf's rule
    (closer, or as close with a lower index; the first one for ``any_hit``), so the same triangle, t,
    u and v (``triangle.leaf_pick`` for the one-ray traversal, which takes the winner's t, u, v from
    its own test instead: slower for packets, whose lanes have their workspace). Returns the best
    triangle after the leaf (``prim`` if none beat it) and, when one did, writes its t, u, v at the
    packet workspace's ``_PK_HIT``."""
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
                        m = packet_step(workspace, base, axis, node_split(tree.nodes, node), a_side, sp & STACK_MASK)
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
                            k = sp & STACK_MASK
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
                            k = sp & STACK_MASK
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
                    hit_t[i] = wp.where(prim[r] >= 0, workspace[base + _PK_BT + r], INF)
                    hit_u[i] = hu[r]
                    hit_v[i] = hv[r]

    return trace_packets

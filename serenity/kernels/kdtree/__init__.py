"""The kd-tree: traversal in Warp kernels and the host class that builds, caches and queries a tree
(paper §9).

:class:`KdTree` takes a scene's triangles (vertices (V,3) and faces (F,3)), builds or loads its SAH
kd-tree (:mod:`serenity.kernels.kdtree_build`, settings :class:`serenity.config.KdBuildConfig`) and
answers two queries on a device:

- :meth:`KdTree.intersect`: closest hits of rays with origins ``o`` (N,3) and directions ``d``
  (N,3) float32, t in units of |d| (directions need not be unit), hits with tmin < t < tmax:
  :class:`Hits` of ``t`` (N,) float32 (inf on a miss), ``prim`` (N,) int32 (−1), barycentrics
  ``u``, ``v`` (N,) float32 with p = (1−u−v)·v0 + u·v1 + v·v2 (Embree's convention); equal t
  resolve to the lower triangle index.
- :meth:`KdTree.occluded`: any hit, (N,) bool.

Both take numpy rays (and give numpy results) or Warp arrays on the query's device: origins and
directions (N,) ``wp.vec3``, tmax a scalar or (N,) float32; then the results are Warp arrays there
(``Hits`` of four arrays, or (N,) int32 occlusion flags) and neither the rays nor the hits are copied
to or from the host, but for the alpha test of cut-outs, which runs on the host.

Degenerate rays (a zero, NaN or infinite direction, a NaN origin, tmax ≤ tmin or NaN) are misses.
Every path — one ray per kernel thread (CUDA, small batches), 16-ray packets, reordered or not, any
thread count, CPU or CUDA — returns the same hits bit for bit (tests); the tracing kernels are
compiled without FMA contraction (``TRACE_MODULE_OPTIONS``) so that CUDA's hits equal the CPU's.

The package, along its seams (each native's C in a ``.h`` file beside the Python that loads it,
``native``):

- ``layout``: the tree on a device (:class:`KdTreeData`: 8-byte nodes, leaf blocks of vertex
  coordinates), its loads (``layout.h``), the shared constants and workspace buffers;
- ``triangle``: Woop's watertight ray–triangle test and a leaf's triangles under one rule (``leaf8.h``:
  the same test 8 triangles at a time on the CPU);
- ``traverse``: the one-ray traversal (:func:`trace_kd`) and its kernels, all that CUDA runs;
- ``keys``: the rays' reordering keys; ``reorder``: the order (a radix sort on CUDA, the counting
  sort on the CPU), the gather of rays into it and the scatter of results back;
- ``cpu/``: the CPU-only kernels: ``packets`` (16-ray packets) and ``sort`` (SIMD keys, counting
  sort, prefetching gather and scatter); their natives trap on CUDA;
- ``query``: which kernels a batch goes through per device and batch kind, and their launch;
- ``tree``: :class:`KdTree`.

How the traversal, the ray reordering, the packets and the threading work, why each is the way it
is, and their figures: docs/kdtree.md.
"""

from serenity.config import KdBuildConfig
from serenity.kernels.kdtree_build import CACHE_MIN_TRIANGLES, PROGRESS_MIN_TRIANGLES, KdStats
from serenity.scene.cache import cache_dir

from .cpu.packets import (
    PACKET_LANES,
    PACKET_MIN_RAYS,
    PACKET_WORKSPACE,
    leaf_simd,
    lowest_lane,
    packet_octant,
    packet_pop,
    packet_setup,
    packet_step,
    trace_packets_kernel,
)
from .cpu.sort import (
    GATHER_PREFETCH,
    KEY_LANES,
    REORDER_BLOCK,
    SCATTER_PREFETCH,
    SORT_MIN_KEYS_PER_THREAD,
    SORT_PREFETCH,
    counting_order,
    keys_simd,
    move_in_order,
    move_range,
    scatter_hits,
    sort_keys_simd,
)
from .keys import (
    SORT_COARSE_BITS,
    SORT_DIGIT_BITS,
    SORT_DIRECTION_BITS,
    SORT_KEY_BITS,
    SORT_MIN_RAYS,
    SORT_MIN_RUN,
    SORT_ORIGIN_BITS,
    SORT_SAMPLE_PAIRS,
    origin_cell,
    ray_sort_key,
    sample_key_changes,
    sort_keys,
    sort_scale,
    spread_bits,
    spread_bits2,
)
from .layout import (
    BOX_PADDING,
    MAX_CUTOUT_LAYERS,
    REF_PAD,
    STACK_SIZE,
    T_TOLERANCE,
    TINY_DIRECTION,
    TRACE_MODULE_OPTIONS,
    KdNode,
    KdTreeData,
    buffers_like,
    finite,
    node_head,
    node_split,
    ref_prim,
    ref_vertex,
    tree_data,
    workspace_buffer,
)
from .query import BATCH_KINDS, TRAVERSAL, Hits, hit_outputs, launch_query, plan_query
from .reorder import (
    batch_is_coherent,
    gather_array,
    gather_in_order,
    ray_order,
    scatter_array,
    scatter_in_order,
)
from .traverse import intersect_rays, occlude_rays, start_ray, trace_kd
from .tree import KdTree
from .triangle import intersect_leaf, intersect_triangle, intersect_triangle_fixed, leaf_pick, setup_ray

__all__ = ["BATCH_KINDS", "BOX_PADDING", "CACHE_MIN_TRIANGLES", "GATHER_PREFETCH", "KEY_LANES", "MAX_CUTOUT_LAYERS",
           "PACKET_LANES", "PACKET_MIN_RAYS", "PACKET_WORKSPACE", "PROGRESS_MIN_TRIANGLES", "REF_PAD",
           "REORDER_BLOCK", "SCATTER_PREFETCH", "SORT_COARSE_BITS", "SORT_DIGIT_BITS", "SORT_DIRECTION_BITS",
           "SORT_KEY_BITS", "SORT_MIN_KEYS_PER_THREAD", "SORT_MIN_RAYS", "SORT_MIN_RUN", "SORT_ORIGIN_BITS",
           "SORT_PREFETCH", "SORT_SAMPLE_PAIRS", "STACK_SIZE", "TINY_DIRECTION", "TRACE_MODULE_OPTIONS",
           "TRAVERSAL", "T_TOLERANCE", "Hits", "KdBuildConfig", "KdNode", "KdStats", "KdTree", "KdTreeData",
           "batch_is_coherent", "buffers_like", "cache_dir", "counting_order", "finite", "gather_array",
           "gather_in_order", "hit_outputs", "intersect_leaf", "intersect_rays", "intersect_triangle",
           "intersect_triangle_fixed", "keys_simd", "launch_query", "leaf_pick", "leaf_simd", "lowest_lane",
           "move_in_order", "move_range", "node_head", "node_split", "occlude_rays", "origin_cell",
           "packet_octant", "packet_pop", "packet_setup", "packet_step", "plan_query", "ray_order",
           "ray_sort_key", "ref_prim", "ref_vertex", "sample_key_changes", "scatter_array", "scatter_hits",
           "scatter_in_order", "setup_ray", "sort_keys", "sort_keys_simd", "sort_scale", "spread_bits",
           "spread_bits2", "start_ray", "trace_kd", "trace_packets_kernel", "tree_data", "workspace_buffer"]

"""Two-level ray tracing: a static :class:`serenity.kernels.kdtree.KdTree` and the moving objects of a
:class:`serenity.kernels.dynamic.DynamicGeometry` traced as one scene (the paper's "Conclusions and
Future Work": its §9 ray tracer is limited to static geometry).

:class:`TwoLevelTracer` numbers the triangles static first (the kd-tree's 0 … F−1), then the dynamic
ones from F on, and answers :class:`KdTree`'s queries in its forms (numpy rays in, numpy hits out, or
Warp arrays on the dynamic geometry's device in and out): the closest hit of the two
(:meth:`TwoLevelTracer.intersect`) and any hit of either (:meth:`TwoLevelTracer.occluded`).

The closest hit is the nearer of the two, static first: the kd-tree's query is its own, unchanged
(its reordering, packets and scalar-tmax fast path), and the dynamic kernel then takes each ray's
static hit as its tmax and replaces it where an object is nearer, in place
(``DynamicGeometry.trace_into``), so the top level culls every object behind the static hit; equal t
keep the static hit (the lower index). Any hit: the kd-tree's, then the objects for the rays it
left unoccluded (``DynamicGeometry.occlude_into``). With no dynamic object its results are the kd-tree's, bit for
bit. The other order (the dynamic query first, its hits the kd-tree's per-ray tmax, then a merge)
cost as much or more: CPU seconds of the courtyard's 320x180 camera rays 37.5 ms static first against
39.1 (10 objects of 10k triangles) and 22.3 against 24.5 (one of 100k), 64k random rays among the
objects 45.7 against 44.7 and 40.2 against 40.4 (2 threads; ``benchmarks/bench_dynamic.py``'s
``order`` figures time both).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from serenity.kernels.dynamic import DynamicGeometry, ray_batch
from serenity.kernels.kdtree import Hits, KdTree


class TwoLevelTracer:
    """A static :class:`KdTree` and a :class:`DynamicGeometry` traced as one scene (module docstring):
    triangles numbered static first (the kd-tree's 0 … F−1), then the dynamic ones from F on (the
    ``DynamicGeometry``'s own ``prim_base`` is not used). Queries on the dynamic geometry's device,
    in :class:`KdTree`'s forms: numpy in and out, or Warp arrays there in and out."""

    def __init__(self, tree: KdTree, dynamic: DynamicGeometry):
        self.tree = tree
        self.dynamic = dynamic
        self.device = dynamic.device

    @property
    def prim_base(self) -> int:
        """The first dynamic triangle's index: the static triangle count."""
        return len(self.tree.faces)

    def intersect(self, origins, directions, tmax=np.inf, *, tmin: float = 0.0, threads: int | None = None,
                  sort: bool | None = None) -> Hits:
        """Closest hits, static or dynamic (``sort`` as ``KdTree.intersect``'s, for the static query)."""
        o, d, tm, on_device = ray_batch(origins, directions, tmax, self.device)
        hits = self.tree.intersect(o, d, tm, self.device, tmin=tmin, threads=threads, sort=sort)
        self.dynamic.trace_into(hits, o, d, tm, tmin, self.prim_base, threads)
        return hits if on_device else hits.numpy()

    def occluded(self, origins, directions, tmax=np.inf, *, tmin: float = 0.0, threads: int | None = None,
                 sort: bool | None = None) -> np.ndarray | wp.array:
        """Any hit, static or dynamic: (N,) bool, or an (N,) int32 Warp array for Warp rays."""
        o, d, tm, on_device = ray_batch(origins, directions, tmax, self.device)
        occ = self.tree.occluded(o, d, tm, self.device, tmin=tmin, threads=threads, sort=sort)
        self.dynamic.occlude_into(occ, o, d, tm, tmin, threads)
        return occ if on_device else occ.numpy().astype(bool)

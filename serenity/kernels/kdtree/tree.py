"""The host class of the kd-tree (paper §9): :class:`KdTree` takes a scene's triangles (vertices
(V,3) and faces (F,3)), builds or loads its SAH kd-tree (:mod:`serenity.kernels.kdtree_build`,
settings :class:`serenity.config.KdBuildConfig`), keeps its arrays per device (``layout``) and
answers the queries (``query``): closest hits (:meth:`KdTree.intersect`) and any hit
(:meth:`KdTree.occluded`), with an optional alpha test for cut-outs.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import warp as wp

from serenity.config import KdBuildConfig
from serenity.device import init_warp, resolve_device
from serenity.errors import SerenityError
from serenity.kernels.kdtree_build import (
    CACHE_MIN_TRIANGLES,
    PROGRESS_MIN_TRIANGLES,
    KdStats,
    build_arrays,
    geometry_key,
    load_tree,
    save_tree,
    validate_mesh,
)
from serenity.kernels.launch import Staging
from serenity.scene.cache import cache_dir

from .cpu.packets import PACKET_MIN_RAYS
from .keys import SORT_MIN_RAYS
from .layout import MAX_CUTOUT_LAYERS, T_TOLERANCE, KdTreeData, is_cpu, tree_data
from .query import Hits, hit_outputs, launch_query, ray_arrays
from .reorder import batch_is_coherent, gather_in_order, ray_order


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
        """The tree's Warp arrays on ``device`` (created once per device; ``layout.tree_data``)."""
        data = self._device_data.get(device)
        if data is None:
            init_warp()
            data = tree_data(self.vertices, self.faces, self.node_head, self.node_split, self.prims, self.box,
                             self.stats.depth, device)
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
    def host_rays(origins, directions, tmax) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """numpy rays checked (as many origins as directions) and packed float32; ``tmax`` a 0-d
        float32 for one value, else (N,) float32 (also what ``serenity.kernels.dynamic`` queries with)."""
        o = np.ascontiguousarray(np.asarray(origins, np.float32).reshape(-1, 3))
        d = np.ascontiguousarray(np.asarray(directions, np.float32).reshape(-1, 3))
        if len(o) != len(d):
            raise SerenityError(f"{len(o)} ray origins but {len(d)} directions")
        if np.ndim(tmax) == 0:
            return o, d, np.float32(tmax)  # one value: a filled workspace buffer (``query.ray_arrays``)
        tm = np.ascontiguousarray(np.broadcast_to(np.asarray(tmax, np.float32), (len(o),)))
        return o, d, tm

    @staticmethod
    def device_rays(origins, directions, tmax, device: str | None) -> tuple[wp.array, wp.array, object, str]:
        """Warp rays checked, and their device: ``origins`` and ``directions`` 1-D ``wp.vec3`` arrays of
        one length on one device (the query's: ``device``, where given, must name it); ``tmax`` as
        :meth:`host_rays` makes it (a scalar stays 0-d), or a 1-D float32 Warp array there, used as it is."""
        if not (isinstance(origins, wp.array) and isinstance(directions, wp.array)):
            raise SerenityError("ray origins and directions: both Warp arrays or neither")
        for name, a in (("origins", origins), ("directions", directions)):
            if a.ndim != 1 or a.dtype != wp.vec3:
                raise SerenityError(f"ray {name}: a 1-D Warp array of wp.vec3 expected, not "
                                    f"{getattr(a.dtype, '__name__', a.dtype)} of shape {a.shape}")
        dev = str(origins.device)
        if str(directions.device) != dev:
            raise SerenityError(f"ray origins on {dev} but directions on {directions.device}")
        if device is not None and resolve_device(device) != dev:
            raise SerenityError(f"rays on {dev} but the query's device is {resolve_device(device)}")
        n = origins.shape[0]
        if directions.shape[0] != n:
            raise SerenityError(f"{n} ray origins but {directions.shape[0]} directions")
        if isinstance(tmax, wp.array):
            if tmax.ndim != 1 or tmax.dtype != wp.float32 or tmax.shape[0] != n or str(tmax.device) != dev:
                raise SerenityError(f"tmax: a 1-D float32 Warp array of {n} on {dev} expected, not "
                                    f"{getattr(tmax.dtype, '__name__', tmax.dtype)} of shape {tmax.shape} on "
                                    f"{tmax.device}")
            return origins, directions, tmax, dev
        if np.ndim(tmax) == 0:
            return origins, directions, np.float32(tmax), dev
        return origins, directions, np.ascontiguousarray(np.broadcast_to(np.asarray(tmax, np.float32), (n,))), dev

    def _batch(self, origins, directions, tmax, device: str | None) -> tuple:
        """(origins, directions, tmax, device, whether the rays are Warp arrays): numpy rays through
        :meth:`host_rays` on the resolved ``device``, Warp rays through :meth:`device_rays` on theirs."""
        if isinstance(origins, wp.array) or isinstance(directions, wp.array):
            return (*self.device_rays(origins, directions, tmax, device), True)
        return (*self.host_rays(origins, directions, tmax), resolve_device(device), False)

    def _query_inputs(self, o, d, tm, dev: str, tmin: float, sort: bool | None,
                      threads: int | None) -> tuple[list, wp.array, bool]:
        """The query kernels' inputs (the tree, the rays in their traced order) and that order (empty:
        as given; else ray i of the kernel is the caller's ray ``order[i]``). ``tm``: :meth:`host_rays`'
        tmax, 0-d when every ray has the same (then it needs no reordering). Third: whether a batch
        left in its order is coherent (:func:`batch_is_coherent`; on the CPU it is traced in packets).
        Warp rays on a GPU: ``sort=None`` sorts every batch of ≥ ``SORT_MIN_RAYS`` rays, without the
        coherence test, whose sample would come back to the host."""
        data = self.device_data(dev)
        workspace = self.workspace(dev)
        origins, directions, tmin, tmax = ray_arrays(o, d, tm, dev, tmin, workspace)
        n = o.shape[0]
        if sort is None and isinstance(o, wp.array) and not is_cpu(dev):
            sort = n >= SORT_MIN_RAYS
        order = ray_order(data.box_lo, data.box_hi, origins, directions, n, sort, dev, threads, workspace)
        coherent = False
        if order.shape[0]:
            origins, directions = gather_in_order(order, [origins, directions], dev, threads, workspace)
            if np.ndim(tm) > 0:  # a scalar tmax (0-d ``tm``, :meth:`host_rays`) needs no reordering
                (tmax,) = gather_in_order(order, [tmax], dev, threads, workspace)
        elif is_cpu(dev) and n >= PACKET_MIN_RAYS:
            # with sort=None, ray_order leaves a big batch in its order only when it found it coherent
            coherent = (sort is None and n >= SORT_MIN_RAYS) or batch_is_coherent(
                data.box_lo, data.box_hi, origins, directions, n, dev, threads)
        return [data, origins, directions, tmin, tmax], order, coherent

    def intersect(self, origins, directions, tmax=np.inf, device: str | None = None, *, tmin: float = 0.0,
                  threads: int | None = None, sort: bool | None = None, rays_per_thread: int | None = None) -> Hits:
        """Closest hits of rays ``origins`` (N,3), ``directions`` (N,3) with tmin < t < tmax
        (scalar or (N,)); t in units of |direction|. ``sort``: trace the rays in the reordered
        order (:func:`ray_order`; None = for batches of ≥ ``SORT_MIN_RAYS``); ``rays_per_thread``:
        1 (one ray per kernel thread) or ``PACKET_LANES`` (packets), CPU only; None = the traversal
        of ``query.TRAVERSAL`` for the device and the batch (on the CPU packets when reordered or
        coherent, else one ray). The results are the same either way, in the caller's order.

        Warp rays in, Warp hits out: ``origins`` and ``directions`` as (N,) ``wp.vec3`` arrays on one
        device (the query's; ``device`` may be left out) and ``tmax`` a scalar or an (N,) float32 Warp
        array there give :class:`Hits` of Warp arrays on that device, with no copy of rays or hits
        to or from the host (a numpy (N,) ``tmax`` is copied there). The one exception is a tree with
        an alpha test (:meth:`set_alpha_test`), which runs on the host: from a GPU the hits on its
        triangles go through the host and back."""
        o, d, tm, dev, on_device = self._batch(origins, directions, tmax, device)
        hits = self._closest(o, d, tm, dev, tmin, threads, sort, rays_per_thread, on_device)
        if self._masked is not None and o.shape[0]:
            if on_device:
                host = hits.numpy()  # views on the CPU, a copy from a GPU
                self._through_cutouts(host, o.numpy(), d.numpy(), _host_tmax(tm), dev, tmin, threads)
                if not is_cpu(dev):
                    for dst, src in zip((hits.t, hits.prim, hits.u, hits.v), (host.t, host.prim, host.u, host.v),
                                        strict=True):
                        dst.assign(src)
            else:
                self._through_cutouts(hits, o, d, tm, dev, tmin, threads)
        return hits

    def _closest(self, o, d, tm, dev: str, tmin: float, threads: int | None, sort: bool | None,
                 rays_per_thread: int | None, on_device: bool = False) -> Hits:
        """The closest-hit query of :meth:`intersect` without the alpha test; ``on_device``: the hits as
        the Warp arrays they were traced into."""
        n = o.shape[0]
        if n:
            args, order, coherent = self._query_inputs(o, d, tm, dev, tmin, sort, threads)
            columns, records = hit_outputs(n, dev, order.shape[0] > 0)
            launch_query(False, n, args, order, columns, dev, threads, rays_per_thread, self.workspace(dev), coherent,
                          records)
        else:
            columns, _ = hit_outputs(0, dev, False)
        if on_device:
            return Hits(*columns)
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
            oi, di32, tmax_i = self.host_rays(oi, d[idx], tmax_i)
            again = self._closest(oi, di32, tmax_i, dev, float(step.min()), threads, None, None)
            hit = again.prim >= 0
            hits.t[idx] = np.where(hit, (t0 + again.t).astype(np.float32), np.inf)
            hits.prim[idx], hits.u[idx], hits.v[idx] = again.prim, again.u, again.v

    def occluded(self, origins, directions, tmax=np.inf, device: str | None = None, *, tmin: float = 0.0,
                 threads: int | None = None, sort: bool | None = None,
                 rays_per_thread: int | None = None) -> np.ndarray | wp.array:
        """(N,) bool: does anything lie on each ray with tmin < t < tmax? (any hit: the traversal
        stops at the first one; ``sort`` and ``rays_per_thread`` as for :meth:`intersect`). Warp rays
        (as for :meth:`intersect`) give an (N,) int32 Warp array on their device, 1 where occluded."""
        o, d, tm, dev, on_device = self._batch(origins, directions, tmax, device)
        n = o.shape[0]
        out = wp.zeros(n, dtype=wp.int32, device=dev)
        if n:
            args, order, coherent = self._query_inputs(o, d, tm, dev, tmin, sort, threads)
            launch_query(True, n, args, order, [out], dev, threads, rays_per_thread, self.workspace(dev), coherent)
        if on_device:
            if self._masked is not None and n:
                occ = out.numpy()  # a view on the CPU, a copy from a GPU
                if occ.any():
                    self._recheck_occluded(occ, o.numpy(), d.numpy(), _host_tmax(tm), dev, tmin, threads)
                    if not is_cpu(dev):
                        out.assign(occ)
            return out
        occ = out.numpy().astype(bool)
        if self._masked is not None and occ.any():
            self._recheck_occluded(occ, o, d, tm, dev, tmin, threads)
        return occ

    def _recheck_occluded(self, occ: np.ndarray, o, d, tm, dev: str, tmin: float, threads: int | None) -> None:
        """An any hit may be a rejected cut-out: the occluded rays (``occ``, in place) look for their
        nearest kept hit."""
        idx = np.flatnonzero(occ)
        tmi = tm if np.ndim(tm) == 0 else tm[idx]
        occ[idx] = self.intersect(o[idx], d[idx], tmi, dev, tmin=tmin, threads=threads).prim >= 0


def _host_tmax(tm):
    """A query's tmax (:meth:`KdTree._batch`) for the host's alpha test: numpy as it is, a Warp array's
    values (a view on the CPU)."""
    return tm.numpy() if isinstance(tm, wp.array) else tm

"""The LPV host class: ``LightPropagationVolume`` owns the device arrays of every cascade and runs
fit → clear → inject (VPLs, surfels) → propagate → lookup (package docstring for the maths).

Every launch goes through ``serenity.kernels.launch`` (split over all CPU cores); the scatter
(injection) goes through its ``ScatterGrid`` and host inputs through its ``Staging``, so nothing
here depends on the device kind.
"""

from __future__ import annotations

import math
import time
import zlib
from dataclasses import dataclass

import numpy as np
import warp as wp

from serenity.config import LPVConfig
from serenity.device import cpu_threads, init_warp, resolve_device
from serenity.kernels.launch import (
    MIN_CHEAP_ITEMS_PER_THREAD,
    ScatterGrid,
    Staging,
    chunk_ranges,
    host_array,
    launch,
)
from serenity.kernels.lpv.basis import MAX_CASCADES, SH_FLUX
from serenity.kernels.lpv.cascades import CascadeGrid, fit_cascades
from serenity.kernels.lpv.early_stop import level_stop
from serenity.kernels.lpv.grid import Cascade
from serenity.kernels.lpv.inject import inject_geometry, inject_vpls, measure_cells
from serenity.kernels.lpv.lookup import blend_shown, lookup_glossy, lookup_irradiance_kernel
from serenity.kernels.lpv.propagate import eval_face_transmittance, hand_over_far, propagate_kernel


def blend_updates(alpha: float) -> int:
    """Updates a temporal blend of ``alpha`` (``LightPropagationVolume.update``) takes to show new light
    exactly: the first after which under 1 % of a change is still to come, (1 − alpha)^k < 0.01."""
    if alpha >= 1.0:
        return 1
    return max(1, math.ceil(math.log(0.01) / math.log(1.0 - alpha)))


@dataclass
class _Level:
    """Offsets of one config level (cascade) in the shared arrays."""

    res: int
    base: int  # first vec4 of this level in the SH grids (3·res³ vec4: R, G, B blocks)
    cell_base: int  # first cell in the per-cell arrays (res³)
    gv_base: int  # first vec4 in the geometry volume ((res+1)³)

    @property
    def size(self) -> int:
        return 3 * self.res**3

    def struct(self, grid: CascadeGrid | None = None) -> Cascade:
        """This level as a kernel ``Cascade``, placed as ``grid`` (origin 0, cell 0 without one)."""
        c = Cascade()
        c.res, c.base, c.cell_base, c.gv_base = self.res, self.base, self.cell_base, self.gv_base
        c.origin = wp.vec3(*(grid.origin if grid else (0.0, 0.0, 0.0)))
        c.cell = float(grid.cell_size) if grid else 0.0
        return c


class LightPropagationVolume:
    """Cascaded LPV on one device: fit → clear → inject (VPLs, surfels) → propagate → lookup.

    All buffers are allocated once in ``__init__`` (4 SH grids — injected, ping, pong, accumulated —
    of 3·res³ float4 per cascade, a (res+1)³ geometry volume, face transmittances; the injected grid
    and the geometry volume are ``ScatterGrid``s); numpy inputs go through a ``Staging``.
    ``timings`` holds the last wall time of each stage in ms (the device is synchronised when
    ``sync_timings``).

    ``fitted``: the cascades placed by ``fit`` (by config level; with ``LPVConfig.stagger`` the grids
    each level holds, some placed by earlier updates); ``grids``: those that hold light (the ones
    looked up and exported; index 0 = finest).

    What a level holds: its own accumulated light (``_accum``), and the grid the lookups read
    (``_lookup``): that plus the far light handed over from the coarser cascades, rebuilt after
    every propagation from each coarser level's last far grid, so a level propagated alone (stagger)
    still sees the others' light.
    """

    def __init__(self, config: LPVConfig | None = None, device: str | None = None, threads: int | None = None,
                 sync_timings: bool = True):
        init_warp()
        self.config = config or LPVConfig()
        self.device = resolve_device(device)
        self.threads = threads
        self.sync_timings = sync_timings
        self.fitted: list[CascadeGrid] = []
        self.grids: list[CascadeGrid] = []
        self.timings: dict[str, float] = {}
        self.iterations_run: list[int] = []
        self._propagate = propagate_kernel(bool(self.config.geometry_volume), bool(self.config.clamp_faces))
        self._propagate_loop = propagate_kernel(bool(self.config.geometry_volume), bool(self.config.clamp_faces),
                                                loop=True)
        self._occlusion = bool(self.config.leak_guard and self.config.lookup_occlusion and self.config.geometry_volume)
        self._planes = self._occlusion and bool(self.config.lookup_planes)
        self._coverage = bool(self.config.geometry_volume and self.config.coverage_blocking)
        self._moments = self._planes or self._coverage  # the geometry volume keeps the blockers' moments
        self._lookup_irradiance = lookup_irradiance_kernel(bool(self.config.leak_guard), self._occlusion,
                                                           self._planes)
        dev = self.device
        self._levels: list[_Level] = []
        base = cbase = gbase = 0
        for r in self.config.resolutions:
            self._levels.append(_Level(r, base, cbase, gbase))
            base, cbase, gbase = base + 3 * r**3, cbase + r**3, gbase + (r + 1) ** 3
        self._n_vec, self._n_cells, self._n_gv = base, cbase, gbase
        self._inj = ScatterGrid(base, dev, threads)
        # the geometry volume: blocking SH, then (lookup_planes) Σ w·offset and Σ w per axis (inject_geometry)
        self._gv = ScatterGrid(gbase * (3 if self._moments else 1), dev, threads)
        self._ping = wp.zeros(base, dtype=wp.vec4, device=dev)
        self._pong = wp.zeros(base, dtype=wp.vec4, device=dev)
        self._accum = wp.zeros(base, dtype=wp.vec4, device=dev)
        self._lookup = wp.zeros(base, dtype=wp.vec4, device=dev)
        self._far = wp.zeros(base, dtype=wp.vec4, device=dev)
        self._far_from = wp.zeros(len(self._levels), dtype=int, device=dev)
        self._trans_pos = wp.ones(cbase, dtype=wp.vec3, device=dev)
        self._trans_neg = wp.ones(cbase, dtype=wp.vec3, device=dev)
        self._open = wp.ones(cbase, dtype=wp.vec3, device=dev)
        self._plane = wp.zeros(cbase, dtype=wp.vec3, device=dev)
        self._change = wp.zeros(cbase, dtype=float, device=dev)
        self._total = wp.zeros(cbase, dtype=float, device=dev)
        self._level_table = wp.array([v.struct() for v in self._levels], dtype=Cascade, device=dev)
        self._level_on = wp.zeros(len(self._levels), dtype=int, device=dev)
        self._iters = wp.zeros(len(self._levels), dtype=int, device=dev)  # the one-launch propagation's
        self._done_dev = wp.zeros(len(self._levels), dtype=int, device=dev)
        self._sums = wp.zeros(2 * len(self._levels), dtype=wp.float64, device=dev)
        #: decide the early stop on the device in the per-iteration launches on the CPU too (as on CUDA;
        #: the CPU's default sums a view of the cells on the host, which costs no copy there)
        self._device_stop = False
        # injection table (fitted cascades) and lookup table (active cascades)
        self._fit_table = wp.zeros(MAX_CASCADES, dtype=Cascade, device=dev)
        self._cas_table = wp.zeros(MAX_CASCADES, dtype=Cascade, device=dev)
        self._staging = Staging(dev)
        nl = len(self._levels)
        #: per level: (grid, input key) it was last injected and propagated with
        self._held: dict[int, tuple] = {}
        self._target: dict[int, tuple] = {}  # per level: (grid, input key) the last ``update`` asked for
        self._next_level = 0  # where the stagger's turn goes on
        self._inject_grids: list[CascadeGrid] = []  # the fitted grids that inject/propagate refresh
        self._lit = np.zeros(nl, bool)  # per level: received light at its last propagation
        self._done = np.zeros(nl, np.int64)  # per level: iterations of its last propagation
        self._scene_size = 0.0  # largest side of the scene bounds given to ``fit`` (m)
        self._gv_dirty = True
        self._has_result = False
        # temporal blend (``update``'s ``blend``): what lookups read, per level in the grid it was shown in,
        # and how many more updates each level blends before it shows its newest light exactly
        self._shown: wp.array | None = None
        self._shown_prev: wp.array | None = None
        self._shown_grids: dict[int, CascadeGrid] = {}
        self._blend_left: dict[int, int] = {}
        self._showing = False

    # -- helpers ---------------------------------------------------------------------------------

    def _launch_cells(self, kernel, dim: int, inputs: list, start: int = 0) -> None:
        """Launch a kernel over cells: ~0.1 µs of work each, so at least
        ``MIN_CHEAP_ITEMS_PER_THREAD`` of them per worker thread (``kernels/launch.py``)."""
        launch(kernel, dim, inputs, device=self.device, threads=self.threads, start=start,
               min_items=MIN_CHEAP_ITEMS_PER_THREAD)

    def _timed(self, name: str, t0: float):
        if self.sync_timings:
            wp.synchronize_device(self.device)
        self.timings[name] = (time.perf_counter() - t0) * 1e3

    def _tables(self, grids: list[CascadeGrid], table: wp.array) -> None:
        rows = [self._levels[g.level].struct(g) for g in grids]
        rows += [Cascade() for _ in range(MAX_CASCADES - len(rows))]
        wp.copy(table, wp.array(rows, dtype=Cascade, device="cpu"))

    def _level_sums(self, a: wp.array, levels=None) -> np.ndarray:
        """Σ of a per-cell array over each config level's cells (float64; 0 for levels not in
        ``levels`` when given — the early-stop test sums only the cascades still iterating)."""
        h = a.numpy()  # a view on the CPU; one copy from CUDA
        out = np.zeros(len(self._levels))
        for k, v in enumerate(self._levels):
            if levels is None or k in levels:
                out[k] = np.sum(h[v.cell_base:v.cell_base + v.res**3], dtype=np.float64)
        return out

    def _last_wavefront(self, level: int) -> wp.array:
        """The array holding a level's last propagation iteration: iteration k writes ping-pong buffer
        k % 2 (the injected grid before the first), and a level's cells are not written once it stops."""
        done = int(self._done[level])
        return self._inj.array if done == 0 else (self._ping, self._pong)[(done - 1) % 2]

    # -- stages --------------------------------------------------------------------------------

    def _place(self, camera, scene_bounds) -> list[CascadeGrid]:
        """The cascades' grids for ``camera`` (a Camera, or (position, view_dir))."""
        if hasattr(camera, "position"):
            pos, view = camera.position, camera.forward
        else:
            pos, view = camera
        b = np.asarray(scene_bounds, np.float64).reshape(2, 3)
        self._scene_size = float(np.max(b[1] - b[0]))
        return fit_cascades(pos, view, scene_bounds, self.config)

    def fit(self, camera, scene_bounds) -> bool:
        """Place the cascades for ``camera`` (a Camera, or (position, view_dir)); True if any moved."""
        t0 = time.perf_counter()
        grids = self._place(camera, scene_bounds)
        moved = grids != self.fitted
        self.fitted = grids
        self._set_inject_grids(grids)
        self._timed("fit", t0)
        return moved

    def _set_inject_grids(self, grids: list[CascadeGrid]) -> None:
        """The grids the next ``inject``/``inject_geometry``/``propagate`` refresh (their table)."""
        if grids != self._inject_grids:
            self._inject_grids = list(grids)
            self._tables(self._inject_grids, self._fit_table)

    def clear(self) -> None:
        """Zero the injected grids and the geometry volume (call before injecting a new frame's lights)."""
        t0 = time.perf_counter()
        self._inj.zero()
        self._gv.zero()
        self._gv_dirty = True
        self._has_result = False
        self._timed("clear", t0)

    def inject(self, positions, normals, flux) -> None:
        """Add VPLs (positions (N,3) m, normals (N,3), flux (N,3) W) to every fitted cascade (to the
        one a staggered ``update`` refreshes)."""
        t0 = time.perf_counter()
        p = self._staging.input(positions, "vpl_p", wp.vec3, 3)
        n = self._staging.input(normals, "vpl_n", wp.vec3, 3)
        f = self._staging.input(flux, "vpl_f", wp.vec3, 3)
        if not (p.shape[0] == n.shape[0] == f.shape[0]):
            raise ValueError(f"VPL arrays differ in length: {p.shape[0]}, {n.shape[0]}, {f.shape[0]}")
        self._inj.scatter(inject_vpls, p.shape[0], [p, n, f, self._fit_table, len(self._inject_grids),
                                                     float(self.config.injection_offset)])
        self._timed("inject", t0)

    def inject_geometry(self, positions, normals, areas) -> None:
        """Add occluding surfels (positions (M,3) m, normals (M,3), areas (M,) m²) to the geometry volume."""
        t0 = time.perf_counter()
        p = self._staging.input(positions, "gv_p", wp.vec3, 3)
        n = self._staging.input(normals, "gv_n", wp.vec3, 3)
        a = self._staging.input(areas, "gv_a", float, 1)
        if not (p.shape[0] == n.shape[0] == a.shape[0]):
            raise ValueError(f"surfel arrays differ in length: {p.shape[0]}, {n.shape[0]}, {a.shape[0]}")
        self._gv.scatter(inject_geometry, p.shape[0], [p, n, a, self._fit_table, len(self._inject_grids),
                                                      self._n_gv if self._moments else 0])
        self._gv_dirty = True
        self._timed("inject_geometry", t0)

    def propagate(self, iterations: int | None = None, early_stop: float | None = None,
                  one_launch: bool | None = None) -> list[int]:
        """Propagate every refreshed cascade (the fitted ones, or the one ``update`` staggers to) that
        received light; return the iterations run per fitted cascade (0 for a skipped one; a level
        not refreshed keeps its last count). Restarts from the injected grids each call (so it may be
        re-run, e.g. with other settings). ``iterations`` overrides the config for every cascade
        (and turns off ``cross_scene``'s extension). ``one_launch``: every iteration in one single-threaded
        launch (``propagate_kernel(loop=True)``) instead of a launch per iteration; the same light, bit for
        bit. None = where the per-iteration launches would each run on one thread anyway (the CPU, under
        ``MIN_CHEAP_ITEMS_PER_THREAD`` cells per thread: a 3 × 12³ LPV), where it saves their Python."""
        t0 = time.perf_counter()
        cfg = self.config
        nl = len(self._levels)
        iters = np.array(cfg.iteration_counts if iterations is None else (int(iterations),) * nl, np.int64)
        if iterations is None and cfg.cross_scene and self.fitted:
            g = self.fitted[-1]
            iters[g.level] = max(iters[g.level], min(g.resolution, math.ceil(self._scene_size / g.cell_size)))
        thresh = cfg.early_stop if early_stop is None else float(early_stop)
        self._inj.gather()
        self._gv.gather()
        inj = self._inj.array
        fitted = {g.level for g in self.fitted}
        upd = sorted(g.level for g in self._inject_grids)  # the levels this call refreshes
        # their span in the shared arrays (levels are stored in order; a level between two refreshed
        # ones is one that is not fitted, so rewriting it is harmless): cells [c0, c1), vec4s [v0, v1)
        refreshed = [self._levels[lv] for lv in upd]
        c0 = min((v.cell_base for v in refreshed), default=0)
        c1 = max((v.cell_base + v.res**3 for v in refreshed), default=0)
        v0 = min((v.base for v in refreshed), default=0)
        v1 = max((v.base + v.size for v in refreshed), default=0)
        # skip cascades that received nothing: not propagated, not looked up
        self._launch_cells(measure_cells, self._n_cells, [inj, self._level_table, nl, self._total])
        injected = self._level_sums(self._total)
        for lv in range(nl):
            if lv in upd:
                self._lit[lv] = injected[lv] > 0.0
            elif lv not in fitted:
                self._lit[lv] = False
        on = np.array([1 if (lv in upd and self._lit[lv] and iters[lv] > 0) else 0 for lv in range(nl)], np.int32)
        self.grids = [g for g in self.fitted if self._lit[g.level]]
        self._tables(self.grids, self._cas_table)
        if cfg.geometry_volume and self._gv_dirty:
            args = [self._gv.array, self._level_table, nl, self._trans_pos, self._trans_neg, self._open,
                    self._plane, self._n_gv if self._moments else 0, int(self._coverage) + 2 * int(self._planes)]
            # the other levels keep the faces of the surfels they were propagated with
            self._launch_cells(eval_face_transmittance, c1 - c0, args, start=c0)
            self._gv_dirty = False
        # hand-over: a cascade's iterations past the finer one's reach (in its own cells) go to "far"
        far_from = np.full(nl, 1 << 30, np.int32)
        hand_over = cfg.handover and len(self.grids) > 1
        if hand_over:
            for fine, coarse in zip(self.grids, self.grids[1:], strict=False):
                reach = iters[fine.level] * fine.cell_size / coarse.cell_size
                far_from[coarse.level] = max(1, math.ceil(reach - 1e-6))
        if v1 > v0:
            self._far[v0:v1].zero_()
        self._far_from.assign(far_from)
        for lv in upd:
            self._done[lv] = 0
        bufs = (self._ping, self._pong)
        if v1 > v0:
            if cfg.accumulate_injected:
                wp.copy(self._accum, inj, dest_offset=v0, src_offset=v0, count=v1 - v0)
            else:
                self._accum[v0:v1].zero_()
        n_iter = int(iters.max(initial=0))
        span = [self._levels[lv] for lv in np.flatnonzero(on & (iters > 0))]
        lo = min((v.cell_base for v in span), default=0)
        hi = max((v.cell_base + v.res**3 for v in span), default=0)
        if one_launch is None:  # where the per-iteration launches would run on one thread anyway
            one_launch = (str(self.device).startswith("cpu") and
                          len(chunk_ranges(hi - lo, self.threads or cpu_threads(), MIN_CHEAP_ITEMS_PER_THREAD)) <= 1)
        if one_launch and span:
            self._level_on.assign(on)
            self._iters.assign(iters.astype(np.int32))
            wp.launch(self._propagate_loop, dim=1,
                      inputs=[inj, self._trans_pos, self._trans_neg, self._level_table, nl, self._iters, self._far_from,
                              n_iter, lo, hi, float(thresh), self._level_on, self._ping, self._pong, self._accum,
                              self._far, self._done_dev, self._sums, 0], device=self.device)
            done = self._done_dev.numpy()
            for lv in np.flatnonzero(on):
                self._done[lv] = int(done[lv])
        else:
            on_device = not str(self.device).startswith("cpu") or self._device_stop
            started = on.copy()
            if on_device:  # which cascades go on is decided on the device (lpv/early_stop.py): no copy per iteration
                self._level_on.assign(on)
                self._iters.assign(iters.astype(np.int32))
                self._done_dev.zero_()
            for k in range(n_iter):
                on = on & (iters > k)  # on the device: the cascades that may still run (level_on says which do)
                if not on.any():
                    break
                if not on_device:
                    self._level_on.assign(on)
                # threads only for the cells of the cascades still iterating (the coarsest may run on alone)
                active = [self._levels[lv] for lv in np.flatnonzero(on)]
                lo = min(v.cell_base for v in active)
                dim = max(v.cell_base + v.res**3 for v in active) - lo
                self._launch_cells(self._propagate, dim,
                                   [inj if k == 0 else bufs[(k - 1) % 2], self._accum, self._trans_pos,
                                    self._trans_neg, self._level_table, nl, self._level_on, self._far_from, k + 1,
                                    bufs[k % 2], self._accum, self._far, self._change, self._total], start=lo)
                if on_device:
                    wp.launch(level_stop, dim=nl, inputs=[self._change, self._total, self._level_table, self._iters,
                                                          k, float(thresh), self._level_on, self._done_dev],
                              device=self.device)
                    continue
                self._done[np.flatnonzero(on)] += 1
                if thresh > 0.0:
                    live = set(np.flatnonzero(on).tolist())
                    change, total = self._level_sums(self._change, live), self._level_sums(self._total, live)
                    on = on & ~((change <= thresh * total) | (total <= 0.0))
            if on_device:
                done = self._done_dev.numpy()
                for lv in np.flatnonzero(started):
                    self._done[lv] = int(done[lv])
        # what lookups read: each level's own light plus the far light of every coarser one
        wp.copy(self._lookup, self._accum)
        if hand_over:
            for c in range(len(self.grids) - 1):
                self._launch_cells(hand_over_far, self._levels[self.grids[c].level].res ** 3,
                                   [self._far, self._cas_table, len(self.grids), c, self._lookup])
        self.iterations_run = [int(self._done[g.level]) for g in self.fitted]
        self._has_result = True
        self._showing = False  # lookups read this propagation's light until ``update`` blends it in
        self._timed("propagate", t0)
        return self.iterations_run

    def input_key(self, vpls, surfels=None):
        """A cheap fingerprint of the injection inputs (shapes + CRC32 of the bytes), or None when it
        cannot be had cheaply (callables, arrays on a GPU): then every update re-injects."""
        parts = []
        for sets in (vpls, surfels):
            if sets is None:
                parts.append(None)
                continue
            if callable(sets):
                return None
            for s in sets:
                for a in s:
                    a = host_array(a)
                    if a is None:
                        return None
                    a = np.ascontiguousarray(a)
                    parts.append((a.shape, a.dtype.str, zlib.crc32(a.view(np.uint8).reshape(-1))))
        return tuple(parts)

    def invalidate(self) -> None:
        """Forget the last update's inputs: the next ``update`` re-injects and propagates."""
        self._held = {}

    @property
    def pending_levels(self) -> int:
        """Cascades that do not yet hold and show what the last ``update`` asked for (> 0 only while
        ``LPVConfig.stagger`` works through them or ``update``'s ``blend`` still blends their light in:
        call ``update`` again with the same inputs; ``stale_levels`` says how many need them)."""
        return sum(1 for lv, want in self._target.items() if self._held.get(lv) != want or lv in self._blend_left)

    @property
    def stale_levels(self) -> int:
        """Cascades that do not yet hold what the last ``update`` asked for: the next ``update`` with the
        same inputs re-injects and propagates one (0: it at most blends, ``blend`` does the same)."""
        return sum(1 for lv, want in self._target.items() if self._held.get(lv) != want)

    def blend(self, alpha: float) -> bool:
        """One step of ``update``'s temporal blend without new inputs (for a caller that knows that
        ``stale_levels`` is 0 and keeps the inputs to itself); returns whether what lookups read changed."""
        if not self._blend_left:
            return False
        t0 = time.perf_counter()
        self._blend(alpha, restart=False, was_showing=self._showing)
        self._timed("blend", t0)
        return True

    def update(self, camera, scene_bounds, vpls, surfels=None, key=None, blend: float = 1.0) -> bool:
        """One frame: refit; re-inject and propagate only the cascades whose inputs or cells changed.

        ``vpls``: a sequence of (positions, normals, flux) sets (sun RSM, sky-lit G-buffer, …), or a
        zero-argument callable returning one (called only when work is needed); ``surfels`` likewise
        with (positions, normals, areas). ``key``: any hashable that changes when the inputs do (sun
        direction, scene version, …); None → ``input_key`` fingerprints the arrays. Returns True
        when what lookups read changed (it re-injected and propagated, or blended). Every changed cascade
        is refreshed, or with ``LPVConfig.stagger`` one of them, the next in turn (``pending_levels``
        says how many wait).

        ``blend`` < 1 (``LPVConfig.temporal_blend``): lookups read light that moves this fraction of the
        way from what they read after the last update to the newest propagation, per cascade and in
        world space (a cascade whose box moved is blended where the boxes overlap), until
        ``blend_updates(blend)`` updates after the last propagation, when they read it exactly; meanwhile
        ``pending_levels`` counts those cascades and an update with unchanged inputs only blends.
        """
        t0 = time.perf_counter()
        was_showing = self._showing
        wanted = self._place(camera, scene_bounds)
        ikey = key if key is not None else self.input_key(vpls, surfels)
        self._target = {g.level: (g, ikey) for g in wanted}
        for lv in [lv for lv in self._held if lv not in self._target]:  # a cascade no longer placed
            del self._held[lv]
        stale = [g for g in wanted if ikey is None or self._held.get(g.level) != self._target[g.level]]
        if self._has_result and not stale:
            self.fitted = wanted
            blending = bool(self._blend_left)
            if blending:
                self._blend(blend, restart=False, was_showing=was_showing)
            self.timings["update"] = (time.perf_counter() - t0) * 1e3
            return blending
        if not self.config.stagger or not self._has_result or any(g.level not in self._held for g in wanted):
            stale = wanted  # every cascade (the paper's update; and whenever one holds no light yet)
        elif len(stale) > 1:
            nl = len(self._levels)
            stale = [min(stale, key=lambda g: (g.level - self._next_level) % nl)]  # the next in turn
        chosen = {g.level for g in stale}
        # the cascades not refreshed now keep the grids their light was propagated in
        self.fitted = [g if g.level in chosen else self._held[g.level][0] for g in wanted]
        self._set_inject_grids(stale)
        self.clear()
        t_inj = t_gv = 0.0
        for s in vpls() if callable(vpls) else vpls:
            self.inject(*s)
            t_inj += self.timings["inject"]
        if surfels is not None and self.config.geometry_volume:
            for s in surfels() if callable(surfels) else surfels:
                self.inject_geometry(*s)
                t_gv += self.timings["inject_geometry"]
        self.timings["inject"], self.timings["inject_geometry"] = t_inj, t_gv
        self.propagate()
        for g in stale:
            self._held[g.level] = self._target[g.level]
        self._next_level = (max(chosen) + 1) % len(self._levels)
        self._blend(blend, restart=True, was_showing=was_showing)
        self._timed("update", t0)
        return True

    def _blend(self, alpha: float, restart: bool, was_showing: bool) -> None:
        """``update``'s temporal blend: each active level's shown light one step towards its newest
        (``restart``: a propagation just made it), or, where there is nothing to blend from (the first
        update, a level that was not shown, ``alpha`` ≥ 1), its newest at once."""
        if alpha >= 1.0:
            self._shown_grids, self._blend_left, self._showing = {}, {}, False
            return
        if self._shown is None:
            self._shown = wp.zeros(self._n_vec, dtype=wp.vec4, device=self.device)
            self._shown_prev = wp.zeros(self._n_vec, dtype=wp.vec4, device=self.device)
        active = {g.level: g for g in self.grids}
        for lv in [lv for lv in self._shown_grids if lv not in active]:
            del self._shown_grids[lv]
            self._blend_left.pop(lv, None)
        steps = blend_updates(alpha)
        for lv, g in active.items():
            v = self._levels[lv]
            old = self._shown_grids.get(lv)
            if restart:
                if not was_showing or old is None or old.cell_size != g.cell_size or old.resolution != g.resolution:
                    self._blend_left.pop(lv, None)  # nothing shown to blend from: show it at once
                    wp.copy(self._shown, self._lookup, dest_offset=v.base, src_offset=v.base, count=v.size)
                    self._shown_grids[lv] = g
                    continue
                self._blend_left[lv] = steps
            left = self._blend_left.get(lv, 0) - 1
            if left < 0:
                continue
            if left == 0:  # the last step: exactly the newest light
                del self._blend_left[lv]
                wp.copy(self._shown, self._lookup, dest_offset=v.base, src_offset=v.base, count=v.size)
            else:
                self._blend_left[lv] = left
                wp.copy(self._shown_prev, self._shown, dest_offset=v.base, src_offset=v.base, count=v.size)
                shift = np.rint((np.asarray(g.origin) - np.asarray(old.origin)) / g.cell_size).astype(int)
                self._launch_cells(blend_shown, v.size, [self._lookup, self._shown_prev, v.base, v.res,
                                                         wp.vec3i(*shift.tolist()), float(alpha), self._shown])
            self._shown_grids[lv] = g
        self._showing = True

    def _lookups(self) -> wp.array:
        """The SH grids lookups and exports read: the blended light while ``update`` blends, else the
        last propagation's."""
        return self._shown if self._showing else self._lookup

    # -- lookup --------------------------------------------------------------------------------

    def irradiance(self, points, normals, blend: bool = True) -> np.ndarray:
        """Diffuse irradiance (W/m², (N,3) float32) at points (N,3) m with normals (N,3), ≥ 0.

        ``blend=False`` switches cascades hard at their borders (for measuring the seam).
        """
        t0 = time.perf_counter()
        p = self._staging.input(points, "lk_p", wp.vec3, 3)
        n = self._staging.input(normals, "lk_n", wp.vec3, 3)
        out = self._staging.buffer("out", p.shape[0], wp.vec3)
        cfg = self.config
        launch(self._lookup_irradiance, p.shape[0],
               [p, n, self._lookups(), self._open, self._plane, self._cas_table, len(self.grids),
                float(cfg.lookup_offset), float(cfg.edge_margin), float(cfg.blend_cells if blend else 0.0),
                float(cfg.self_damping), float(cfg.self_damping_power), out],
               device=self.device, threads=self.threads)
        res = out.numpy().copy()
        self._timed("lookup", t0)
        return res

    def glossy_step_length(self) -> float:
        """Spacing (m) of the glossy march: glossy_step cells of the finest active cascade."""
        return self.config.glossy_step * (self.grids[0].cell_size if self.grids else 1.0)

    def glossy(self, points, directions, shininess) -> np.ndarray:
        """Radiance (W·m⁻²·sr⁻¹, (N,3)) arriving at points from ``directions`` (reflected view rays),
        prefiltered by a normalised Phong lobe of exponent ``shininess`` (scalar or (N,))."""
        t0 = time.perf_counter()
        p = self._staging.input(points, "gl_p", wp.vec3, 3)
        d = self._staging.input(directions, "gl_d", wp.vec3, 3)
        m = np.broadcast_to(np.asarray(shininess, np.float32), (p.shape[0],))
        s = self._staging.input(m, "gl_m", float, 1)
        out = self._staging.buffer("out", p.shape[0], wp.vec3)
        cfg = self.config
        launch(lookup_glossy, p.shape[0],
               [p, d, s, self._lookups(), self._cas_table, len(self.grids), int(cfg.glossy_steps),
                float(self.glossy_step_length()), float(cfg.edge_margin), float(cfg.blend_cells), out],
               device=self.device, threads=self.threads)
        res = out.numpy().copy()
        self._timed("glossy", t0)
        return res

    # -- export --------------------------------------------------------------------------------

    def textures(self, cascade: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Accumulated intensity SH of active cascade ``cascade`` (index into ``grids``) for GL upload:
        R, G, B, each float32 (Z, Y, X, 4), RGBA = (Y0, x, y, z) in W/sr; origin and cell size in
        ``grids[cascade]``."""
        g = self.level_grid(self.grids[cascade].level, "accum")
        return g[0].copy(), g[1].copy(), g[2].copy()

    def openness(self, cascade: int) -> np.ndarray:
        """Face openness of active cascade ``cascade`` for GL upload: float32 (Z, Y, X, 4), RGB = 1 − the
        geometry volume's blocking of the cell's +x, +y, +z faces (1 = open; all 1 without a geometry
        volume); A = where the blockers of those faces lie (``lookup_planes``), t ∈ [−½, ½] cells from
        the face, packed as the integer qx + 256·qy + 65536·qz, q = round((t + ½)·254) (exact in float32;
        lpv.glsl unpacks it; 127 per axis = on the face)."""
        lv = self._levels[self.grids[cascade].level]
        sl = slice(lv.cell_base, lv.cell_base + lv.res**3)
        o = self._open.numpy()[sl].reshape(lv.res, lv.res, lv.res, 3)
        q = np.rint((self._plane.numpy()[sl].reshape(o.shape).astype(np.float64) + 0.5) * 254.0).clip(0, 254)
        a = (q[..., 0] + 256.0 * q[..., 1] + 65536.0 * q[..., 2]).astype(np.float32)
        return np.concatenate([o, a[..., None]], axis=-1)

    def level_grid(self, level: int, which: str = "accum") -> np.ndarray:
        """A config level's grid as numpy: (3, res, res, res, 4) float32 (RGB, z, y, x, SH) for
        ``accum`` (what lookups read: its accumulated light plus the coarser cascades' far light),
        ``own`` (its accumulated light alone), ``inj`` or ``last`` (the last iteration's wavefront);
        (res+1, res+1, res+1, 4) for ``gv``."""
        lv = self._levels[level]
        if which == "gv":
            self._gv.gather()
            r1 = lv.res + 1
            return self._gv.array.numpy()[lv.gv_base:lv.gv_base + r1**3].reshape(r1, r1, r1, 4)
        if which == "inj":
            self._inj.gather()
        arr = {"accum": self._lookups(), "own": self._accum, "inj": self._inj.array}.get(which)
        if which == "last":
            arr = self._last_wavefront(level)
        if arr is None:
            raise ValueError(f"unknown grid {which!r}")
        return arr.numpy()[lv.base:lv.base + lv.size].reshape(3, lv.res, lv.res, lv.res, 4)

    def flux(self, level: int, which: str = "last") -> np.ndarray:
        """Total flux (W, RGB) held by a config level's grid: SH_FLUX·Σ DC (the SH integral)."""
        g = self.level_grid(level, which)
        return SH_FLUX * g[..., 0].astype(np.float64).reshape(3, -1).sum(axis=1)

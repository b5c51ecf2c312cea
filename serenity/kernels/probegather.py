"""Ray-traced irradiance probes: the sky volume's probes lit by the sky *and* by the light the scene
bounces, through the real geometry (``SkyConfig.method = "gather"``; beyond the paper, §7–§8). The
sky volume's method that drives them is ``serenity.kernels.skygather.GatherMethod``; the surfels'
and depth moments' host work is ``serenity.kernels.probesurfels``'s.

Why: the paper lights its probes with the sky through occlusion quads and leaves all bounced light
to the light propagation volumes. Measured against path-traced references, the LPV is where the
error sits — it over-lights surfaces next to a bright patch, a lit plane lights itself, light
leaks through thin walls, and it carries one bounce where a courtyard of pale walls or a closed room
gets a third of its indirect light from later ones. Here the probes instead *gather*: each casts
``gather_rays`` rays through the scene's kd-tree once (the geometry is static), and each frame a
probe's radiance along a ray is

    a miss:  the sky map (ω.y ≥ 0) or the ground below the horizon (``SkyVolume.ground_radiance``);
    a hit:   the Lambertian radiance leaving the surface element ("surfel") the ray hit,
             B_s = ρ_s/π · (E_sun · max(0, n_s·l) · V_s + E_volume(p_s, n_s)),

projected onto L2 SH and convolved with the clamped cosine as the sky volume's own probes are
(E_k = Â_l·w_l·4π/R·Σ_i L(ω_i)·Y_k(ω_i)). E_volume is the probe volume itself at the surfel, so
each pass over the volume adds one more bounce of sky and sun light (radiosity by gathering: after
k passes the volume holds k bounces; ``gather_bounces`` passes follow every change of the sun).

The surfels' albedo is the diffuse albedo plus the energy of the material's Phong lobe k_s
(``glossy_energy``, materials that are neither mirrors nor transparent): a lobe as broad as the
built-in scenes' (exponents 8–24) sends its k_s of the light around as a diffuse surface would, and
the reference reflects it. Rays are bent through up to ``transmissions`` transparent interfaces
(``SkyConfig.gather_transmissions``; the window panes: the tracer's ``transmissions``) instead of
stopping on the glass as if it were an opaque diffuse wall.

Surfels: the rays' hit points quantised to cubes of ``gather_surfel_size`` metres (counted from the
corner of the scene's bounding box) and the dominant axis of their normal (so the two faces of a
thin wall are two surfels), each with the mean position, normal and albedo (the tracer's
ray-cone-filtered texture × material albedo) of its hits. V_s is one shadow ray towards the sun's
centre through the kd-tree, from one of the surfel's own hits, the one nearest a point of its square
fixed per surfel (``shadow_origins``: from the centres, which lie on a grid, a straight shadow edge
flipped a whole row at once; from the square's point itself, a surfel at a corner or an edge started
its ray inside the wall beside it or beyond the edge), re-traced when the sky map is rebaked (the
sun moved). Rays that hit a back face (the probe sits inside or under geometry) mark the probe: a
probe with more than ``BACKFACE_LIMIT`` of its rays on back faces is moved by up to half a cell to a
free spot (DDGI's probe relocation, Majercik et al. 2019); its texel stays on the grid. Each probe is
first judged on every ``RELOCATION_STRIDE``-th ray, as a spot to move to is, so that a probe inside
geometry is traced in full only where it moves to (about half of a room's probes next to its
surfaces). Directions:
``DIRECTION_SETS`` spherical Fibonacci sets of R directions, each turned by its own random rotation;
probe p uses set p mod ``DIRECTION_SETS`` (neighbouring probes sample different directions, so the
quantisation of one set does not line up across the volume).

Probes no lookup reads (DDGI's probe classification, Majercik et al. 2021): a lookup at a surface
point reads the 8 probes around it, moved by the normal offset, so a probe whose cells no triangle
comes within that offset of (the air in the middle of a room, 60 % of the breakfast room's probes)
is never read. Those probes are not traced or gathered (``skylookup.reachable_probes``; their coefficients are
zeros); a surfel's own lookup, from its mean position, is checked too.

Costs (``benchmarks/``): the rays are traced once per scene (``ProbeGather._build``), in chunks that
are merged into surfels and depth moments as they come (the hits of every ray never exist at once);
the result is cached on disk, and so are the coefficients after a first lighting's passes
(``converged_path``); a pass is one surfel update (a volume lookup per surfel) and one gather of R
loads per probe.
"""

from __future__ import annotations

import hashlib
import math
import os
from pathlib import Path

import numpy as np
import warp as wp
from tqdm import tqdm

from serenity.kernels.atmosphere_ref import sample_sky_map_np
from serenity.kernels.launch import launch
from serenity.kernels.probesurfels import MomentWeights, SurfelMerge, hit_distances
from serenity.kernels.sh import sh_basis, vec9
from serenity.kernels.skylookup import (
    REACH_PLANE_PROBES,
    VIS_OCT,
    ProbeGrid,
    ProbeVolume,
    lookup_probes,
    volume_irradiance,
)
from serenity.memory import mapped_large_blocks
from serenity.scene.cache import cache_dir
from serenity.scene.model import IDENTITY_UV
from serenity.threads import single_threaded_blas

wp.set_module_options({"enable_backward": False})

# ---------------------------------------------------------------------------------------------
# constants

#: rotated direction sets the probes cycle through (probe index mod this)
DIRECTION_SETS = 8
#: a probe with more than this fraction of its rays on back faces sits inside geometry
BACKFACE_LIMIT = 0.1
#: a relocation spot is judged on every this-many-th ray of the probe's set before it is traced in full
RELOCATION_STRIDE = 8
#: relocation offsets tried for such a probe, in cells (first the one up: probes under a floor)
RELOCATIONS = ((0.0, 0.45, 0.0), (0.45, 0.0, 0.0), (-0.45, 0.0, 0.0), (0.0, 0.0, 0.45), (0.0, 0.0, -0.45),
               (0.0, -0.45, 0.0), (0.3, 0.3, 0.3), (-0.3, 0.3, -0.3))
_INV_PI = wp.constant(1.0 / math.pi)
#: bump when the traced data or its cached layout changes
FORMAT_VERSION = 5
#: traces of at least this many rays are cached on disk (``cache_dir()/probegather-<key>.npz``)
CACHE_MIN_RAYS = 1_000_000
#: rays the probes' trace hands the tracer per call (its G-buffer for those rays is the memory peak)
TRACE_CHUNK_RAYS = 1 << 18
#: a trace of at least this many rays shows a progress bar
PROGRESS_RAYS = 4_000_000
#: a probe ray's distance in the depth moments is capped at VIS_MAX_CELLS cell diagonals (a miss counts as that)
VIS_MAX_CELLS = 2.0
#: the probes the lookups can read (``skylookup.reachable_probes``) are found around the triangles within the
#: lookup's normal offset and this many cells more (rasterised positions, normal-mapped normals)
REACH_MARGIN_CELLS = 0.02
#: rounds of tracing the probes that the surfels' own lookups read beyond the active ones (``ProbeGather``)
_REACH_ROUNDS = 3


# ---------------------------------------------------------------------------------------------
# kernels


@wp.kernel
def surfel_radiance(
    # inputs
    positions: wp.array(dtype=wp.vec3),
    normals: wp.array(dtype=wp.vec3),
    albedo: wp.array(dtype=wp.vec3),
    sun_visible: wp.array(dtype=float),
    sun_dir: wp.vec3,
    sun_irradiance: wp.vec3,
    vol: ProbeVolume,
    # outputs
    radiance: wp.array(dtype=wp.vec3),
    offset: int,
):
    """B_s = ρ_s/π·(E_sun·max(0, n·l)·V_s + E_volume(p_s, n_s)) (module docstring)."""
    i = wp.tid() + offset
    n = normals[i]
    e = volume_irradiance(vol, positions[i], n)
    e += sun_irradiance * (wp.max(wp.dot(n, sun_dir), 0.0) * sun_visible[i])
    radiance[i] = wp.cw_mul(albedo[i], e) * _INV_PI


@wp.kernel
def gather_probes(
    # inputs
    grid: ProbeGrid,
    first_layer: int,
    rays: int,
    active: wp.array(dtype=wp.int32),
    surfel: wp.array2d(dtype=wp.int32),
    surfel_radiance: wp.array(dtype=wp.vec3),
    miss_radiance: wp.array2d(dtype=wp.vec3),
    basis: wp.array2d(dtype=vec9),
    scale: vec9,
    # outputs
    coeffs: wp.array2d(dtype=float),
    offset: int,
):
    """The i-th probe of the y-layers from ``first_layer`` on (x fastest, then z; stored (z, y, x)):
    E_k = scale_k·4π/R·Σ_r L_r·Y_k(ω_r), L_r the radiance of the surfel ray r hit (surfel[p, r] ≥ 0),
    the miss radiance of the probe's direction set (−1), or 0 (−2: a back face); zeros for a probe
    that is not ``active`` (no lookup reads it: ``skylookup.reachable_probes``)."""
    t = wp.tid() + offset
    res_x = grid.res[0]
    res_y = grid.res[1]
    res_z = grid.res[2]
    slab = res_x * res_z
    y = first_layer + t // slab
    rem = t - (t // slab) * slab
    z = rem // res_x
    x = rem - z * res_x
    probe = (z * res_y + y) * res_x + x
    if active[probe] == 0:
        for k in range(27):
            coeffs[probe, k] = 0.0
        return
    s = probe % basis.shape[0]
    acc_r = vec9()
    acc_g = vec9()
    acc_b = vec9()
    for r in range(rays):
        j = surfel[probe, r]
        radiance = wp.vec3()
        if j >= 0:
            radiance = surfel_radiance[j]
        elif j == -1:
            radiance = miss_radiance[s, r]
        b = basis[s, r]
        acc_r += b * radiance[0]
        acc_g += b * radiance[1]
        acc_b += b * radiance[2]
    w = 4.0 * wp.pi / float(rays)
    for k in range(9):
        sk = scale[k] * w
        coeffs[probe, 3 * k + 0] = acc_r[k] * sk
        coeffs[probe, 3 * k + 1] = acc_g[k] * sk
        coeffs[probe, 3 * k + 2] = acc_b[k] * sk


# ---------------------------------------------------------------------------------------------
# host


def scene_key(scene) -> str:
    """Digest of what a probe's traced rays depend on in ``scene``: its merged geometry and its
    materials (albedo, textures, Phong and glass parameters)."""
    h = hashlib.blake2b(digest_size=20)
    for a in scene.merged():
        h.update(np.ascontiguousarray(a).tobytes())
    for m in scene.materials:
        h.update(f"{m.name}|{m.specular}|{m.shininess}|{m.reflectivity}|{m.transparency}|{m.ior}".encode())
        h.update(np.ascontiguousarray(m.albedo, np.float64).tobytes())
        if m.albedo_texture is not None:
            h.update(np.ascontiguousarray(m.albedo_texture.mips[0]).tobytes())
        if m.alpha_tested or m.normal_texture is not None or not np.array_equal(m.albedo_uv_transform, IDENTITY_UV):
            # cut-outs, normal maps and uv transforms change what the rays hit and see (only such
            # scenes' keys change)
            h.update(f"|cutout {m.alpha_tested} {m.alpha} {m.alpha_cutoff} {m.normal_scale}".encode())
            h.update(np.ascontiguousarray(np.concatenate([m.albedo_uv_transform, m.normal_uv_transform])).tobytes())
            if m.normal_texture is not None:
                h.update(np.ascontiguousarray(m.normal_texture.mips[0]).tobytes())
    return h.hexdigest()


def reach_key(reach: float, resolution) -> str:
    """What ``skylookup.reachable_probes`` (and the surfels' check, ``ProbeGather``) depend on beyond the
    scene and the probes' positions: the cache key of a trace whose active probes are made on demand."""
    return f"reach {float(reach)!r} {tuple(int(r) for r in resolution)} {REACH_MARGIN_CELLS!r} " \
           f"{REACH_PLANE_PROBES} {_REACH_ROUNDS}"


def direction_sets(rays: int, sets: int = DIRECTION_SETS, seed: int = 0) -> np.ndarray:
    """(sets, rays, 3) float64 unit directions: a spherical Fibonacci set of ``rays`` points, turned
    by one random rotation per set."""
    i = np.arange(rays) + 0.5
    z = 1.0 - 2.0 * i / rays
    phi = math.pi * (1.0 + math.sqrt(5.0)) * i
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    base = np.stack([r * np.cos(phi), z, r * np.sin(phi)], axis=1)
    rng = np.random.default_rng(seed)
    out = np.empty((sets, rays, 3))
    for k in range(sets):
        q, rr = np.linalg.qr(rng.normal(size=(3, 3)))
        q *= np.sign(np.diag(rr))  # a uniformly random rotation (det may be -1: a reflection is as good)
        out[k] = base @ q.T
    return out


class ProbeGather:
    """The traced rays of one probe grid and the surfels they hit (module docstring).

    The constructor traces (and relocates probes inside geometry); ``set_sky`` and
    ``update_visibility`` follow a new sky and sun; a pass over the volume is ``update_surfels``
    (one more bounce) then ``gather`` of its y-layers into the volume's coefficients."""

    def __init__(self, tracer, positions: np.ndarray, cell: np.ndarray, rays: int, surfel_size: float,
                 device, glossy_energy=None, transmissions: int = 0, cache_key: str | None = None,
                 active=None, grid: tuple | None = None, active_key: str | None = None):
        """``glossy_energy``: per material of the tracer's scene, the albedo its surfels gain from
        its Phong lobe (module docstring), None: none; ``transmissions``: transparent interfaces a
        ray is bent through before the hit it lights the probe with; ``cache_key``: a digest of the
        tracer's scene (geometry and materials), with which a big trace is cached on disk (like the
        kd-tree: ``$SERENITY_CACHE`` or ``~/.cache/serenity``) and read back by the next renderer of
        the same scene and grid; None: no cache. ``active``: (P,) bool, the probes a lookup can read
        (``skylookup.reachable_probes``); only they are traced and gathered, the others hold zeros; None:
        every probe; or a function that returns them, called only when the probes are traced (not
        when they are read from the disk cache), with ``active_key`` a string of everything they
        depend on beyond the scene and the grid (:func:`reach_key`), which the cache key takes
        instead of them. ``grid``: (origin, resolution, normal offset in m) of the volume, with which the
        surfels' own lookups are checked to read active probes only (else those probes are traced too)."""
        self.device = device
        self.rays = int(rays)
        n_probes = len(positions)
        #: (P,) bool: the probes traced and gathered (``active``)
        self._active_fn = None
        if callable(active) and active_key is not None:
            self._active_fn, self.active = active, None
        else:
            self._set_active(active() if callable(active) else active, n_probes)
        self._active_key = active_key if self._active_fn is not None else None
        self.grid = None if grid is None or active is None else grid
        self.tracer = tracer
        self.glossy_energy = None if glossy_energy is None else np.asarray(glossy_energy, np.float32)
        self.transmissions = int(transmissions)
        self.dirs = direction_sets(self.rays)
        self.dirs32 = self.dirs.astype(np.float32)
        self.from_cache = False
        path = None
        #: the trace's cache key (None: not cached), which the converged lighting's key extends
        self.cache_key = None
        if cache_key is not None and len(positions) * self.rays >= CACHE_MIN_RAYS:
            self.cache_key = self._key(cache_key, positions, cell, surfel_size)
            path = cache_dir() / f"probegather-{self.cache_key}.npz"
            self.from_cache = self._load(path, len(positions))
        if not self.from_cache:
            if self.active is None:
                self._set_active(self._active_fn(), len(positions))
            # chunk after chunk of rays: freed, not kept on the heap; the moments' small matrix
            # products on one thread (BLAS's threads only spun beside the tracer's: 5x slower)
            with mapped_large_blocks(), single_threaded_blas():
                self._build(positions, cell, surfel_size)
            if path is not None:
                self._save(path)
        dev = device
        self._basis = wp.array(np.stack([sh_basis(d) for d in self.dirs]).astype(np.float32), dtype=vec9, device=dev)
        self._active = wp.array(self.active.astype(np.int32), dtype=wp.int32, device=dev)
        self._miss = wp.zeros((DIRECTION_SETS, self.rays), dtype=wp.vec3, device=dev)
        self._radiance = wp.zeros(self.surfel_count, dtype=wp.vec3, device=dev)
        self._visible = wp.zeros(self.surfel_count, dtype=float, device=dev)
        self._visible_host = np.zeros(self.surfel_count, np.float32)
        self._vis_sun = np.array([0.0, 1.0, 0.0])
        self._vis_parts, self._vis_left, self._vis_next = 1, 0, 0

    def _set_active(self, active, n_probes: int) -> None:
        self.active = np.ones(n_probes, bool) if active is None else np.asarray(active, bool).reshape(-1).copy()
        if len(self.active) != n_probes:
            raise ValueError(f"active: {len(self.active)} flags for {n_probes} probes")

    def _trace_chunks(self, origins: np.ndarray, sets: np.ndarray, progress: bool = False):
        """The rays of the given probes (their direction sets) in chunks of about ``TRACE_CHUNK_RAYS``
        (the tracer's G-buffer for those rays is the memory peak): yields (first probe, last probe + 1,
        hits) per chunk, hits a dict of the chunk's rays (probe-major): hit mask (front faces),
        back-face mask, position, shading normal (facing the ray) and albedo (+ the Phong lobe's
        energy), float32 (a tqdm bar for big jobs)."""
        n, r = len(origins), self.rays
        total = n * r
        per = max(1, TRACE_CHUNK_RAYS // r)
        bar = tqdm(total=total, desc=f"probe rays ({n:,} probes x {r})", unit="ray", unit_scale=True,
                   leave=False, disable=not (progress and total >= PROGRESS_RAYS))
        for a in range(0, n, per):
            b = min(n, a + per)
            o = np.repeat(origins[a:b].astype(np.float32), r, axis=0)
            d = self.dirs32[sets[a:b]].reshape(-1, 3)
            g = self.tracer.trace(o, d, 0.0, 0.0, backfaces=True, transmissions=self.transmissions)
            del o, d
            back = g.pop("backface")
            albedo = g["albedo"][:, :3]
            if self.glossy_energy is not None and len(self.glossy_energy):
                material = np.clip(np.rint(g["albedo"][:, 3]).astype(np.int32), 0, len(self.glossy_energy) - 1)
                albedo = albedo + self.glossy_energy[material][:, None]
            hits = {"hit": (g["position"][:, 3] > 0) & ~back, "back": back,
                    "position": np.ascontiguousarray(g["position"][:, :3]),
                    "normal": np.ascontiguousarray(g["normal"][:, :3]), "albedo": np.ascontiguousarray(albedo)}
            del g
            bar.update(len(back))
            yield a, b, hits
        bar.close()

    def _build(self, positions, cell, surfel_size) -> None:
        """Trace the active probes' rays, move probes out of geometry, merge the hits into surfels and
        the distances into depth moments, chunk by chunk: the hits of every ray at once (14M rays of a
        262k-triangle room: half a GB, and as much again to merge them) never exist. Where a surfel's
        own lookup reads a probe that is not active (its mean lies off the triangles), that probe is
        made active and traced too (``_REACH_ROUNDS`` rounds at most)."""
        n_probes, r = len(positions), self.rays
        s = np.arange(n_probes) % DIRECTION_SETS
        cell = np.asarray(cell, np.float64)
        origins = np.asarray(positions, np.float64).copy()
        cap = VIS_MAX_CELLS * float(np.linalg.norm(cell))
        self.moments = np.empty((n_probes, VIS_OCT * VIS_OCT, 2), np.float32)
        self.moments[~self.active] = (cap, cap * cap)  # no lookup reads them: as if every ray missed
        merge = SurfelMerge(n_probes * r, self._surfel_anchor(), surfel_size)
        merge.surfel.reshape(n_probes, r)[~self.active] = -2  # not traced: no light (the gather skips them)
        weights = MomentWeights(self.dirs32)
        bad = np.zeros(n_probes, bool)  # probes with too many back faces: merged once their place is settled
        self.relocated = 0

        def merge_probes(probes, hits, rays):  # the probes' rays (a mask of the chunk's) into the surfels
            hits = {k: v[rays] for k, v in hits.items()}
            rows = (probes[:, None] * r + np.arange(r)).reshape(-1)
            merge.add(rows, *(hits[k] for k in ("hit", "back", "position", "normal", "albedo")))
            self.moments[probes] = weights.moments(hit_distances(hits, origins[probes], r, cap), s[probes])

        def trace(act):  # the probes ``act`` (sorted indices) traced, relocated where needed, merged
            # first judged on every RELOCATION_STRIDE-th ray, as a relocation spot is: a probe inside
            # geometry (most of a room's probes next to its surfaces, or under its floor) is not traced
            # in full where it is, only where it moves to
            pre = self._backface_fraction(origins[act], s[act]) > BACKFACE_LIMIT
            bad[act[pre]] = True
            act = act[~pre]
            for a, b, hits in self._trace_chunks(origins[act], s[act], progress=True):
                probes = act[a:b]
                first_bad = hits["back"].reshape(b - a, r).mean(axis=1) > BACKFACE_LIMIT
                bad[probes] = first_bad
                for i in np.flatnonzero(first_bad):
                    hits["hit"][i * r:(i + 1) * r] = False
                    hits["back"][i * r:(i + 1) * r] = False
                rows = slice(probes[0] * r, (probes[-1] + 1) * r) if probes[-1] - probes[0] == b - a - 1 else \
                    (probes[:, None] * r + np.arange(r)).reshape(-1)
                merge.add(rows, *(hits[k] for k in ("hit", "back", "position", "normal", "albedo")))
                self.moments[probes] = weights.moments(hit_distances(hits, origins[probes], r, cap), s[probes])
                del hits
            for off in RELOCATIONS:  # probes inside geometry: try a free spot nearby
                if not bad.any():
                    break
                idx = np.nonzero(bad)[0]
                cand = origins[idx] + np.asarray(off) * cell
                # judged on every RELOCATION_STRIDE-th ray of the set (a spread subset of the spherical
                # Fibonacci points), then traced in full only where the spot is free
                ok = self._backface_fraction(cand, s[idx]) <= BACKFACE_LIMIT
                if not ok.any():
                    continue
                idx, cand = idx[ok], cand[ok]
                for a, b, hits in self._trace_chunks(cand, s[idx]):
                    keep = hits["back"].reshape(b - a, r).mean(axis=1) <= BACKFACE_LIMIT
                    take = idx[a:b][keep]
                    origins[take] = cand[a:b][keep]
                    merge_probes(take, hits, np.repeat(keep, r))
                    bad[take] = False
                    self.relocated += len(take)
                    del hits
            if bad.any():  # no free spot found: kept, their back-face hits count as misses, traced again
                idx = np.flatnonzero(bad)  # where they are (cheaper than keeping every bad probe's first rays)
                self.inside += len(idx)
                for a, b, hits in self._trace_chunks(origins[idx], s[idx]):
                    merge_probes(idx[a:b], hits, np.ones((b - a) * r, bool))
                    del hits
                bad[idx] = False

        self.inside = 0
        todo = np.flatnonzero(self.active)
        for _ in range(_REACH_ROUNDS):
            if len(todo):
                trace(todo)
            if self.grid is None:
                break
            sp, sn = merge.means()
            origin, resolution, offset = self.grid
            read = np.zeros(n_probes, bool)
            read[lookup_probes(sp + offset * sn, origin, cell, resolution).reshape(-1)] = True
            todo = np.flatnonzero(read & ~self.active)
            if not len(todo):
                break
            self.active[todo] = True
            merge.surfel.reshape(n_probes, r)[todo] = -1
        self.offsets = (origins - np.asarray(positions, np.float64)).astype(np.float32)
        surfel, sp, sn, sa, sv = merge.finish()
        self._set_surfels(surfel.reshape(-1, r), sp, sn, sa, sv)

    def _surfel_anchor(self) -> np.ndarray:
        """(3,) float64 the corner the surfels' cubes are counted from: the scene's bounding box's
        (every hit lies inside it, and it is known before the first ray is traced)."""
        bounds = getattr(self.tracer, "bounds", None)
        return np.zeros(3) if bounds is None else np.asarray(bounds[0], np.float64)

    # -- the disk cache

    _CACHED = ("surfel", "surfel_positions", "surfel_normals", "surfel_albedo", "surfel_shadow_origins", "moments",
               "offsets", "active")

    def _key(self, scene_key: str, positions, cell, surfel_size) -> str:
        h = hashlib.blake2b(digest_size=20)
        h.update(f"probegather-v{FORMAT_VERSION}|{scene_key}|{self.rays}|{self.transmissions}|{surfel_size!r}|"
                 f"{DIRECTION_SETS}|{BACKFACE_LIMIT}|{RELOCATIONS}|{RELOCATION_STRIDE}".encode())
        for a in (np.asarray(positions, np.float64), np.asarray(cell, np.float64),
                  np.zeros(0) if self.glossy_energy is None else self.glossy_energy,
                  self.active if self._active_key is None else np.frombuffer(self._active_key.encode(), np.uint8)):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()

    def _save(self, path: Path) -> None:
        """Write the traced data (an ``.npz`` of plain arrays); an unwritable cache is ignored."""
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
            np.savez(tmp, surfel=self._surfel.numpy(), surfel_positions=self.surfel_positions,
                     surfel_normals=self.surfel_normals, surfel_albedo=self.surfel_albedo,
                     surfel_shadow_origins=self.surfel_shadow_origins, moments=self.moments,
                     offsets=self.offsets, active=self.active,
                     meta=np.array([FORMAT_VERSION, self.relocated, self.inside], np.int64))
            os.replace(tmp, path)
        except OSError:
            pass  # an unwritable cache only costs a trace next time

    def _load(self, path: Path, n_probes: int) -> bool:
        """Read the traced data cached at ``path``; False when absent, unreadable or stale."""
        if not path.is_file():
            return False
        try:
            with np.load(path, allow_pickle=False) as z:
                a = {k: np.array(z[k]) for k in self._CACHED}
                meta = z["meta"].tolist()
        except (OSError, ValueError, KeyError, EOFError):
            return False
        m = len(a["surfel_positions"])
        if (len(meta) != 3 or meta[0] != FORMAT_VERSION or a["surfel"].shape != (n_probes, self.rays)
                or a["surfel"].max(initial=-1) >= m or a["moments"].shape != (n_probes, VIS_OCT * VIS_OCT, 2)
                or a["offsets"].shape != (n_probes, 3) or a["active"].shape != (n_probes,)
                or (self.active is not None and np.any(self.active & ~a["active"].astype(bool)))
                or a["surfel_shadow_origins"].shape != (m, 3)):
            return False
        self.relocated, self.inside = int(meta[1]), int(meta[2])
        self.moments, self.offsets, self.active = a["moments"], a["offsets"], a["active"].astype(bool)
        self._set_surfels(a["surfel"], a["surfel_positions"], a["surfel_normals"], a["surfel_albedo"],
                          a["surfel_shadow_origins"])
        return True

    # -- the converged lighting (the passes of a volume lit for the first time)

    def converged_path(self, *inputs) -> Path | None:
        """Where the coefficients after every pass of a first lighting are cached, keyed by the trace's
        key and everything else they depend on (``inputs``: arrays and numbers — the sky map, the
        ground and the sun, the grid, the passes); None where the trace is not cached. A renderer
        started again on the same scene, sky and sun reads them instead of running the passes
        (the breakfast room's 21 passes until converged: seconds of its warm start)."""
        if self.cache_key is None:
            return None
        h = hashlib.blake2b(digest_size=20)
        h.update(f"converged-v{FORMAT_VERSION}|{self.cache_key}|{len(inputs)}".encode())
        for a in inputs:
            a = np.ascontiguousarray(a)
            h.update(f"|{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())
        return cache_dir() / f"probegather-lit-{h.hexdigest()}.npy"

    @staticmethod
    def load_converged(path: Path | None, coeffs) -> bool:
        """Read the cached coefficients at ``path`` into the Warp array ``coeffs``; False when absent,
        unreadable or of another shape."""
        if path is None or not path.is_file():
            return False
        try:
            a = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError):
            return False
        if a.shape != tuple(coeffs.shape) or a.dtype != np.float32 or not np.all(np.isfinite(a)):
            return False
        coeffs.assign(a)
        return True

    @staticmethod
    def save_converged(path: Path | None, coeffs) -> None:
        """Cache the coefficients (the Warp array ``coeffs``) at ``path``; an unwritable cache is ignored."""
        if path is None:
            return
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npy")
            np.save(tmp, coeffs.numpy().astype(np.float32))
            os.replace(tmp, path)
        except OSError:
            pass

    def _backface_fraction(self, origins: np.ndarray, sets: np.ndarray) -> np.ndarray:
        """(N,) fraction of back-face hits over every ``RELOCATION_STRIDE``-th ray of each probe's set."""
        sub = self.dirs32[:, ::RELOCATION_STRIDE]
        r = sub.shape[1]
        out = np.empty(len(origins))
        per = max(1, TRACE_CHUNK_RAYS // r)
        for a in range(0, len(origins), per):  # chunks of about TRACE_CHUNK_RAYS (the tracer's G-buffer)
            o = np.repeat(origins[a:a + per].astype(np.float32), r, axis=0)
            d = sub[sets[a:a + per]].reshape(-1, 3)
            g = self.tracer.trace(o, d, 0.0, 0.0, backfaces=True, transmissions=self.transmissions)
            out[a:a + per] = g["backface"].reshape(-1, r).mean(axis=1)
        return out

    def _set_surfels(self, surfel, sp, sn, sa, sv) -> None:
        """The surfel each ray hit ((P, R) int32: ≥ 0, −1 a miss, −2 a back face) and the surfels'
        mean positions, normals and albedo and their shadow rays' origins ((S, 3) each)."""
        self.surfel_count = len(sp)
        self.surfel_positions, self.surfel_normals, self.surfel_albedo = sp, sn, sa
        self.surfel_shadow_origins = np.asarray(sv, np.float64)
        dev = self.device
        self._surfel = wp.array(np.ascontiguousarray(surfel, np.int32), dtype=wp.int32, device=dev)
        self._sp = wp.array(sp.astype(np.float32), dtype=wp.vec3, device=dev)
        self._sn = wp.array(sn.astype(np.float32), dtype=wp.vec3, device=dev)
        self._sa = wp.array(sa.astype(np.float32), dtype=wp.vec3, device=dev)

    def update_visibility(self, sun_direction, parts: int = 1) -> None:
        """V_s towards a new sun: one shadow ray per surfel (from just off the surfel, at its own hit
        nearest its point of the surfel's square: ``shadow_origins``), all of them
        now (``parts`` = 1) or in ``parts`` slices, the first now and one per :meth:`refresh_visibility`
        (the slices continue the cycle where it stood: under a sun that moves every frame each surfel
        is re-traced once every ``parts`` frames, against the newest sun)."""
        sun = np.asarray(sun_direction, np.float64)
        self._vis_sun = sun / max(np.linalg.norm(sun), 1e-12)
        self._vis_parts = max(1, int(parts))
        self._vis_left = self._vis_parts
        self.refresh_visibility()

    def refresh_visibility(self) -> bool:
        """Re-trace the next slice of surfels against the sun of the last :meth:`update_visibility`,
        if any are still to do; returns whether it traced."""
        m = self.surfel_count
        if self._vis_left <= 0 or m == 0:
            self._vis_left = 0
            return False
        n = -(-m // self._vis_parts)
        a = self._vis_next if self._vis_parts > 1 else 0
        b = min(m, a + n)
        sun = self._vis_sun
        eps = self.tracer.ray_epsilon
        o = (self.surfel_shadow_origins[a:b] + self.surfel_normals[a:b] * (4 * eps)).astype(np.float32)
        d = np.broadcast_to(sun.astype(np.float32), o.shape)
        occ = self.tracer.tree.occluded(o, d, tmin=eps)
        self._visible_host[a:b] = (~occ).astype(np.float32) * (self.surfel_normals[a:b] @ sun > 0)
        self._visible.assign(self._visible_host)
        self._vis_next = b % m
        self._vis_left -= 1
        return True

    def set_sky(self, sky_map: np.ndarray, ground: np.ndarray) -> None:
        """The miss radiance of every direction: the sky map above the horizon, the ground below."""
        d = self.dirs.reshape(-1, 3)
        out = np.empty((len(d), 3))
        up = d[:, 1] >= 0
        out[up] = sample_sky_map_np(sky_map, d[up])
        out[~up] = np.asarray(ground, np.float64)
        self._miss.assign(out.reshape(DIRECTION_SETS, self.rays, 3).astype(np.float32))

    def update_surfels(self, volume: ProbeVolume, sun_direction, sun_irradiance) -> None:
        """B_s of every surfel from the volume as it is now (one more bounce): ``volume`` the lookup's
        data (``skylookup.ProbeVolume``), the sun's direction and irradiance (3,) W·m⁻²."""
        if self.surfel_count == 0:
            return
        sun = np.asarray(sun_direction, np.float64)
        sun = sun / max(np.linalg.norm(sun), 1e-12)
        launch(surfel_radiance, self.surfel_count,
               [self._sp, self._sn, self._sa, self._visible, wp.vec3(*sun.astype(np.float32)),
                wp.vec3(*np.asarray(sun_irradiance, np.float32)), volume, self._radiance], device=self.device)

    def gather(self, grid: ProbeGrid, coeffs, scale, first_layer: int, layers: int) -> None:
        """The probes of y-layers ``first_layer .. first_layer + layers - 1`` of ``grid`` gathered into
        ``coeffs`` (P, 27), each coefficient times ``scale`` (the volume's window)."""
        x, _, z = grid.res
        launch(gather_probes, layers * int(x) * int(z),
               [grid, int(first_layer), self.rays, self._active, self._surfel, self._radiance, self._miss,
                self._basis, scale, coeffs], device=self.device)

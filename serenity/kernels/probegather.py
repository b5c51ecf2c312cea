"""Ray-traced irradiance probes: the sky volume's probes lit by the sky *and* by the light the scene
bounces, through the real geometry (``SkyConfig.method = "gather"``; beyond the paper, §7–§8).

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

Surfels: the rays' hit points quantised to cubes of ``gather_surfel_size`` metres and the dominant
axis of their normal (so the two faces of a thin wall are two surfels), each with the mean position,
normal and albedo (the tracer's ray-cone-filtered texture × material albedo) of its hits. V_s is
one shadow ray from the surfel towards the sun's centre through the kd-tree, re-traced when the sky
map is rebaked (the sun moved). Rays that hit a back face (the probe sits inside or under geometry)
mark the probe: a probe with more than ``BACKFACE_LIMIT`` of its rays on back faces is moved by up
to half a cell to a free spot (DDGI's probe relocation, Majercik et al. 2019); its texel stays on
the grid. Directions: ``DIRECTION_SETS`` spherical Fibonacci sets of R directions, each turned by its
own random rotation; probe p uses set p mod ``DIRECTION_SETS`` (neighbouring probes sample
different directions, so the quantisation of one set does not line up across the volume).

Costs (``benchmarks/``): the rays are traced once per scene (``ProbeGather.build``); a pass is one
surfel update (a volume lookup per surfel) and one gather of R loads per probe.
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
from serenity.kernels.kdtree_build import cache_dir
from serenity.kernels.launch import launch
from serenity.kernels.sh import eval_sh9, sh_basis, vec9

wp.set_module_options({"enable_backward": False})

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
FORMAT_VERSION = 1
#: traces of at least this many rays are cached on disk (``cache_dir()/probegather-<key>.npz``)
CACHE_MIN_RAYS = 1_000_000
#: rays the probes' trace hands the tracer per call (its G-buffer for those rays is the memory peak)
TRACE_CHUNK_RAYS = 1 << 20
#: a trace of at least this many rays shows a progress bar
PROGRESS_RAYS = 4_000_000

#: beyond the grid's sides and top, the lookup fades to the open sky's coefficients over this many cells
OPEN_FADE_CELLS = 2.0


@wp.func
def volume_irradiance(coeffs: wp.array2d(dtype=float), open_sky: wp.array(dtype=float), origin: wp.vec3,
                      cell: wp.vec3, res_x: int, res_y: int, res_z: int, normal_offset: float, p: wp.vec3,
                      n: wp.vec3) -> wp.vec3:
    """Irradiance of the volume at a surface point (sky.glsl's arithmetic): trilinear coefficients
    at p + offset·n, faded to ``open_sky`` (27, the open sky's) beyond the grid's sides and top,
    evaluated at n, clamped at 0."""
    gr = wp.cw_div(p + n * normal_offset - origin, cell)
    beyond = wp.max(wp.max(wp.max(-gr[0], gr[0] - float(res_x - 1)), wp.max(-gr[2], gr[2] - float(res_z - 1))),
                    gr[1] - float(res_y - 1))
    w_open = wp.clamp(beyond / OPEN_FADE_CELLS, 0.0, 1.0)
    g = wp.vec3(wp.clamp(gr[0], 0.0, float(res_x - 1)), wp.clamp(gr[1], 0.0, float(res_y - 1)),
                wp.clamp(gr[2], 0.0, float(res_z - 1)))
    x0 = int(wp.floor(g[0]))
    y0 = int(wp.floor(g[1]))
    z0 = int(wp.floor(g[2]))
    ax = g[0] - float(x0)
    ay = g[1] - float(y0)
    az = g[2] - float(z0)
    y = eval_sh9(n)
    e = wp.vec3()
    for corner in range(8):
        dx = corner & 1
        dy = (corner >> 1) & 1
        dz = corner >> 2
        xi = wp.min(x0 + dx, res_x - 1)
        yi = wp.min(y0 + dy, res_y - 1)
        zi = wp.min(z0 + dz, res_z - 1)
        w = wp.where(dx == 1, ax, 1.0 - ax) * wp.where(dy == 1, ay, 1.0 - ay) * wp.where(dz == 1, az, 1.0 - az)
        probe = (zi * res_y + yi) * res_x + xi
        for k in range(9):
            wk = w * y[k]
            e += wp.vec3(coeffs[probe, 3 * k], coeffs[probe, 3 * k + 1], coeffs[probe, 3 * k + 2]) * wk
    e_open = wp.vec3()
    for k in range(9):
        e_open += wp.vec3(open_sky[3 * k], open_sky[3 * k + 1], open_sky[3 * k + 2]) * y[k]
    e = e * (1.0 - w_open) + e_open * w_open
    return wp.vec3(wp.max(e[0], 0.0), wp.max(e[1], 0.0), wp.max(e[2], 0.0))


@wp.kernel
def surfel_radiance(
    # inputs
    positions: wp.array(dtype=wp.vec3),
    normals: wp.array(dtype=wp.vec3),
    albedo: wp.array(dtype=wp.vec3),
    sun_visible: wp.array(dtype=float),
    sun_dir: wp.vec3,
    sun_irradiance: wp.vec3,
    coeffs: wp.array2d(dtype=float),
    open_sky: wp.array(dtype=float),
    origin: wp.vec3,
    cell: wp.vec3,
    res_x: int,
    res_y: int,
    res_z: int,
    normal_offset: float,
    # outputs
    radiance: wp.array(dtype=wp.vec3),
    offset: int,
):
    """B_s = ρ_s/π·(E_sun·max(0, n·l)·V_s + E_volume(p_s, n_s)) (module docstring)."""
    i = wp.tid() + offset
    n = normals[i]
    e = volume_irradiance(coeffs, open_sky, origin, cell, res_x, res_y, res_z, normal_offset, positions[i], n)
    e += sun_irradiance * (wp.max(wp.dot(n, sun_dir), 0.0) * sun_visible[i])
    radiance[i] = wp.cw_mul(albedo[i], e) * _INV_PI


@wp.kernel
def gather_probes(
    # inputs
    res_x: int,
    res_y: int,
    first_layer: int,
    rays: int,
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
    the miss radiance of the probe's direction set (−1), or 0 (−2: a back face)."""
    t = wp.tid() + offset
    res_z = surfel.shape[0] // (res_x * res_y)
    slab = res_x * res_z
    y = first_layer + t // slab
    rem = t - (t // slab) * slab
    z = rem // res_x
    x = rem - z * res_x
    probe = (z * res_y + y) * res_x + x
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
    return h.hexdigest()


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
                 device, glossy_energy=None, transmissions: int = 0, cache_key: str | None = None):
        """``glossy_energy``: per material of the tracer's scene, the albedo its surfels gain from
        its Phong lobe (module docstring), None: none; ``transmissions``: transparent interfaces a
        ray is bent through before the hit it lights the probe with; ``cache_key``: a digest of the
        tracer's scene (geometry and materials), with which a big trace is cached on disk (like the
        kd-tree: ``$SERENITY_CACHE`` or ``~/.cache/serenity``) and read back by the next renderer of
        the same scene and grid; None: no cache."""
        self.device = device
        self.rays = int(rays)
        self.tracer = tracer
        self.glossy_energy = None if glossy_energy is None else np.asarray(glossy_energy, np.float32)
        self.transmissions = int(transmissions)
        self.dirs = direction_sets(self.rays)
        self.from_cache = False
        path = None
        if cache_key is not None and len(positions) * self.rays >= CACHE_MIN_RAYS:
            path = cache_dir() / f"probegather-{self._key(cache_key, positions, cell, surfel_size)}.npz"
            self.from_cache = self._load(path, len(positions))
        if not self.from_cache:
            self._build(positions, cell, surfel_size)
            if path is not None:
                self._save(path)
        dev = device
        self._basis = wp.array(np.stack([sh_basis(d) for d in self.dirs]).astype(np.float32), dtype=vec9, device=dev)
        self._miss = wp.zeros((DIRECTION_SETS, self.rays), dtype=wp.vec3, device=dev)
        self._radiance = wp.zeros(self.surfel_count, dtype=wp.vec3, device=dev)
        self._visible = wp.zeros(self.surfel_count, dtype=float, device=dev)
        self._visible_host = np.zeros(self.surfel_count, np.float32)
        self._vis_sun = np.array([0.0, 1.0, 0.0])
        self._vis_parts, self._vis_left, self._vis_next = 1, 0, 0

    def _trace(self, origins: np.ndarray, sets: np.ndarray, progress: bool = False) -> dict:
        """Rays of the given probes (their direction sets): hit mask (front faces), back-face mask,
        position, shading normal (facing the ray) and albedo (+ the Phong lobe's energy) per ray,
        flattened (probe-major), float32. Traced in chunks of about ``TRACE_CHUNK_RAYS`` so that the
        tracer's full G-buffer never exists for all the rays at once (a tqdm bar for big jobs)."""
        n, r = len(origins), self.rays
        total = n * r
        out = {"hit": np.zeros(total, bool), "back": np.zeros(total, bool),
               "position": np.empty((total, 3), np.float32), "normal": np.empty((total, 3), np.float32),
               "albedo": np.empty((total, 3), np.float32)}
        per = max(1, TRACE_CHUNK_RAYS // r)
        bar = tqdm(total=total, desc=f"probe rays ({n:,} probes x {r})", unit="ray", unit_scale=True,
                   leave=False, disable=not (progress and total >= PROGRESS_RAYS))
        for a in range(0, n, per):
            b = min(n, a + per)
            o = np.repeat(origins[a:b], r, axis=0).astype(np.float32)
            d = self.dirs[sets[a:b]].reshape(-1, 3).astype(np.float32)
            g = self.tracer.trace(o, d, 0.0, 0.0, backfaces=True, transmissions=self.transmissions)
            rows = slice(a * r, b * r)
            back = g["backface"]
            out["back"][rows] = back
            out["hit"][rows] = (g["position"][:, 3] > 0) & ~back
            out["position"][rows] = g["position"][:, :3]
            out["normal"][rows] = g["normal"][:, :3]
            albedo = g["albedo"][:, :3]
            if self.glossy_energy is not None and len(self.glossy_energy):
                material = np.clip(np.rint(g["albedo"][:, 3]).astype(np.int64), 0, len(self.glossy_energy) - 1)
                albedo = albedo + self.glossy_energy[material][:, None]
            out["albedo"][rows] = albedo
            bar.update(len(o))
        bar.close()
        out["backface_fraction"] = out["back"].reshape(n, r).mean(axis=1)
        return out

    def _build(self, positions, cell, surfel_size) -> None:
        """Trace the probes' rays, move probes out of geometry, merge the hits into surfels."""
        n_probes = len(positions)
        s = np.arange(n_probes) % DIRECTION_SETS
        cell = np.asarray(cell, np.float64)
        origins = np.asarray(positions, np.float64).copy()
        hits = self._trace(origins, s, progress=True)
        bad = hits["backface_fraction"] > BACKFACE_LIMIT
        self.relocated = 0
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
            h2 = self._trace(cand, s[idx])
            keep = h2["backface_fraction"] <= BACKFACE_LIMIT
            take = idx[keep]
            origins[take] = cand[keep]
            for k in ("hit", "back", "position", "normal", "albedo"):
                hits[k].reshape(n_probes, self.rays, -1)[take] = h2[k].reshape(len(idx), self.rays, -1)[keep]
            self.relocated += int(keep.sum())
            bad[take] = False
        self.inside = int(bad.sum())  # no free spot found: kept, their back-face hits count as misses
        self._make_surfels(hits, surfel_size)

    # -- the disk cache

    _CACHED = ("surfel", "surfel_positions", "surfel_normals", "surfel_albedo")

    def _key(self, scene_key: str, positions, cell, surfel_size) -> str:
        h = hashlib.blake2b(digest_size=20)
        h.update(f"probegather-v{FORMAT_VERSION}|{scene_key}|{self.rays}|{self.transmissions}|{surfel_size!r}|"
                 f"{DIRECTION_SETS}|{BACKFACE_LIMIT}|{RELOCATIONS}|{RELOCATION_STRIDE}".encode())
        for a in (np.asarray(positions, np.float64), np.asarray(cell, np.float64),
                  np.zeros(0) if self.glossy_energy is None else self.glossy_energy):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()

    def _save(self, path: Path) -> None:
        """Write the traced data (an ``.npz`` of plain arrays); an unwritable cache is ignored."""
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
            np.savez(tmp, surfel=self._surfel.numpy(), surfel_positions=self.surfel_positions,
                     surfel_normals=self.surfel_normals, surfel_albedo=self.surfel_albedo,
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
                or a["surfel"].max(initial=-1) >= m):
            return False
        self.relocated, self.inside = int(meta[1]), int(meta[2])
        self._set_surfels(a["surfel"], a["surfel_positions"], a["surfel_normals"], a["surfel_albedo"])
        return True

    def _backface_fraction(self, origins: np.ndarray, sets: np.ndarray) -> np.ndarray:
        """(N,) fraction of back-face hits over every ``RELOCATION_STRIDE``-th ray of each probe's set."""
        sub = self.dirs[:, ::RELOCATION_STRIDE]
        r = sub.shape[1]
        o = np.repeat(origins, r, axis=0).astype(np.float32)
        d = sub[sets].reshape(-1, 3).astype(np.float32)
        g = self.tracer.trace(o, d, 0.0, 0.0, backfaces=True, transmissions=self.transmissions)
        return g["backface"].reshape(len(origins), r).mean(axis=1)

    def _make_surfels(self, hits: dict, size: float) -> None:
        hit = hits["hit"]
        idx = np.flatnonzero(hit)
        pos, nrm = hits["position"][idx], hits["normal"][idx]
        axis = np.argmax(np.abs(nrm), axis=1)
        side = nrm[np.arange(len(idx)), axis] > 0
        key = axis * 2 + side  # the cube's index and the normal's dominant axis and sign, one int64
        if len(idx):
            base = pos.min(axis=0)
            for c, prime in ((2, 1), (1, 1_000_033), (0, 1_000_033 * 1_000_003)):
                key = key + np.floor((pos[:, c] - base[c]) / size).astype(np.int64) * (6 * prime)
        uniq, inv = np.unique(key, return_inverse=True)
        del key
        m = len(uniq)
        cnt = np.maximum(np.bincount(inv, minlength=m), 1).astype(np.float64)[:, None]

        def mean(a):
            return np.stack([np.bincount(inv, a[:, c], m) for c in range(3)], axis=1) / cnt

        sp, sn, sa = mean(pos), mean(nrm), mean(hits["albedo"][idx])
        sn /= np.maximum(np.linalg.norm(sn, axis=1, keepdims=True), 1e-12)
        surfel = np.full(len(hit), -1, np.int32)
        surfel[idx] = inv.astype(np.int32)
        surfel[hits["back"]] = -2  # a back face: no light (a probe kept inside geometry)
        self._set_surfels(surfel.reshape(-1, self.rays), sp, sn, sa)

    def _set_surfels(self, surfel, sp, sn, sa) -> None:
        """The surfel each ray hit ((P, R) int32: ≥ 0, −1 a miss, −2 a back face) and the surfels'
        mean positions, normals and albedo ((S, 3) each)."""
        self.surfel_count = len(sp)
        self.surfel_positions, self.surfel_normals, self.surfel_albedo = sp, sn, sa
        dev = self.device
        self._surfel = wp.array(np.ascontiguousarray(surfel, np.int32), dtype=wp.int32, device=dev)
        self._sp = wp.array(sp.astype(np.float32), dtype=wp.vec3, device=dev)
        self._sn = wp.array(sn.astype(np.float32), dtype=wp.vec3, device=dev)
        self._sa = wp.array(sa.astype(np.float32), dtype=wp.vec3, device=dev)

    def update_visibility(self, sun_direction, parts: int = 1) -> None:
        """V_s towards a new sun: one shadow ray per surfel (from just off the surfel), all of them
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
        o = (self.surfel_positions[a:b] + self.surfel_normals[a:b] * (4 * eps)).astype(np.float32)
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

    def update_surfels(self, coeffs, open_sky, grid, sun_direction, sun_irradiance) -> None:
        """B_s of every surfel from the volume as it is now (one more bounce); ``open_sky``: the (27,)
        Warp array of the open sky's coefficients beyond the grid."""
        origin, cell, res, offset = grid
        if self.surfel_count == 0:
            return
        sun = np.asarray(sun_direction, np.float64)
        sun = sun / max(np.linalg.norm(sun), 1e-12)
        launch(surfel_radiance, self.surfel_count,
               [self._sp, self._sn, self._sa, self._visible, wp.vec3(*sun.astype(np.float32)),
                wp.vec3(*np.asarray(sun_irradiance, np.float32)), coeffs, open_sky, wp.vec3(*origin.astype(np.float32)),
                wp.vec3(*cell.astype(np.float32)), int(res[0]), int(res[1]), int(res[2]), float(offset),
                self._radiance], device=self.device)

    def gather(self, coeffs, scale, resolution, first_layer: int, layers: int) -> None:
        """The probes of y-layers ``first_layer .. first_layer + layers - 1`` gathered into ``coeffs``."""
        x, y, z = resolution
        launch(gather_probes, layers * x * z,
               [int(x), int(y), int(first_layer), self.rays, self._surfel, self._radiance, self._miss, self._basis,
                scale, coeffs], device=self.device)

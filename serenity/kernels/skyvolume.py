"""The sky lighting irradiance volume (paper §7, Fig. 6–9): L2 SH irradiance probes lit by the sky map,
by one of three methods (``SkyConfig.method``, :mod:`serenity.kernels.skymethod`).

Grid: probes at ``grid_origin + (x, y, z)·cell_size`` for x < X, y < Y, z < Z (``resolution`` =
(X, Y, Z)), fitted to the scene's bounds (centred on them). The cell is cubic,
``SkyConfig.cell_size`` metres, or by default chosen from the scene's scale so that the
bounds hold about ``target_probes`` = 32·16·23 probes (the paper's reference volume);
``resolution=(X, Y, Z)`` instead fits exactly that many probes to the bounds (per-axis cells).
A **layer** is one y slice (X·Z probes; the paper's 32×16×23 volume has 16 layers).

Methods (each a :class:`~serenity.kernels.skymethod.SkyVolumeMethod`, picked by :func:`sky_method`):
``"layers"`` (``skylayers``: the paper's rays against the occlusion quads, one layer per update),
``"transfer"`` (``skytransfer``: the quads' visibility integrated once into per-probe transfer
matrices, every probe re-lit from a new sky at once) and ``"gather"`` (``skygather`` and
``probegather``: the traced probes, rays through the kd-tree lit by the sky and the scene's bounced
light). Every method's probe sees, along an unoccluded ray, the sky map above the horizon and below
it the ground, a Lambertian plane of albedo ``ground_albedo`` lit by the sky only:
L_g = ρ_g/π·E_sky↓ (``ground_radiance``; E_sky↓ = the map's irradiance on a horizontal surface; the
sun's bounce off the ground is left to the light propagation volumes; ρ_g = 0 gives a black lower
hemisphere, ρ_g = 1 with a constant sky is the white furnace, E = π·L for every normal), projected
onto real L2 SH and convolved with the clamped cosine and windowed: E_k = Â_l·w_l·L_k (the
**irradiance coefficients**, W·m⁻²). A constant sky is supported (``Sky.model == "constant"``: the
map holds ``Sky.radiance``).

Storage (paper §7: "six RGBA textures and one RGB texture"): 27 float32 per probe, coefficient-
major, flat index f = 3k + c (k the SH index 0..8, c the RGB channel); texture t < 6 holds
f = 4t..4t+3 in RGBA, texture 6 holds f = 24..26 in RGB. ``textures()`` returns them as 7 numpy
arrays (Z, Y, X, 4) ×6 + (Z, Y, X, 3), ready for ``upload_texture3d`` (width X, height Y,
depth Z).

Lookup (``irradiance``, ``irradiance_wp``, ``glossy``): :mod:`serenity.kernels.skylookup` defines
it once (trilinear at p + ``normal_offset_m``·n, the traced probes' visibility, the fade to the
open sky's coefficients, ``open_coefficients``, beyond the grid's sides and top) and holds its Warp,
numpy and GLSL implementations. ``normal_offset_m`` = ``normal_offset`` (in cells) × the smallest
cell edge: it moves the lookup off the surface, away from probes behind it. The grid covers the
scene's bounds, or with ``SkyConfig.fit = "content"`` what stands on the ground
(``Scene.content_bounds``).

Updating: ``update(layers=1)`` — the per-frame path — rebakes the sky map when the sun moved more
than ``rebuild_angle_deg`` (``atmosphere.SkyMapCache``), then lets the method bring the probes
towards it; it returns whether anything changed (``updated_layers``: which y-layers). The layers'
cycle (``next_slabs``) and each layer's sky version (``layer_versions``) are the volume's, shared by
the methods. ``rebuild()`` does it all at once.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from serenity.config import SkyConfig
from serenity.device import resolve_device
from serenity.kernels.atmosphere import SkyMapCache, horizontal_irradiance
from serenity.kernels.atmosphere_ref import sampling_operator
from serenity.kernels.launch import launch
from serenity.kernels.occlusion import quads_arrays
from serenity.kernels.probegather import direction_sets
from serenity.kernels.quadfit import fit_occlusion_quads
from serenity.kernels.sampling import hammersley_np
from serenity.kernels.sh import irradiance_scale, sh_basis, vec9
from serenity.kernels.skygather import GatherMethod
from serenity.kernels.skylayers import LayersMethod
from serenity.kernels.skylookup import (
    COEFFS,
    ProbeGrid,
    ProbeVolume,
    eval_volume_glossy,
    eval_volume_irradiance,
    lookup_sky_irradiance,
    probe_grid,
    probe_volume,
)
from serenity.kernels.skymethod import SkyVolumeMethod
from serenity.kernels.skytransfer import TransferMethod
from serenity.kernels.tracers import SharedRayTracer

# ---------------------------------------------------------------------------------------------
# constants

#: directions (a spherical Fibonacci set) the open sky's coefficients are projected from
OPEN_SKY_DIRECTIONS = 4096

PAPER_RESOLUTION = (32, 16, 23)
#: the grid is at least this fraction of its widest side high: a scene that is (or whose contents
#: are) flat, e.g. a ground plane alone, still gets a volume of light above it, not one layer of
#: probes in the plane (which took the plane scene to 256 × 1 × 256 probes, more than asked for)
MIN_HEIGHT_FRACTION = 1.0 / 16.0
#: ``SkyConfig.method`` → the class that lights the probes
METHODS: dict[str, type[SkyVolumeMethod]] = {"layers": LayersMethod, "transfer": TransferMethod,
                                             "gather": GatherMethod}


# ---------------------------------------------------------------------------------------------
# host


def sky_method(config: SkyConfig) -> type[SkyVolumeMethod]:
    """The :class:`~serenity.kernels.skymethod.SkyVolumeMethod` of ``config.method``."""
    try:
        return METHODS[config.method]
    except KeyError:
        raise ValueError(f"sky volume method must be one of {tuple(METHODS)}, got {config.method!r}") from None


def fit_grid(bounds: np.ndarray, config: SkyConfig) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int]]:
    """(origin (3,), cell_size (3,), resolution (X, Y, Z)) of the probe grid for scene bounds (2,3),
    raised to at least ``MIN_HEIGHT_FRACTION`` of its widest side above their floor; at most the
    method's ``max_axis_probes`` along an axis."""
    lo, hi = np.array(bounds, np.float64)
    hi[1] = max(hi[1], lo[1] + MIN_HEIGHT_FRACTION * float(np.max(hi - lo)))
    extent = np.maximum(hi - lo, 0.0)
    centre = (lo + hi) / 2
    if config.resolution is not None:
        res = np.asarray(config.resolution, np.int64)
        cell = np.where(res > 1, extent / np.maximum(res - 1, 1), max(float(extent.max()), 1e-3))
        cell = np.maximum(cell, 1e-6)
    else:
        c = config.cell_size
        if c is None:
            vol = float(np.prod(np.maximum(extent, 1e-3 * max(float(extent.max()), 1e-3))))
            c = (vol / config.target_probes) ** (1.0 / 3.0)
            c = max(c, float(extent.max()) / (sky_method(config).max_axis_probes(config) - 1), 1e-6)
        res = np.maximum(np.ceil(extent / c - 1e-9).astype(np.int64) + 1, 1)
        cell = np.full(3, float(c))
    origin = centre - (res - 1) * cell / 2
    return origin, cell, (int(res[0]), int(res[1]), int(res[2]))


def pack_sh_textures(coeffs: np.ndarray, resolution: tuple[int, int, int]) -> list[np.ndarray]:
    """(P, 27) coefficients → 6 × (Z, Y, X, 4) + 1 × (Z, Y, X, 3) float32 (coefficient-major packing)."""
    x, y, z = resolution
    c = np.asarray(coeffs, np.float32).reshape(z, y, x, COEFFS)
    return [np.ascontiguousarray(c[..., 4 * t:4 * t + 4]) for t in range(6)] + [np.ascontiguousarray(c[..., 24:27])]


def unpack_sh_textures(textures: list[np.ndarray]) -> np.ndarray:
    """Inverse of :func:`pack_sh_textures`: (Z, Y, X, 27)."""
    return np.concatenate([np.asarray(t, np.float32) for t in textures], axis=-1)



class SkyVolume:
    """The sky lighting irradiance volume of one scene (see the module docstring).

    Attributes for the shader: ``grid_origin`` (3,) m, ``cell_size`` (3,) m, ``resolution``
    (X, Y, Z), ``normal_offset_m``; ``textures()`` the 7 arrays. ``sky`` is the
    :class:`~serenity.kernels.atmosphere.SkyMapCache` (its ``sky_map`` is what the dome samples);
    ``method`` the :class:`~serenity.kernels.skymethod.SkyVolumeMethod` that lights the probes.
    ``tracer``: a callable that returns the process's :class:`~serenity.kernels.raytrace.RayTracer` of
    the scene (the renderer's :class:`~serenity.kernels.tracers.SharedRayTracer`), for a method that
    traces rays; None: one of the volume's own, built when first asked for.
    """

    def __init__(self, scene, config: SkyConfig | None = None, device: str | None = None, tracer=None):
        self.scene = scene
        self.config = cfg = config or SkyConfig()
        self.device = dev = resolve_device(device)
        method = sky_method(cfg)
        bounds = scene.content_bounds() if cfg.fit == "content" else scene.bounds
        self.grid_origin, self.cell_size, self.resolution = fit_grid(bounds, cfg)
        self.normal_offset_m = float(cfg.normal_offset * float(np.min(self.cell_size)))
        quads = list(scene.occlusion_quads)
        self.quad_fit = None
        if not quads and cfg.auto_quads and method.occlusion_quads:
            self.quad_fit = fit_occlusion_quads(scene)
            quads = self.quad_fit.quads
        self.quads = quads
        c, u, r, h = quads_arrays(quads)
        #: the quads as Warp arrays (centres, ups, rights, half extents)
        self.quads_wp = (wp.array(c, dtype=wp.vec3, device=dev), wp.array(u, dtype=wp.vec3, device=dev),
                         wp.array(r, dtype=wp.vec3, device=dev), wp.array(h, dtype=wp.vec2, device=dev))
        n = cfg.rays_per_probe
        #: the Hammersley base points of the quads' rays (zeros for Owen-scrambled Sobol')
        self.base_points = wp.array(hammersley_np(n) if cfg.sequence == "hammersley" else np.zeros((n, 2), np.float32),
                                    dtype=wp.vec2, device=dev)
        #: the window's factors times Â_l per SH coefficient (``sh.irradiance_scale``)
        self.scale = vec9(*irradiance_scale(cfg.window, cfg.window_size).astype(np.float32).tolist())
        x, y, z = self.resolution
        self.probe_count = x * y * z
        #: the irradiance coefficients (P, 27), storage order (z, y, x)
        self.coeffs_wp = wp.zeros((self.probe_count, COEFFS), dtype=float, device=dev)
        #: the open sky's coefficients (the lookup fades to them beyond the grid's sides and top)
        self._open = wp.zeros(COEFFS, dtype=float, device=dev)
        self._open_host = np.zeros((9, 3))
        self._open_version = -1
        self._open_dirs = direction_sets(OPEN_SKY_DIRECTIONS, 1)[0]
        self._open_operator = None  # (sky map size, its sampling operator, the lower directions' Σ Y)
        self.constant_sky = getattr(scene.sky, "model", "atmosphere") == "constant"
        self.sky = SkyMapCache(cfg.sky_map_size, cfg.rebuild_angle_deg, device=dev, steps=cfg.sky_steps,
                               table=cfg.sky_view_table)
        self._constant_map = None
        self.ground_radiance = np.zeros(3)
        #: sky-map version each layer was last lit by (-1: never)
        self.layer_versions = np.full(y, -1, np.int64)
        self._next_layer = 0
        #: (first layer, count) slabs the last ``update``/``rebuild`` changed, for a partial upload
        self.updated_layers: list[tuple[int, int]] = []
        self._host: np.ndarray | None = None
        self._tracer = tracer if tracer is not None else SharedRayTracer(scene, dev)
        self.method: SkyVolumeMethod = method(self)

    def ray_tracer(self):
        """The scene's :class:`~serenity.kernels.raytrace.RayTracer` (the shared one, built on first use)."""
        return self._tracer()

    @property
    def visibility(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(atlas (Z·T, Y, X·T, 2), offsets (P, 3)) of the traced probes' depth moments and relocations,
        weighing each probe by whether it sees the point (``skylookup``); None: plain trilinear."""
        return self.method.visibility

    def lookup_defines(self) -> dict[str, int]:
        """The switches the shaders' lookup (sky.glsl) is compiled with for this volume."""
        return self.method.lookup_defines(self.config)

    # -- sky

    @property
    def sky_version(self) -> int:
        """Version of the sky the probes are lit by (the sky map's bake count; 1 for a constant sky)."""
        return 1 if self.constant_sky else self.sky.version

    def _current_sky_map(self, sun_direction):
        """(Warp sky map, changed?) — the atmosphere's cached bake, or the constant sky."""
        cfg = self.config
        if self.constant_sky:
            if self._constant_map is None:
                m = np.broadcast_to(np.asarray(self.scene.sky.radiance, np.float32), (2, 2, 3))
                self._constant_map = wp.array(np.ascontiguousarray(m), dtype=wp.vec3, device=self.device)
                self.ground_radiance = cfg.ground_albedo * np.asarray(self.scene.sky.radiance, np.float64)
                return self._constant_map, True
            return self._constant_map, False
        m, rebaked = self.sky.get(sun_direction)
        if rebaked:
            self.ground_radiance = cfg.ground_albedo / math.pi * horizontal_irradiance(self.sky.sky_map)
        return m, rebaked

    def sky_may_rebake(self, sun) -> bool:
        """Whether the next update could bake a new sky map (a constant sky: only its first)."""
        if self.constant_sky:
            return self._constant_map is None
        return self.sky.sky_map is None or self.sky.needs_rebuild(sun)
    def open_coefficients(self) -> np.ndarray:
        """(9, 3) float64 irradiance coefficients of a probe under the open sky (nothing occludes it:
        the sky map above the horizon, the ground radiance below, as a probe's misses), for the sky
        the volume was last lit by. The lookup fades to them beyond the grid's sides and top
        (``OPEN_FADE_CELLS``), where only open sky is left (``SkyConfig.fit = "content"``)."""
        if not self.constant_sky and self.sky.sky_map is None:  # no sky baked yet: nothing lit either
            return self._open_host
        if self._open_version != self.sky_version:
            d = self._open_dirs
            sky_map = self.sky_map()
            size = sky_map.shape[0]
            if self._open_operator is None or self._open_operator[0] != size:
                # Σ_i Y(d_i) L(d_i): the sky map's bilinear samples at the upper directions and the
                # ground radiance at the lower ones, as one linear map of the sky map per map size
                # (the sky map is rebaked every frame while the sun moves: this is ~50 µs, the
                # samples and their projection were ~1 ms)
                basis = sh_basis(d)
                up = d[:, 1] >= 0
                self._open_operator = (size, sampling_operator(size, d[up], basis[up]), basis[~up].sum(axis=0))
            _, op, ground = self._open_operator
            summed = op @ np.asarray(sky_map, np.float64).reshape(-1, 3) + np.outer(ground, self.ground_radiance)
            scale = irradiance_scale(self.config.window, self.config.window_size)
            self._open_host = scale[:, None] * (4.0 * math.pi / len(d)) * summed
            self._open.assign(self._open_host.reshape(-1).astype(np.float32))
            self._open_version = self.sky_version
        return self._open_host

    def sky_map(self) -> np.ndarray:
        """(S, S, 3) float32 the sky map the probes sample (constant sky: a 2×2 map)."""
        if self.constant_sky:
            return np.broadcast_to(np.asarray(self.scene.sky.radiance, np.float32), (2, 2, 3)).copy()
        return self.sky.sky_map

    # -- updating

    def _sun(self, sun_direction):
        return np.asarray(self.scene.sun.direction if sun_direction is None else sun_direction, np.float64)

    def may_change(self, sun_direction=None) -> bool:
        """Whether ``update`` (with ``layers`` > 0) could change a probe now; False only when it surely
        changes none (the method's ``may_change``). For a scheduler that decides before the update runs
        (``Renderer``'s volume worker)."""
        return self.method.may_change(self._sun(sun_direction))

    def update(self, layers: int = 1, sun_direction=None) -> bool:
        """Bring the volume towards the current sky (the method's ``update``; ``layers``: y-layers per
        update for ``"layers"``); returns whether any probe changed (``updated_layers`` then says which
        y-layers). ``sun_direction`` defaults to ``scene.sun.direction``."""
        sun = self._sun(sun_direction)
        sky_map, _ = self._current_sky_map(sun)
        self.updated_layers = []
        return self.method.update(sun, sky_map, layers)

    def rebuild(self, sun_direction=None) -> None:
        """Bring every layer up to date now (rebakes the sky map only if the sun moved)."""
        sun = self._sun(sun_direction)
        sky_map, _ = self._current_sky_map(sun)
        self.updated_layers = []
        self.method.rebuild(sun, sky_map)

    def next_slabs(self, count: int) -> list[tuple[int, int]]:
        """The next ``count`` layers of the cycle as contiguous (first, n) slabs (a cycle that
        wraps is two), and the cycle moved on past them."""
        y = self.resolution[1]
        first = self._next_layer
        count = min(int(count), y)
        self._next_layer = (first + count) % y
        return [(start, n) for start, n in ((first, min(count, y - first)), (0, max(0, first + count - y))) if n]

    @property
    def cycle_position(self) -> int:
        """The layer the cycle of :meth:`next_slabs` goes on from."""
        return self._next_layer

    def restart_cycle(self) -> None:
        """The cycle of :meth:`next_slabs` goes on from layer 0."""
        self._next_layer = 0

    def mark_lit(self, first: int, count: int) -> None:
        """A method re-lit y-layers ``first`` .. ``first + count - 1`` from the current sky."""
        self._host = None
        self.layer_versions[first:first + count] = self.sky_version
        self.updated_layers.append((first, count))

    @property
    def pending_layers(self) -> int:
        """Layers not yet lit by the current sky (0: the volume is current)."""
        return int(np.count_nonzero(self.layer_versions != self.sky_version))

    # -- outputs

    def probe_grid(self) -> ProbeGrid:
        """The grid as the kernels take it (``skylookup.ProbeGrid``)."""
        return probe_grid(self.grid_origin, self.cell_size, self.resolution)

    def lookup_volume(self) -> ProbeVolume:
        """What the Warp lookup reads (``skylookup.ProbeVolume``), current."""
        return probe_volume(self.probe_grid(), self.normal_offset_m, self.coeffs_wp, self._open_sky(),
                            *self.method.visibility_wp)

    def visibility_textures(self) -> tuple[np.ndarray, np.ndarray] | None:
        """For the shader (``SkyTexturesGL.upload_visibility``): the depth-moment atlas (Z·T, Y, X·T, 2)
        and the probes' relocation offsets (Z, Y, X, 3), float32; None without visibility."""
        if self.visibility is None:
            return None
        x, y, z = self.resolution
        return self.visibility[0], np.ascontiguousarray(self.visibility[1].reshape(z, y, x, 3), np.float32)

    def probe_positions(self) -> np.ndarray:
        """(P, 3) float64 probe positions, in storage order (z, y, x)."""
        x, y, z = self.resolution
        zz, yy, xx = np.meshgrid(np.arange(z), np.arange(y), np.arange(x), indexing="ij")
        g = np.stack([xx, yy, zz], axis=-1).reshape(-1, 3).astype(np.float64)
        return self.grid_origin + g * self.cell_size

    def coefficients(self) -> np.ndarray:
        """(Z, Y, X, 9, 3) float32 irradiance coefficients E_k per channel."""
        if self._host is None:
            x, y, z = self.resolution
            self._host = self.coeffs_wp.numpy().reshape(z, y, x, COEFFS)
        return self._host.reshape(*self._host.shape[:3], 9, 3)

    def textures(self, layers: tuple[int, int] | None = None) -> list[np.ndarray]:
        """The 7 arrays of the paper's layout: 6 × (Z, Y, X, 4) + (Z, Y, X, 3) float32; with
        ``layers`` = (first, n) only that slab of y-layers, (Z, n, X, ·)."""
        c = self.coefficients()
        x, _, z = self.resolution
        if layers is None:
            return pack_sh_textures(c.reshape(-1, COEFFS), self.resolution)
        first, n = (int(v) for v in layers)
        slab = c[:, first:first + n]
        return pack_sh_textures(slab.reshape(-1, COEFFS), (x, n, z))


    def irradiance_wp(self, points, normals) -> np.ndarray:
        """(N, 3) float32 W·m⁻²: :meth:`irradiance` by a Warp kernel on the volume's device (the
        frame's sky-light VPLs: tens of thousands of G-buffer points per update)."""
        p = np.ascontiguousarray(np.asarray(points, np.float32).reshape(-1, 3))
        n = np.ascontiguousarray(np.asarray(normals, np.float32).reshape(-1, 3))
        dev = self.device
        out = wp.empty(len(p), dtype=wp.vec3, device=dev)
        launch(lookup_sky_irradiance, len(p),
               [self.lookup_volume(), wp.array(p, dtype=wp.vec3, device=dev), wp.array(n, dtype=wp.vec3, device=dev),
                out], device=dev)
        return out.numpy()
    def irradiance(self, points, normals) -> np.ndarray:
        """(N, 3) float64 W·m⁻² at surface points with unit normals, as the shader evaluates it."""
        c = self.coefficients().reshape(*self.resolution[::-1], COEFFS)
        return eval_volume_irradiance(c, self.grid_origin, self.cell_size, self.resolution, self.normal_offset_m,
                                      points, normals, self.open_coefficients(), self.visibility)

    def glossy(self, points, normals, directions, shininess) -> np.ndarray:
        """(N, 3) float64 W·m⁻²·sr⁻¹: the volume's radiance around ``directions`` filtered by the Phong
        lobe of exponent ``shininess`` (scalar or (N,)), looked up at the surface points and normals,
        as the shader evaluates it (``SkyConfig.glossy``)."""
        c = self.coefficients().reshape(*self.resolution[::-1], COEFFS)
        return eval_volume_glossy(c, self.grid_origin, self.cell_size, self.resolution, self.normal_offset_m,
                                  points, normals, directions, shininess, self.open_coefficients(), self.visibility)

    def _open_sky(self):
        """The (27,) Warp array of :meth:`open_coefficients`, current."""
        self.open_coefficients()
        return self._open

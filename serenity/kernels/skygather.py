"""The traced probes as a sky volume's method (``SkyConfig.method = "gather"``, beyond the paper §7–§8):
the probes lit by the sky *and* by the light the scene bounces, through the real geometry.

The rays, surfels and passes are :class:`~serenity.kernels.probegather.ProbeGather`'s (its module
docstring says how a probe is lit); this module drives them over the volume:

- **Tracing** (the first update): each probe's ``gather_rays`` rays through the kd-tree of the
  renderer's shared :class:`~serenity.kernels.raytrace.RayTracer` (``SkyVolume(tracer=...)``),
  only for the probes a lookup on the scene's surfaces can read (``reachable_probes``); with
  ``gather_visibility`` the probes' depth moments become the lookup's visibility atlas.
- **Following the sky**: after a rebake of the sky map (or a move of the sun past
  ``rebuild_angle_deg`` under a constant sky) the miss radiance follows at once and the surfels'
  shadow rays towards the sun are re-traced — all at once for a whole pass, else a slice per update,
  so that each pass of Y updates (one y-layer each) re-traces every surfel once against the newest sun.
- **Passes**: a pass is one surfel update (each surfel's radiance from the volume as it is: one more
  bounce) then a gather of every y-layer; passes follow a change of the sky until they converge
  (:meth:`GatherMethod.converged`) or ``gather_bounces`` have run — all of them at once when the
  volume was never lit (or :meth:`rebuild`), else ``transfer_layers`` y-layers per update (0: a whole
  pass). A first lighting's converged coefficients are cached on disk beside the trace.

The updates stay on the renderer's main thread (``on_volume_worker`` False): their passes are split
over every core already, and beside the GL passes they only slowed both.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from serenity.config import SkyConfig
from serenity.kernels.atmosphere_ref import angle_between_deg, scene_sun_irradiance
from serenity.kernels.probegather import REACH_MARGIN_CELLS, ProbeGather, reach_key, scene_key
from serenity.kernels.probesurfels import visibility_atlas
from serenity.kernels.skylookup import VIS_TILE, reachable_probes
from serenity.kernels.skymethod import SkyVolumeMethod

#: 3D textures of this size per axis are what every GL 4.x must allow (GL_MAX_3D_TEXTURE_SIZE,
#: llvmpipe's limit too): the visibility atlas holds VIS_TILE texels per probe along x and z, so a
#: grid with visibility has at most this / VIS_TILE probes along them
GL_MIN_MAX_3D_TEXTURE = 2048


class GatherMethod(SkyVolumeMethod):
    """``"gather"``: the traced probes (module docstring). ``probes`` is the
    :class:`~serenity.kernels.probegather.ProbeGather`, made on the first update (it traces)."""

    occlusion_quads = False  # the rays see the real geometry
    on_volume_worker = False

    @classmethod
    def max_axis_probes(cls, config: SkyConfig) -> int:
        """255, or fewer where the visibility atlas must fit a 3D texture (``GL_MIN_MAX_3D_TEXTURE``)."""
        return min(255, GL_MIN_MAX_3D_TEXTURE // VIS_TILE) if config.gather_visibility else 255

    @classmethod
    def lookup_defines(cls, config: SkyConfig) -> dict[str, int]:
        return {"SKY_VISIBILITY": int(config.gather_visibility)}

    def __init__(self, volume):
        super().__init__(volume)
        self.probes: ProbeGather | None = None
        self._version = -1  # sky version the miss radiance and the surfels' sun visibility follow
        self._sun = None  # ... and the sun direction
        #: passes over the volume still to run for the current sky (each adds a bounce)
        self.passes_left = 0
        #: the relative change of the volume's light in the last complete pass (None: no pass since the
        #: passes started), and the light at the start of the running pass
        self._last_change: float | None = None
        self._pass_before: np.ndarray | None = None

    def may_change(self, sun) -> bool:
        return True

    def _ensure_probes(self) -> ProbeGather:
        if self.probes is None:
            v = self.volume
            cfg = v.config
            size = cfg.gather_surfel_size or 0.4 * float(np.min(v.cell_size))
            glossy = ([m.specular if m.reflectivity == 0 and m.transparency == 0 else 0.0
                       for m in v.scene.materials] if cfg.glossy else None)
            # only the probes a lookup on the scene's surfaces can read are traced and gathered
            pos, _, _, faces, _ = v.scene.merged()
            reach = v.normal_offset_m + REACH_MARGIN_CELLS * float(np.min(v.cell_size))
            grid = (v.grid_origin.copy(), v.cell_size.copy(), v.resolution)
            self.probes = g = ProbeGather(v.ray_tracer(), v.probe_positions(), v.cell_size, cfg.gather_rays, size,
                                          v.device, glossy_energy=glossy, transmissions=cfg.gather_transmissions,
                                          cache_key=scene_key(v.scene),
                                          active=lambda: reachable_probes(pos, faces, *grid, reach),
                                          active_key=reach_key(reach, v.resolution),
                                          grid=(v.grid_origin, v.resolution, v.normal_offset_m))
            if cfg.gather_visibility:
                atlas = visibility_atlas(g.moments, v.resolution)
                self.visibility = (atlas, g.offsets)
                self.visibility_wp = (wp.array(atlas, dtype=wp.vec2, device=v.device),
                                      wp.array(g.offsets, dtype=wp.vec3, device=v.device))
        return self.probes

    def _start_pass(self, sun) -> None:
        """The surfels' radiance from the volume as it is (the start of a pass: one more bounce)."""
        v = self.volume
        if v.config.gather_tolerance > 0.0:  # the light the pass starts from, for converged()
            self._pass_before = v.coeffs_wp.numpy().copy()
        self.probes.update_surfels(v.lookup_volume(), sun, scene_sun_irradiance(v.scene, sun))

    def converged(self) -> bool:
        """After a complete pass: whether the passes have converged. Each pass adds the next bounce, so
        successive passes change the volume's light by Δ_k = r·Δ_(k−1), r the share of the light
        the scene passes on; the bounces still missing then sum to about Δ_k·r/(1−r) of the light,
        and the passes stop once that is under ``SkyConfig.gather_tolerance`` (an open courtyard
        after 5 passes, a closed white room after about 20)."""
        tol = self.volume.config.gather_tolerance
        if tol <= 0.0:
            return False
        after = self.volume.coeffs_wp.numpy()
        change = float(np.abs(after - self._pass_before).sum() / max(float(np.abs(after).sum()), 1e-30))
        last, self._last_change = self._last_change, change
        if last is None:
            return False
        if last <= 0.0:
            return True
        r = min(change / last, 0.99)
        return change * r / (1.0 - r) < tol

    def update(self, sun, sky_map, layers: int) -> bool:
        return self._update(sun, full=False)

    def rebuild(self, sun, sky_map) -> None:
        if self.passes_left <= 0:
            self.passes_left = self.volume.config.gather_bounces
            self._last_change = None
        self._update(sun, full=True)

    def _update(self, sun, full: bool) -> bool:
        """Follow a new sky (miss radiance, surfel shadow rays), then run passes over the volume until
        they converge (:meth:`converged`; ``gather_bounces`` at most) — all of them now when the
        volume was never lit or ``full``, else ``transfer_layers`` y-layers per call (0 = a whole pass)."""
        g = self._ensure_probes()
        v = self.volume
        cfg = v.config
        y = v.resolution[1]
        never_lit = bool(np.any(v.layer_versions < 0))
        moved = self._sun is None or angle_between_deg(self._sun, sun) > cfg.rebuild_angle_deg
        whole = full or never_lit or cfg.transfer_layers <= 0
        if self._version != v.sky_version or moved:  # a new sky, or the sun moved (constant skies)
            g.set_sky(v.sky_map(), v.ground_radiance)
            # the surfels' shadow rays: all now for a whole pass, else a slice per update, so that each
            # pass of y updates (one y-layer each) re-traces every surfel once against the newest sun
            g.update_visibility(sun, parts=1 if whole else y)
            self._version = v.sky_version
            self._sun = np.array(sun, np.float64)
            self.passes_left = cfg.gather_bounces
            self._last_change = None
        elif not whole:
            g.refresh_visibility()  # the slices left after the last move of the sun
        if full or never_lit:
            while g.refresh_visibility():  # a whole pass needs every surfel's visibility current
                pass
            # a first lighting's passes: read back where this scene, sky and sun were lit before
            cached = (g.converged_path(v.sky_map(), v.ground_radiance, sun, scene_sun_irradiance(v.scene, sun),
                                       v.open_coefficients(), v.grid_origin, v.cell_size, v.resolution,
                                       v.normal_offset_m, self.passes_left, cfg.gather_tolerance,
                                       self.visibility is not None, np.asarray(v.scale))
                      if np.all(v.layer_versions < 0) else None)
            if g.load_converged(cached, v.coeffs_wp):
                self.passes_left = 0
            while self.passes_left > 0:
                self._start_pass(sun)
                g.gather(v.probe_grid(), v.coeffs_wp, v.scale, 0, y)
                self.passes_left -= 1
                if self.converged():
                    self.passes_left = 0
                if self.passes_left == 0:
                    g.save_converged(cached, v.coeffs_wp)
            v.restart_cycle()  # a pass starts at layer 0 (the cycle's next layer is where the current one is)
            v.mark_lit(0, y)
            return True
        if self.passes_left <= 0:
            return False
        per_update = cfg.transfer_layers if cfg.transfer_layers > 0 else y
        if v.cycle_position == 0:
            self._start_pass(sun)
        for start, n in v.next_slabs(min(per_update, y - v.cycle_position)):  # never past the pass's end
            g.gather(v.probe_grid(), v.coeffs_wp, v.scale, start, n)
            v.mark_lit(start, n)
        if v.cycle_position == 0:  # the pass is complete
            self.passes_left -= 1
            if self.converged():
                self.passes_left = 0
        return True

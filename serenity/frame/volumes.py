"""The frame's volume stages (paper §7 and §8), a part of :class:`~serenity.frame.renderer.Renderer`."""

from __future__ import annotations

import time

import numpy as np

from serenity.frame.record import MAIN_LANE, VOLUME_LANE
from serenity.kernels.lpv import (
    LightPropagationVolume,
    rsm_surfels,
    sample_gbuffer,
    sky_vpls_from_samples,
    surfels_from_samples,
)
from serenity.kernels.skyvolume import SkyVolume, sky_method
from serenity.raster.deferred import LightingInputs
from serenity.raster.indirect import IndirectPass, LowResIndirect
from serenity.raster.lowres import GBufferSamples, IndirectRefinement
from serenity.raster.lpv_gl import LPVTexturesGL, lookup_defines
from serenity.raster.rsm import RSMPass
from serenity.raster.sky import SkyTexturesGL
from serenity.raster.temporal import IndirectHistory


class VolumeStages:
    """The :class:`~serenity.frame.renderer.Renderer`'s volume stages: the sky irradiance volume (paper
    §7) and the light propagation volumes (paper §8) — built, updated as far as the sun, the sky and
    the camera changed (on the volume worker where there is one), and uploaded to GL."""

    def _init_gi(self) -> None:
        """The volumes: the sky irradiance volume (paper §7) and the light propagation volumes
        (paper §8), each when enabled."""
        cfg, ctx = self.config, self.ctx
        self.lowres = None
        self.indirect_history = None
        self.indirect_refinement = None
        if cfg.indirect.scale > 1 and (cfg.sky.enabled or cfg.lpv.enabled):
            self.lowres = LowResIndirect(ctx, cfg.indirect.scale, cfg.indirect.tile_balance)
            self.lowres.resize(self.width, self.height)
            if cfg.indirect.refine_below > 0.0:  # full resolution where the upsampling has no match
                self.indirect_refinement = IndirectRefinement(ctx, cfg.indirect.scale, cfg.indirect.refine_below)
                self.indirect_refinement.resize(self.width, self.height)
            if cfg.indirect.history < 1.0:  # the upsampled light blended with the last frame's (raster/temporal.py)
                self.indirect_history = IndirectHistory(ctx)
                self.indirect_history.resize(self.width, self.height)
        self.sky_volume = None
        self._sky_map_version = -1
        self._sky_volume_version = 0  # counts the sky volume's updates (the sky-light VPLs read it)
        if cfg.sky.enabled:
            self.sky_volume = SkyVolume(self.scene, cfg.sky, self.device, tracer=self.shared_ray_tracer)
            self.sky_gl = SkyTexturesGL(ctx)
            sky_defines = {"SKY_GLOSSY": int(cfg.sky.glossy), **self.sky_volume.lookup_defines()}
            self.sky_pass = IndirectPass(ctx, "sky", defines=sky_defines)
            self.sky_pass_lo = IndirectPass(ctx, "sky", lowres=True, defines=sky_defines) if self.lowres else None
            self._sky_built = False
            self._sky_map_version = -1
        self.lpv = None
        if cfg.lpv.enabled:
            self.rsm_pass = RSMPass(ctx, self.scene_gl, cfg.lpv.rsm_size)
            self.rsm_pass.lod_pixel_error = cfg.lod_pixel_error
            self.lpv = LightPropagationVolume(cfg.lpv, self.device)
            self.gbuffer_samples = GBufferSamples(ctx, cfg.lpv.sky_vpl_stride)
            self.gbuffer_samples.resize(self.width, self.height)
            self.lpv_gl = LPVTexturesGL(ctx)
            # the lookup's switches compiled in (lpv.glsl; fixed with the LPV's config when the renderer
            # is built): only the paths the config takes are run
            switches = lookup_defines(cfg.lpv)
            self.lpv_pass = IndirectPass(ctx, "lpv", defines=switches)
            self.lpv_pass_lo = IndirectPass(ctx, "lpv", lowres=True, defines=switches) if self.lowres else None

    def invalidate_lpv(self) -> None:
        """Make the next frame re-inject and re-propagate the LPV even if nothing changed (for
        timing the update, or after editing the scene's geometry in place)."""
        self._changes.forget("lpv")
        self._lpv_inputs_version += 1
        if self.lpv is not None:
            self.lpv.invalidate()

    def _update_volumes(self, gbuf, light: LightingInputs) -> None:
        """The sky irradiance volume (paper §7) and the light propagation volumes (paper §8), each
        only as far as the sun, the sky and the camera changed; on this thread, in turn."""
        if self.sky_volume is not None:
            self._upload_sky(self._compute_sky())
        if self.lpv is None:
            return
        view_changed = self._lpv_view_changed(light)
        sky_changed = self._lpv_sky_version != self._sky_volume_version
        if view_changed or sky_changed or self.lpv.pending_levels:
            wanted = view_changed or sky_changed or self.lpv.stale_levels  # else only a blend step
            self._lpv_job(view_changed, self._read_lpv_inputs(gbuf, light.sun_irradiance) if wanted else None)
            self._upload_lpv()

    def _plan_lpv(self, light: LightingInputs, sky_may_change: bool):
        """With the volume worker, at the frame's start: when the LPV may change this frame (the view
        changed, a staggered cascade is behind, or the sky volume may change: ``SkyVolume.may_change``,
        asked before its update started), the sun's RSM drawn and read back. Returns (whether the view
        changed, the RSM), or None: the LPV is left alone this frame."""
        if self.lpv is None:
            return None
        view_changed = self._lpv_view_changed(light)
        if not (view_changed or sky_may_change or self.lpv.pending_levels):
            return None
        wanted = view_changed or sky_may_change or self.lpv.stale_levels  # else only a blend step
        return view_changed, self._read_rsm(light.sun_irradiance) if wanted else None

    def _start_lpv(self, gbuf, plan):
        """With the volume worker, after the G-buffer: its samples read back and the LPV's kernels
        queued behind the sky volume's update (``_plan_lpv``'s plan; the worker then decides exactly:
        ``_lpv_job``). Returns the job, or None."""
        if plan is None:
            return None
        view_changed, rsm = plan
        inputs = None if rsm is None else (rsm, self._read_gbuffer_samples(gbuf))
        return self._volume_pool.submit(self._lpv_job, view_changed, inputs)

    def _lpv_view_changed(self, light: LightingInputs) -> bool:
        """Whether the LPV's inputs other than the sky volume (the sun, its irradiance, the camera)
        changed since the last frame (main thread: the change tracker's state)."""
        cam = self.scene.camera
        return self._changes.changed(
            lpv=np.concatenate([self.scene.sun.direction, light.sun_irradiance, cam.position, cam.target,
                                [cam.fov_y_deg]]))

    def _lpv_job(self, view_changed: bool, inputs) -> None:
        """Re-inject and propagate when the LPV's inputs changed (the view, or the sky volume since the
        LPV last read it: the sky-light VPLs) or a staggered LPV's cascades are still behind
        (``LPVConfig.stagger``); one step of the blend of its light when only that is left
        (``LPVConfig.temporal_blend``; ``inputs`` may then be None); else nothing (the inputs were read
        for a sky that did not change)."""
        sky_changed = self._lpv_sky_version != self._sky_volume_version
        if view_changed or sky_changed:
            self._lpv_inputs_version += 1
            self._lpv_sky_version = self._sky_volume_version
        elif not self.lpv.pending_levels:
            return
        elif not self.lpv.stale_levels:  # every cascade holds these inputs: their light's blend goes on
            with self._cpu_stage("lpv blend"):
                if self.lpv.blend(self.config.lpv.temporal_blend):
                    self._lpv_pending_upload = True
            return
        self._compute_lpv(*inputs)

    def _lpv_terms(self) -> dict | None:
        """The LPV lighting passes' switches (``LPVConfig.diffuse`` / ``.glossy``, read each frame), or
        None when there is no LPV light to add this frame (no LPV, no cascade, or both terms off)."""
        c = self.config.lpv
        if self.lpv is None or not self.lpv_gl.count or not (c.diffuse or c.glossy):
            return None
        return {"diffuse": c.diffuse, "glossy": c.glossy}

    def _sky_irradiance_at(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray | None:
        """Sky irradiance (W/m²) at G-buffer points for the sky-light VPLs; None without a sky volume."""
        if self.sky_volume is None:
            return None
        shape = points.shape[:-1]
        return self.sky_volume.irradiance_wp(points.reshape(-1, 3), normals.reshape(-1, 3)).reshape(*shape, 3)

    def _compute_sky(self) -> dict | None:
        """The sky volume follows the sky (``SkyVolume.update``: the whole volume on the first
        frame; then by transfer, or ``sky.layers_per_frame`` layers of the paper's sweep), and the
        host side of its upload is prepared: the sky map when rebaked, the open sky's coefficients,
        the texture arrays of the layers that changed. No GL: the volume worker may run it. Returns
        what ``_upload_sky`` writes, or None when no probe changed."""
        sv = self.sky_volume
        first = not self._sky_built
        with self._cpu_stage("sky volume build" if first else "sky volume update"):
            changed = sv.update(layers=sv.resolution[1] if first else self.config.sky.layers_per_frame)
            self._sky_built = True
            if not changed and not first:
                return None
            out = {"visibility": sv.visibility_textures() if first else None, "changed": changed}
            if changed:
                self._sky_volume_version += 1
                slabs = sv.updated_layers  # the first update always re-lights the whole volume
                out.update(sky_version=sv.sky.version, open=sv.open_coefficients(),
                           sky_map=sv.sky_map() if sv.sky.version != self._sky_map_version else None,
                           whole=sv.textures() if slabs == [(0, sv.resolution[1])] else None,
                           slabs=[] if slabs == [(0, sv.resolution[1])] else
                           [(slab[0], sv.textures(layers=slab)) for slab in slabs])
            return out

    def _upload_sky(self, prepared: dict | None) -> None:
        """The sky map and the volume's textures uploaded, where ``_compute_sky`` changed them."""
        if prepared is None:
            return
        sv = self.sky_volume
        if prepared["visibility"] is not None:  # the gathered probes' depth moments: static, uploaded once
            with self._stage("sky upload"):
                self.sky_gl.upload_visibility(*prepared["visibility"])
        if prepared["changed"]:
            with self._stage("sky upload"):
                if prepared["sky_map"] is not None:
                    self.sky_gl.upload_sky_map(prepared["sky_map"])
                    self._sky_map_version = prepared["sky_version"]
                self.sky_gl.set_open_sky(prepared["open"])
                if prepared["whole"] is not None:
                    self.sky_gl.upload_volume(prepared["whole"], sv.grid_origin, sv.cell_size, sv.resolution,
                                              sv.normal_offset_m)
                for first_layer, textures in prepared["slabs"]:  # only the layers this update re-lit
                    self.sky_gl.upload_volume_layers(textures, first_layer)

    def _read_lpv_inputs(self, gbuf, sun_irradiance: np.ndarray):
        """What the LPV is injected from, read back from GL: (the sun's RSM, the G-buffer's samples)."""
        return self._read_rsm(sun_irradiance), self._read_gbuffer_samples(gbuf)

    def _read_rsm(self, sun_irradiance: np.ndarray):
        """The sun's RSM, drawn and read back as VPLs (stage "rsm")."""
        with self._stage("rsm"):
            self.rsm_pass.render(self.scene.sun.direction, sun_irradiance, self.scene_gl.bounds)
            return self.rsm_pass.read()

    def _read_gbuffer_samples(self, gbuf) -> dict:
        """Every ``lpv.sky_vpl_stride``-th pixel of the G-buffer, gathered on the GL side and read back
        (the "rsm" stage's G-buffer half, ``STAGES``)."""
        with self._stage("rsm"):
            return self.gbuffer_samples.read(gbuf)

    def _compute_lpv(self, rsm, g) -> None:
        """Re-inject and propagate (the sun, the sky or the camera changed): the VPLs and surfels of
        the RSM and of the sky-lit G-buffer (paper Fig. 11), injected and propagated. No GL: the
        volume worker may run it."""
        with self._cpu_stage("lpv inputs"):
            vpls, surfels = self._lpv_inputs(rsm, g)
        t0 = time.perf_counter()
        # the key: which change of the inputs this is (a staggered LPV's cascades catch up under one key)
        self.lpv.update(self.scene.camera, self.scene_gl.bounds, vpls, surfels, key=self._lpv_inputs_version,
                        blend=self.config.lpv.temporal_blend)
        t_inject = (self.lpv.timings.get("inject", 0.0) + self.lpv.timings.get("inject_geometry", 0.0)) / 1e3
        t1 = time.perf_counter()
        lane = VOLUME_LANE if self._on_volume_worker() else MAIN_LANE
        self._record(lane, "lpv inject", t0, min(t1, t0 + t_inject))
        self._record(lane, "lpv propagate", min(t1, t0 + t_inject), t1)
        self._lpv_pending_upload = True

    def _upload_lpv(self) -> None:
        if self._lpv_pending_upload:
            with self._stage("lpv upload"):
                self.lpv_gl.upload(self.lpv)
            self._lpv_pending_upload = False

    def _lpv_inputs(self, rsm, g):
        """(VPL sets, surfel sets) of the sun's RSM and of the G-buffer's samples ``g`` (the sky-lit
        G-buffer as a second RSM, paper Fig. 11)."""
        scene, cam = self.scene, self.scene.camera
        vpls = [(rsm.positions, rsm.normals, rsm.flux)]
        surfels = [rsm_surfels(rsm, scene.sun.direction)]
        pos, nrm = g["position"], g["normal"][..., :3]
        samples = sample_gbuffer(pos, nrm, cam.position, cam.forward, cam.fov_y_deg, stride=1)  # w = 0: no surface
        surfels.append(surfels_from_samples(samples))
        e_sky = self._sky_irradiance_at(pos[..., :3], nrm)
        if e_sky is not None:
            vpls.append(sky_vpls_from_samples(samples, g["albedo"][..., :3], e_sky))
        return vpls, surfels

    def _volumes_in_worker(self) -> bool:
        """Whether the volumes' kernels run on a worker thread (``_volume_pool``), known from the
        config alone (the tracer process, started before the volumes exist, asks it too)."""
        cfg = self.config
        return (cfg.schedule.overlap and cfg.schedule.overlap_volumes and str(self.device).startswith("cpu")
                and ((cfg.sky.enabled and sky_method(cfg.sky).on_volume_worker) or cfg.lpv.enabled))

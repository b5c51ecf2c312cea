"""The frame's ray-tracing stages (paper §9), a part of :class:`~serenity.frame.renderer.Renderer`."""

from __future__ import annotations

from functools import cached_property

import numpy as np

from serenity.frame.record import RT_LANE
from serenity.kernels.tracers import InlineTracer, RestartingTracer, SharedRayTracer, ThreadTracer, TracerProcess
from serenity.raster.deferred import LightingInputs
from serenity.raster.raycast import RayCastingBuffer
from serenity.raster.shadow import STAGGER_PAD, fit_overlapped


class RayTracingStages:
    """The :class:`~serenity.frame.renderer.Renderer`'s ray-tracing stages (paper §9): the ray-casting
    buffer read back at sync 1, the rays handed to the tracer (``kernels/tracers``), its hits joined
    at sync 2 and lit as the reflection and refraction views, composited over the main view."""

    def _start_ray_tracing(self, view_proj, gbuf):
        """The ray-casting buffer (which pixels reflect or refract, and their rays; read from the
        G-buffer), read back; the tracer starts on them at once. Returns (rcb or None, a callable
        that joins the tracer)."""
        if not self.traces:
            return None, None
        with self._stage("ray casting buffer"):
            self.raycast_pass.render(view_proj, self.scene.camera, gbuf)
            rcb = self.raycast_pass.read().select(self.config.rt.reflections, self.config.rt.refractions)
        if not rcb.count:
            return rcb, None
        tracing = self._ensure_tracer()
        handle = tracing.submit(self._ray_batches(rcb))
        return rcb, lambda: self._join_tracer(handle)

    def _ray_traced_views(self, rcb, join, gbuf, lit, light: LightingInputs):
        """Join the tracer (sync 2), light the ray-traced G-buffers with the overlapped shadow maps
        (paper §9) and composite them over the main view with a Fresnel blend."""
        if join is None:
            return lit.hdr
        cfg, scene, cam = self.config, self.scene, self.scene.camera
        sky_gl = self.sky_gl if self.sky_volume is not None else None
        with self._stage("wait for ray tracing", gl=False):
            traced = join()
        with self._stage("rt g-buffer upload"):
            view_rt = self.rt_upload.upload(rcb, *traced)
        osm = None  # rt.sun_shadows == "traced": the tracer's shadow rays (eye.w) instead
        if self.osm_pass is not None:
            with self._stage("shadow maps (OSM)"):
                stagger = cfg.shadow.stagger
                osm = self.osm_pass.render(fit_overlapped(cam.position, scene.sun.direction, self.scene_gl.bounds, 3,
                                                          cfg.rt.osm_size, pad=STAGGER_PAD if stagger else 0.0),
                                           stagger=stagger)
        with self._stage("rt direct lighting"):
            rt_lit = self.rt_deferred.render(view_rt, osm, light, None, rt_view=view_rt, sky=sky_gl)
        if sky_gl is not None:
            with self._stage("rt sky lighting"):
                self.sky_pass.render(rt_lit.hdr, view_rt, sky_gl.bind, cam.position, rt_view=view_rt)
        terms = self._lpv_terms()
        if terms:
            with self._stage("rt lpv lighting"):
                self.lpv_pass.render(rt_lit.hdr, view_rt, self.lpv_gl.bind, cam.position, rt_view=view_rt, **terms)
        with self._stage("composite"):
            return self.composite_pass.render(lit.hdr, rt_lit.hdr, view_rt.points, gbuf, cam.position)

    @property
    def tracer_niceness(self) -> int | None:
        """The tracer process's niceness relative to this process's, as the OS granted
        ``ScheduleConfig.tracer_nice`` (None before the first traced frame, or without the process)."""
        return None if self._tracer_proc is None else self._tracer_proc.niceness

    def _tracer_starts_idle(self) -> bool:
        """Whether sync 1 waits for the main thread's idle point (``ScheduleConfig.tracer_start``):
        "auto" does once the tracer process is known to run in a scheduling group of its own
        (``TracerProcess.own_group``); a tracer sharing the renderer's group at nice 19 would only
        start later and still wait for a core."""
        where = self.config.schedule.tracer_start
        if where == "auto":
            return self._tracer_proc is not None and self._tracer_proc.own_group
        return where == "idle"

    def _tracer_in_process(self) -> bool:
        """Whether the tracer runs in a process of its own (the overlapped schedule on the CPU)."""
        return self.config.schedule.overlap and str(self.device).startswith("cpu")

    def _ensure_tracer(self) -> RestartingTracer:
        """The ray tracer (``kernels/tracers``), restarted once where it stops or hangs: for the
        overlapped schedule on the CPU a :class:`TracerProcess` (a thread would stall behind the GL
        calls that hold the GIL), started with the renderer (its imports, scene and tree run beside
        the GL set-up and the first frame's volumes); on CUDA a :class:`ThreadTracer` (its launches
        run asynchronously); else an :class:`InlineTracer`. The in-process tracers build their
        kd-tree on the first frame that shows a traced pixel."""
        if self._tracing is None:
            cfg, scene, device = self.config, self.scene, self.device
            if self._tracer_in_process():
                session = cfg.schedule.tracer_session
                if session is None:  # a group of its own where the main thread will wait for a volume worker
                    session = self._volumes_in_worker()

                def make():
                    return TracerProcess(scene, device, nice=cfg.schedule.tracer_nice, session=session)
            elif cfg.schedule.overlap:
                def make():
                    return ThreadTracer(scene, device, self.shared_ray_tracer)
            else:
                def make():
                    return InlineTracer(scene, device, self.shared_ray_tracer)
            self._tracing = RestartingTracer(make)
        return self._tracing

    @cached_property
    def shared_ray_tracer(self) -> SharedRayTracer:
        """The process's one :class:`~serenity.kernels.raytrace.RayTracer` of the scene, built by its
        first user: the in-process tracer and the sky volume's traced probes share it (the tracer
        process builds its own)."""
        return SharedRayTracer(self.scene, self.device)

    @property
    def _tracer_proc(self) -> TracerProcess | None:
        """The tracer process, where the ray tracer runs in one."""
        t = None if self._tracing is None else self._tracing.tracer
        return t if isinstance(t, TracerProcess) else None

    @property
    def tracer(self):
        """The :class:`~serenity.kernels.raytrace.RayTracer` in this process (serial schedule, or
        CUDA), once a frame has built it; None with the tracer process or before."""
        t = None if self._tracing is None else self._tracing.tracer
        return getattr(t, "ray_tracer", None)

    def _ray_batches(self, rcb: RayCastingBuffer) -> list:
        """(origins, directions, cone width, cone spread, transmissions, sun direction or None) of the
        reflected and the refracted rays, None where there are none."""
        sun = self._traced_sun()
        out = []
        for sel, dirs, transmissions in ((rcb.reflection_rays(), rcb.reflect_dirs, 0),
                                         (rcb.refraction_rays(), rcb.refract_dirs, self.config.rt.transmissions)):
            out.append((rcb.origins[sel], dirs[sel], rcb.cone_width[sel], rcb.cone_spread[sel], transmissions, sun)
                       if sel.any() else None)
        return out

    def _traced_sun(self):
        """The sun direction the tracer casts shadow rays to (``rt.sun_shadows == "traced"``), or None."""
        if self.config.rt.sun_shadows != "traced":
            return None
        return np.asarray(self.scene.sun.direction, np.float64)

    def _join_tracer(self, handle: int) -> tuple[dict | None, dict | None]:
        """Sync 2: the hits of the reflected and the refracted rays submitted under ``handle``, with
        the tracer's time on the timeline and its CPU time in the frame's."""
        tracing = self._tracing
        results, t0, t1 = tracing.result(handle)
        if self._tracer_proc is not None:  # the child's CPU time: not in this process's
            self._child_cpu_ms += tracing.cpu_seconds * 1e3
        self._tracer_cpu_ms = tracing.cpu_seconds * 1e3
        if not self._build_reported and tracing.build_seconds is not None:
            self._timings["kd-tree build"] = tracing.build_seconds * 1e3
            self._build_reported = True
        self._record(RT_LANE, "cpu ray tracing", t0, t1)
        return results[0], results[1]

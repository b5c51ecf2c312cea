"""The renderer: its set-up, the frame's schedule (``render``), timing and read-back; the volume
and ray-tracing stages are its bases (``volumes.py``, ``tracing.py``)."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager

import numpy as np

from serenity.colour import reinhard_srgb
from serenity.config import RenderConfig, changed_settings, check_image_size
from serenity.device import resolve_device
from serenity.errors import SerenityError
from serenity.frame.record import MAIN_LANE, READ_BACK, STAGES, VOLUME_LANE, VOLUME_THREAD, ChangeTracker, Frame
from serenity.frame.tracing import RayTracingStages
from serenity.frame.volumes import VolumeStages
from serenity.kernels.atmosphere import scene_sun_irradiance
from serenity.kernels.tracers import RestartingTracer
from serenity.raster.composite import CompositePass
from serenity.raster.context import finish, get_context
from serenity.raster.deferred import DeferredPass, LightingInputs
from serenity.raster.fxaa import FXAAPass
from serenity.raster.gbuffer import GBufferPass
from serenity.raster.interop import read_texture
from serenity.raster.lowres import LowResGuide
from serenity.raster.raycast import RayCastPass
from serenity.raster.rt_gbuffer import RTGBufferUpload
from serenity.raster.scene_gl import SceneGL
from serenity.raster.shadow import STAGGER_PAD, ShadowPass, fit_shadow_cascades
from serenity.raster.ssao import SSAOPass
from serenity.raster.taa import TAAPass, halton
from serenity.raster.tonemap import TonemapPass
from serenity.threads import lower_thread_priority, single_threaded_blas


def lighting_inputs(scene, config: RenderConfig, view_proj: np.ndarray) -> LightingInputs:
    """The deferred passes' uniforms for ``scene``'s sun, sky and camera (radiometric units)."""
    sun, sky, cam = scene.sun, scene.sky, scene.camera
    e_sun = scene_sun_irradiance(scene)
    return LightingInputs(
        sun_direction=sun.direction,
        sun_irradiance=e_sun,
        sun_radiance=e_sun / sun.solid_angle,
        sun_cos_radius=sun.cos_angular_radius,
        sky_radiance=sky.radiance,
        ambient_irradiance=math.pi * sky.radiance if config.ambient == "constant" else np.zeros(3),
        camera_position=cam.position,
        view_proj=view_proj,
        inv_view_proj=np.linalg.inv(view_proj),
        camera_forward=cam.forward,
        sun_tan_half=sun.tan_angular_radius,
        shadow=config.shadow,
    )


class Renderer(VolumeStages, RayTracingStages):
    """Renders a ``Scene`` at a fixed size. Static data (geometry, textures, the kd-tree) is
    built and uploaded once; each ``render()`` redoes only what the frame's changes need.

    ``config`` None renders the default quality preset (``RenderConfig.preset()``:
    ``DEFAULT_QUALITY``), the one every ``serenity`` command uses. ``close()`` stops the worker
    thread and the tracer process; a ``with Renderer(...) as r:`` block closes it on the way out."""

    def __init__(self, scene, width: int, height: int, device: str | None = None,
                 config: RenderConfig | None = None):
        check_image_size(width, height)
        self.scene = scene
        self.width, self.height = int(width), int(height)
        self.config = config if config is not None else RenderConfig.preset()
        self.device = resolve_device(device)
        self.ctx = get_context()
        self._timings: dict[str, float] = {}
        self._events: list[tuple[str, str, float, float]] = []
        self._lock = threading.Lock()
        self._t_frame = time.perf_counter()
        with self._stage("upload"):
            cfg = self.config
            self.traces = cfg.rt.enabled and any(m.needs_ray_tracing for m in scene.materials)
            self._tracing: RestartingTracer | None = None  # the ray tracer (``_ensure_tracer``)
            self._build_reported = False
            if self.traces and self._tracer_in_process():  # first: its start-up runs beside the set-up below
                self._ensure_tracer()
            self.scene_gl = SceneGL(self.ctx, scene)
            self.shadow_size = cfg.shadow.size_for(self.width, self.height)
            self.shadow_pass = ShadowPass(self.ctx, self.scene_gl, self.shadow_size, cfg.shadow.cascades)
            self.gbuffer_pass = GBufferPass(self.ctx, self.scene_gl, cfg.texture_taps)
            self.gbuffer_pass.lod_pixel_error = self.shadow_pass.lod_pixel_error = cfg.lod_pixel_error
            self.deferred_pass = DeferredPass(self.ctx)
            self.tonemap_pass = TonemapPass(self.ctx)
            self.ssao_pass = SSAOPass(self.ctx, cfg.ssao, cfg.indirect.scale, cfg.indirect.tile_balance)
            self.lowres_guide = LowResGuide(self.ctx, cfg.indirect.scale, cfg.indirect.tile_balance)
            for p in (self.gbuffer_pass, self.deferred_pass, self.tonemap_pass, self.ssao_pass, self.lowres_guide):
                p.resize(self.width, self.height)
            self.fxaa_pass = FXAAPass(self.ctx) if cfg.antialiasing == "fxaa" else None
            if self.fxaa_pass is not None:
                self.fxaa_pass.resize(self.width, self.height)
            self.taa_pass = TAAPass(self.ctx) if cfg.antialiasing == "taa" else None
            if self.taa_pass is not None:
                self.taa_pass.resize(self.width, self.height)
            # ray tracing only where a material needs it (paper §9); in this process the kd-tree
            # waits for the first frame that actually shows such a pixel
            if self.traces:
                self.raycast_pass = RayCastPass(self.ctx, self.scene_gl)
                self.raycast_pass.resize(self.width, self.height)
                self.osm_pass = (ShadowPass(self.ctx, self.scene_gl, cfg.rt.osm_size, 3)
                                 if cfg.rt.sun_shadows == "osm" else None)
                if self.osm_pass is not None:
                    self.osm_pass.lod_pixel_error = cfg.lod_pixel_error
                self.rt_upload = RTGBufferUpload(self.ctx)
                self.rt_upload.resize(self.width, self.height)
                self.rt_deferred = DeferredPass(self.ctx)
                self.rt_deferred.resize(self.width, 2 * self.height)
                self.composite_pass = CompositePass(self.ctx)
            self._init_gi()
            # the volumes' kernels beside the GL passes (``_render``): on the CPU only, where the GL
            # passes are llvmpipe's threads and the kernels would otherwise wait for them in turn
            # (where the sky volume's method allows: ``SkyVolumeMethod.on_volume_worker``)
            self._sky_in_worker = self.sky_volume is not None and self.sky_volume.method.on_volume_worker
            self._volume_pool = (ThreadPoolExecutor(max_workers=1, thread_name_prefix=VOLUME_THREAD,
                                                    initializer=lower_thread_priority,
                                                    initargs=(cfg.schedule.volume_nice,))
                                 if self._volumes_in_worker() else None)
        self._upload_ms = self._timings.pop("upload")
        self._first = True
        self._changes = ChangeTracker()
        self._lpv_inputs_version = 0  # counts the changes of the LPV's inputs (its update key)
        self._lpv_pending_upload = False  # the LPV changed since its textures were uploaded
        self._lpv_sky_version = 0  # the sky volume's version the LPV's sky-light VPLs were last made from

    # ------------------------------------------------------------------------------------ timing

    def _record(self, lane: str, name: str, t0: float, t1: float) -> None:
        with self._lock:
            self._timings[name] = self._timings.get(name, 0.0) + (t1 - t0) * 1e3
            self._events.append((lane, name, (t0 - self._t_frame) * 1e3, (t1 - self._t_frame) * 1e3))

    @contextmanager
    def _stage(self, name: str, gl: bool = True) -> Iterator[None]:
        sync = self.config.schedule.sync_stages
        if not gl and sync == "cpu":  # the queued GL work first: it would contend with this stage's
            finish(self.ctx)           # CPU work for the cores
        t0 = time.perf_counter()
        yield
        if gl and sync == "each":
            finish(self.ctx)  # the GIL released while llvmpipe renders: the volume worker goes on
        self._record(MAIN_LANE, name, t0, time.perf_counter())

    def _on_volume_worker(self) -> bool:
        """Whether the calling thread is the volume worker (the thread that renders may be any)."""
        return self._volume_pool is not None and threading.current_thread().name.startswith(VOLUME_THREAD)

    @contextmanager
    def _cpu_stage(self, name: str) -> Iterator[None]:
        """A stage of host work (numpy, Warp launches) on whichever thread runs it: the volume worker's
        lane when that is the calling thread, else ``_stage`` (no GL call here: the worker has none)."""
        if not self._on_volume_worker():
            with self._stage(name, gl=False):
                yield
            return
        t0 = time.perf_counter()
        yield
        self._record(VOLUME_LANE, name, t0, time.perf_counter())


    # ------------------------------------------------------------------------------------ frame

    def render(self, read_back: bool | Iterable[str] = True, jitter: tuple[float, float] | None = None) -> Frame:
        """Render the scene's current camera and sun: the diagram of docs/architecture.md ("The
        frame"), one method per box. ``read_back`` says what comes back to the host: True =
        everything (hdr, ldr and the AOVs), False = nothing (for a caller that draws
        ``self.outputs`` itself, e.g. the viewer's window), or a subset of {"hdr", "ldr", "aovs"}
        (``serenity bench`` and the viewer read nothing: every read stalls the GL pipeline; a NaN or
        infinite pixel still shows in ``Frame.nonfinite_pixels``). ``jitter``:
        sub-pixel offset (x right, y up; pixels) of the projection, for :meth:`render_accumulated`;
        None: the temporal anti-aliasing's next offset with ``antialiasing = "taa"`` (``raster/taa.py``),
        else none. A given offset replaces TAA's (the resolve then takes that one out)."""
        wanted = set(READ_BACK) if read_back is True else set(read_back or ())
        if not wanted <= set(READ_BACK):
            raise SerenityError(f"read_back must be a bool or a subset of {READ_BACK}, got {read_back!r}")
        with single_threaded_blas():  # the frame's own threads (llvmpipe, Warp launches) fill the cores
            try:
                return self._render(wanted, jitter)
            except BaseException:
                self._abandon_frame()
                raise

    def _abandon_frame(self) -> None:
        """After a frame that raised: let the volume worker finish what the frame queued (the next
        frame reads what it writes), so that the next frame starts as any other; the ray tracer drops
        hits the frame did not collect at its next submit."""
        pool = getattr(self, "_volume_pool", None)
        if pool is not None:
            try:
                pool.submit(lambda: None).result()  # one worker: runs after everything queued before it
            except RuntimeError:  # shut down (closed)
                pass

    def _render(self, wanted: set[str], jitter: tuple[float, float] | None) -> Frame:
        self._begin_frame()
        cam = self.scene.camera
        proj = cam.projection_matrix(self.width / self.height)
        taa = self.taa_pass
        if taa is not None:  # its history restarts on a camera cut or a new config
            own = taa.begin(cam, float(np.linalg.norm(np.subtract(*self.scene_gl.bounds))), self.config)
            jitter = own if jitter is None else jitter
            unjittered = proj @ cam.view_matrix()
        jitter = (0.0, 0.0) if jitter is None else jitter
        if jitter[0] or jitter[1]:  # shift NDC by 2·jitter/size: x_ndc += m[0,2]·z/(−z) = −m[0,2]
            proj[0, 2] -= 2.0 * float(jitter[0]) / self.width
            proj[1, 2] -= 2.0 * float(jitter[1]) / self.height
        view_proj = proj @ cam.view_matrix()
        light = lighting_inputs(self.scene, self.config, view_proj)
        pool = self._volume_pool
        sky_job = lpv_plan = None
        if pool is not None:
            # asked before the sky volume's update starts (the worker changes what it reads)
            sky_may_change = self.sky_volume is not None and self.sky_volume.may_change()
            if self._sky_in_worker:  # the sky volume's update needs only the sun: it starts at once
                sky_job = pool.submit(self._compute_sky)
            # so does the RSM: drawn and read back first, so that the LPV's kernels can start as soon
            # as the G-buffer's samples are read (it shortens the worker's chain, which the main thread
            # waits for at 320×180)
            lpv_plan = self._plan_lpv(light, sky_may_change)
        with self._stage("g-buffer"):
            gbuf = self.gbuffer_pass.render(view_proj, self.scene.camera.position)
        # sync 1 right after the G-buffer, or with tracer_start = "idle" (or "auto" and the tracer in
        # a scheduling group of its own) where the main thread is about to wait for the volume
        # worker, in a frame that gives the worker work
        late = pool is not None and self._tracer_starts_idle() and (
            (sky_job is not None and sky_may_change) or lpv_plan is not None)
        if not late:
            rcb, join = self._start_ray_tracing(view_proj, gbuf)        # sync 1
        if pool is None:
            # the volumes first: their Warp kernels mostly keep one core busy, so the tracer process
            # gets the other; the GL passes that follow keep both busy (llvmpipe's threads)
            self._update_volumes(gbuf, light)
            shadow, ao, guide = self._main_view(view_proj, gbuf)
        else:  # the LPV's kernels in the worker too, after the sky's; the main view's GL passes beside them
            if self.sky_volume is not None and sky_job is None:  # a main-thread sky volume: here, in turn
                self._upload_sky(self._compute_sky())
            lpv_job = self._start_lpv(gbuf, lpv_plan)
            shadow, ao, guide = self._main_view(view_proj, gbuf)
            if late:
                rcb, join = self._start_ray_tracing(view_proj, gbuf)
            with self._stage("wait for volumes", gl=False):
                prepared = sky_job.result() if sky_job is not None else None
                if lpv_job is not None:
                    lpv_job.result()
            self._upload_sky(prepared)
            self._upload_lpv()
        lit = self._light_main_view(gbuf, shadow, light, ao, guide)
        out_hdr = self._ray_traced_views(rcb, join, gbuf, lit, light)  # sync 2
        if self.fxaa_pass is not None:
            with self._stage("anti-aliasing"):
                out_hdr = self.fxaa_pass.render(out_hdr, self.config.exposure)
        if taa is not None:
            with self._stage("anti-aliasing"):
                out_hdr = taa.render(out_hdr, gbuf, cam, unjittered, jitter, self.config.exposure)
        with self._stage("tone map"):
            self.tonemap_pass.render(out_hdr, self.config.exposure)
        #: this frame's GL textures: hdr (lit + composited, RGBA32F), ldr (tone-mapped sRGB, RGBA8),
        #: direct, ao (None without SSAO; 1/indirect.scale resolution), the main view's gbuffer, and
        #: rcb (the read-back RayCastingBuffer, None without ray tracing); valid until the next render()
        self.outputs = {"hdr": out_hdr, "ldr": self.tonemap_pass.ldr, "direct": lit.direct, "ao": ao,
                        "gbuffer": gbuf, "rcb": rcb}
        hdr, ldr, aovs = self._read_back(wanted, out_hdr, gbuf, lit, ao, rcb, cam)
        finish(self.ctx)  # the frame is done when its GL work is (sync_stages other than "each" leave some queued)
        return self._end_frame(hdr, ldr, aovs, rcb)

    def render_accumulated(self, samples: int) -> Frame:
        """Temporal accumulation on a static camera: the mean linear HDR of ``samples`` frames whose
        projections are jittered by the Halton(2, 3) sequence within the pixel (the first unjittered),
        i.e. ``samples`` sub-pixel positions box-filtered as the reference's pixel filter does. An
        interactive viewer shows the running mean after each frame, so the extra cost per displayed
        frame is one average; the image converges over ``samples`` frames. The AOVs are those of the
        unjittered first frame; timings are the last frame's, ``wall_ms`` the sum."""
        if not (isinstance(samples, int) and 1 <= samples <= 1024):
            raise SerenityError(f"samples must be an int in 1..1024, got {samples!r}")
        first, acc, wall = None, None, 0.0
        for i in range(samples):
            f = self.render(read_back=("hdr",) if i else ("hdr", "aovs"),
                            jitter=(halton(i, 2) - 0.5, halton(i, 3) - 0.5) if i else (0.0, 0.0))
            wall += f.wall_ms
            first = first or f
            acc = f.hdr.astype(np.float64) if acc is None else acc + f.hdr
        hdr = (acc / samples).astype(np.float32)
        return Frame(hdr=hdr, ldr=reinhard_srgb(hdr, f.exposure), aovs=first.aovs, timings=f.timings,
                     exposure=f.exposure, wall_ms=wall, events=f.events, rays=f.rays,
                     nonfinite_pixels=int((~np.isfinite(hdr)).any(axis=-1).sum()))

    def _begin_frame(self) -> None:
        self._timings, self._events = {}, []
        self._gbuffer_images = {}
        self._t_frame = time.perf_counter()
        self._cpu_frame = time.process_time()
        self._child_cpu_ms = 0.0
        self._tracer_cpu_ms = None
        if self._first:
            self._timings["upload"] = self._upload_ms
            self._first = False

    def _end_frame(self, hdr, ldr, aovs, rcb) -> Frame:
        nonfinite = self.tonemap_pass.nonfinite_pixels()  # 4 bytes, after the frame's finish()
        wall = (time.perf_counter() - self._t_frame) * 1e3 + self._timings.get("upload", 0.0)
        cpu = (time.process_time() - self._cpu_frame) * 1e3 + self._child_cpu_ms
        timings = {k: self._timings[k] for k in sorted(self._timings, key=STAGES.index)}  # pipeline order
        return Frame(hdr=hdr, ldr=ldr, aovs=aovs, timings=timings, exposure=self.config.exposure,
                     wall_ms=wall, events=sorted(self._events, key=lambda e: e[2]),
                     rays=0 if rcb is None else rcb.count, cpu_ms=cpu,
                     nonfinite_pixels=nonfinite, tracer_cpu_ms=self._tracer_cpu_ms)


    def _main_view(self, view_proj, gbuf):
        """Sun shadow cascades (paper §6) and SSAO (paper §3) of the main view (its G-buffer is
        drawn first: the ray-casting buffer is drawn against its depth), and the low-res guide the
        SSAO blur and the indirect light's upsampling share. Returns (shadow maps, AO or None, guide
        or None)."""
        cfg, scene, cam = self.config, self.scene, self.scene.camera
        with self._stage("shadow maps (CSM)"):
            sc = cfg.shadow
            cascades = fit_shadow_cascades(cam, self.width / self.height, scene.sun.direction, self.scene_gl.bounds,
                                           sc.cascades, self.shadow_size, sc.split_lambda, sc.max_distance,
                                           pad=STAGGER_PAD if sc.stagger else 0.0)
            shadow = self.shadow_pass.render(cascades, stagger=sc.stagger)
        ao = guide = None
        if cfg.ssao.enabled or self.lowres is not None:
            with self._stage("low-res guide"):
                guide = self.lowres_guide.render(gbuf, cam.position, cam.forward)
        if cfg.ssao.enabled:
            with self._stage("ssao"):
                ao = self.ssao_pass.render(gbuf, view_proj, cam.position, cam.forward, guide)
        return shadow, ao, guide


    def _light_main_view(self, gbuf, shadow, light: LightingInputs, ao, guide):
        """Phong + CSM/PCSS and the sky volume's and the LPV's light: at full resolution added onto
        the lit image; at 1/indirect.scale drawn first and upsampled by the deferred pass."""
        sky_gl = self.sky_gl if self.sky_volume is not None else None
        vis = None
        if self.config.shadow.visibility != "pixel":  # the sun's visibility sampled sparsely, upsampled
            with self._stage("sun visibility"):
                vis = self.deferred_pass.render_visibility(gbuf, shadow, light, self.config.shadow.visibility)
        lo = self.lowres
        if lo is None:  # full resolution: the indirect passes add onto the lit image
            with self._stage("direct lighting"):
                lit = self.deferred_pass.render(gbuf, shadow, light, ao, sky=sky_gl, visibility=vis)
            self._indirect_passes(lit.hdr, gbuf, ao, sky_gl, full_res=True)
            return lit
        # reduced resolution: the indirect passes first, into the low-res targets; the deferred pass
        # then upsamples them as it lights each pixel (no second full-resolution pass)
        lo.clear()
        lo.use_depth(self.lowres_guide.depth)  # the texels' classes: the passes shade only theirs
        self._indirect_passes(lo, gbuf, ao, sky_gl, full_res=False)
        refined = self.indirect_refinement
        if refined is not None:
            cam = self.scene.camera
            with self._stage("indirect refinement"):
                refined.classify(gbuf, self.lowres_guide, cam.position, cam.forward)
            self._indirect_passes(refined, gbuf, ao, sky_gl, full_res=False)  # timed as their techniques
        with self._stage("direct lighting"):  # the upsampling included (and the indirect light's history)
            history = None
            if self.indirect_history is not None:
                history = (self.indirect_history, self.scene.camera, self.config.indirect.history)
            return self.deferred_pass.render(gbuf, shadow, light, ao, sky=sky_gl, upsample=(lo, guide, refined),
                                             visibility=vis, history=history)

    def _indirect_passes(self, target, gbuf, ao, sky_gl, full_res: bool) -> None:
        """The sky volume's and the LPV's light of the main view, added onto ``target``."""
        cam = self.scene.camera
        if sky_gl is not None:
            with self._stage("sky lighting"):
                (self.sky_pass if full_res else self.sky_pass_lo).render(target, gbuf, sky_gl.bind, cam.position, ao)
        terms = self._lpv_terms()
        if terms:
            with self._stage("lpv lighting"):
                (self.lpv_pass if full_res else self.lpv_pass_lo).render(target, gbuf, self.lpv_gl.bind,
                                                                         cam.position, ao, **terms)






    def _read_back(self, wanted: set[str], out_hdr, gbuf, lit, ao, rcb, cam):
        hdr = ldr = None
        aovs: dict[str, np.ndarray] = {}
        if not wanted:
            return hdr, ldr, aovs
        with self._stage("readback"):
            if "hdr" in wanted:
                hdr = read_texture(out_hdr, 3)
            if "ldr" in wanted:
                ldr = self.tonemap_pass.read()
            if "aovs" in wanted:
                aovs = self._read_aovs(gbuf, lit, cam)
                if ao is not None:
                    aovs["ao"] = self._full_res(read_texture(ao, 1))
                if rcb is not None:
                    aovs["rt_mask"] = rcb.mask()[..., None].astype(np.float32)
        return hdr, ldr, aovs

    def _gbuffer_image(self, gbuf, name: str) -> np.ndarray:
        """A main-view G-buffer target read back to (H, W, 4) float32, once per frame (the LPV's
        VPLs and surfels and the AOVs both need position, normal and albedo)."""
        img = self._gbuffer_images.get(name)
        if img is None:
            img = self._gbuffer_images[name] = read_texture(getattr(gbuf, name), 4)
        return img

    def _read_aovs(self, gbuf, lit, cam) -> dict[str, np.ndarray]:
        pos = self._gbuffer_image(gbuf, "position")
        covered = pos[..., 3] > 0
        depth = np.where(covered, (pos[..., :3] - cam.position) @ cam.forward, np.inf).astype(np.float32)
        albedo = self._gbuffer_image(gbuf, "albedo")
        return {
            "albedo": np.ascontiguousarray(albedo[..., :3]),
            # the G-buffer keeps the material index in albedo.a (exact in f16); -1 = background
            "material": np.where(covered, albedo[..., 3], -1.0).astype(np.float32)[..., None],
            "normal": np.ascontiguousarray(self._gbuffer_image(gbuf, "normal")[..., :3]),
            "position": np.where(covered[..., None], pos[..., :3], 0.0).astype(np.float32),
            "depth": depth[..., None],
            "direct": read_texture(lit.direct, 3),
        }

    def _full_res(self, img: np.ndarray) -> np.ndarray:
        """A 1/indirect.scale image (SSAO) as a full-size AOV: each texel repeated over its block.
        Texel (i, j) covers the pixels (i·s.., j·s..) counted from GL's bottom-left corner, so in the
        top-down image a partial block row (height not a multiple of s) is the top one."""
        s = self.config.indirect.scale
        if s == 1:
            return img
        full = np.repeat(np.repeat(img, s, axis=0), s, axis=1)
        return np.ascontiguousarray(full[full.shape[0] - self.height:, :self.width])

    LIVE_SETTINGS = frozenset({"exposure", "rt.reflections", "rt.refractions", "ssao.enabled", "shadow.filter",
                               "lpv.diffuse", "lpv.glossy"})
    """The settings every frame reads afresh (``reconfigure`` changes them between frames); every other
    setting is built into the renderer's passes, volumes or tracer, and a change of it needs a new
    ``Renderer``. (A technique switched on or off, e.g. both of the LPV's terms or both ray-traced
    views off, is its ``enabled``, ``lpv.enabled`` or ``rt.enabled``: a rebuild.)"""

    @classmethod
    def needs_rebuild(cls, old: RenderConfig, new: RenderConfig) -> bool:
        """Whether a renderer built with ``old`` must be built anew to render with ``new``."""
        return any(s not in cls.LIVE_SETTINGS for s in changed_settings(old, new))

    def reconfigure(self, config: RenderConfig) -> None:
        """Render the next frames with ``config``, which may differ from this renderer's only in
        ``LIVE_SETTINGS``; a ``SerenityError`` names the settings that need a new renderer."""
        rebuild = [s for s in changed_settings(self.config, config) if s not in self.LIVE_SETTINGS]
        if rebuild:
            raise SerenityError(f"{', '.join(rebuild)} cannot change on a built renderer: build a new Renderer "
                                f"(live: {', '.join(sorted(self.LIVE_SETTINGS))})")
        self.config = config

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Stop the ray tracer (its worker thread or process) and the volume worker (the GL objects
        go with the process's context). Closing twice is harmless."""
        pool = getattr(self, "_volume_pool", None)
        if pool is not None:
            pool.shutdown(wait=True)
        tracing = getattr(self, "_tracing", None)
        if tracing is not None:
            tracing.close()
            self._tracing = None

    def __del__(self):
        tracing = getattr(self, "_tracing", None)
        if tracing is not None:
            tracing.close()



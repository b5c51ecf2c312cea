"""The frame pipeline of docs/architecture.md ("The frame") and paper §10 as code: named stages, no maths, each timed.

    renderer = Renderer(scene, 640, 360)
    frame = renderer.render()          # Frame(hdr, ldr, aovs, timings, events)

The schedule (paper §10): the ray-casting buffer is drawn first and read back (sync 1); the CPU
ray tracing of the reflective/refractive pixels starts in the tracer process (on CUDA: a worker
thread); meanwhile the main thread issues the GL work (shadow cascades, G-buffer, RSM, SSAO, the
lighting passes) and the volume kernels (LPV, the sky volume); then it joins the tracer (sync 2),
uploads the ray-traced G-buffers, lights them with the overlapped shadow maps and composites them
with a Fresnel blend; last the tone map. (With a volume worker the tracer process runs in a session of its own by
default, ``RenderConfig.tracer_session``, and where that gives it a scheduling group of its own sync
1 moves to just before the main thread waits for the volume worker, ``tracer_start = "auto"``;
with ``tracer_nice`` they set how the tracer process shares the cores.) ``RenderConfig.overlap=False``
(``--serial``) runs the ray tracing inline before the GL work, for comparison. ``STAGES`` names every stage in order;
each stage of ``Renderer.render`` is one short method below.

Stage names follow the paper's Table 1 where it has one. ``Frame.timings`` holds each stage's
milliseconds (the worker's ``cpu ray tracing`` included); ``Frame.wall_ms`` is the frame's real
duration, less than the sum when the tracer overlaps the GL work; ``Frame.events`` is the
timeline (lane, stage, start, end in ms from the frame start) that ``serenity bench`` charts.

Stage timing: GL is asynchronous, so with ``RenderConfig.sync_stages`` = "each" (default) each GL
stage ends with ``ctx.finish()`` and is timed by the wall clock; "cpu" waits only before the stages
that run on the CPU, so a GL stage's time is then what it took to queue and the queued work shows up
in the next wait (or the frame's final one). GL timer queries would not perturb the
pipeline, but Mesa's llvmpipe returns garbage for them (elapsed = 0xFFFFFFFF), and the CPU
"GPU" of this project's CI runs the GL work synchronously anyway.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from serenity.colour import reinhard_srgb
from serenity.config import RenderConfig, check_image_size
from serenity.device import resolve_device
from serenity.errors import SerenityError
from serenity.kernels.atmosphere import scene_sun_irradiance
from serenity.kernels.lpv import (
    LightPropagationVolume,
    rsm_surfels,
    sample_gbuffer,
    sky_vpls_from_samples,
    surfels_from_samples,
)
from serenity.kernels.skyvolume import SkyVolume
from serenity.kernels.tracers import InlineTracer, RestartingTracer, ThreadTracer, TracerProcess
from serenity.raster.composite import CompositePass
from serenity.raster.context import finish, get_context
from serenity.raster.deferred import DeferredPass, LightingInputs
from serenity.raster.fxaa import FXAAPass
from serenity.raster.gbuffer import GBufferPass
from serenity.raster.indirect import IndirectPass, LowResIndirect
from serenity.raster.interop import read_texture
from serenity.raster.lowres import GBufferSamples, IndirectRefinement, LowResGuide
from serenity.raster.lpv_gl import LPVTexturesGL, lookup_defines
from serenity.raster.raycast import RayCastingBuffer, RayCastPass
from serenity.raster.rsm import RSMPass
from serenity.raster.rt_gbuffer import RTGBufferUpload
from serenity.raster.scene_gl import SceneGL
from serenity.raster.shadow import STAGGER_PAD, ShadowPass, fit_overlapped, fit_shadow_cascades
from serenity.raster.sky import SkyTexturesGL
from serenity.raster.ssao import SSAOPass
from serenity.raster.taa import TAAPass, halton
from serenity.raster.temporal import IndirectHistory
from serenity.raster.tonemap import TonemapPass
from serenity.threads import lower_thread_priority, single_threaded_blas

MAIN_LANE = "main (GL + volumes)"
STAGES = (
    "upload",
    "g-buffer", "ray casting buffer", "kd-tree build", "cpu ray tracing",  # sync 1, the tracer starts
    "sky volume build", "sky volume update", "wait for volumes", "sky upload",  # paper §7
    "rsm", "lpv inputs", "lpv inject", "lpv propagate", "lpv blend",   # paper §8
    "shadow maps (CSM)", "low-res guide", "ssao", "lpv upload",        # the main view
    "sun visibility", "indirect refinement", "direct lighting", "sky lighting", "lpv lighting",
    "wait for ray tracing", "rt g-buffer upload", "shadow maps (OSM)",  # sync 2, paper §9
    "rt direct lighting", "rt sky lighting", "rt lpv lighting", "composite",
    "anti-aliasing", "tone map", "readback",
)
"""Every stage a frame can time, in pipeline order (``Frame.timings`` keys are a subsequence; with
``indirect_scale`` > 1 "sky lighting" and "lpv lighting" run at low resolution before "direct
lighting", which then includes their upsampling: one full-resolution pass). "rsm" includes the
read-back of the RSM and of the G-buffer's samples; with the volume worker
(``RenderConfig.overlap_volumes``) "sky volume update", "lpv inputs", "lpv inject" and "lpv
propagate" run on its lane beside the GL stages, and "wait for volumes" is what the main thread
waited for them. "lpv propagate" includes a step of the LPV's temporal blend; "lpv blend" is that
step alone, in a frame whose LPV inputs did not change while its light is still blended in
(``LPVConfig.temporal_blend``)."""
LPV_UPDATE_STAGES = ("rsm", "lpv inputs", "lpv inject", "lpv propagate", "lpv upload")
"""The parts of the paper's "Light Propagation Volumes Update" (Table 1)."""
SKY_UPDATE_STAGES = ("sky volume update", "sky upload")
"""The sky volume's per-frame update, which the paper's Table 1 leaves out of the frame time."""
READ_BACK = ("hdr", "ldr", "aovs")
"""What ``Renderer.render(read_back=...)`` can bring back to the host."""
RT_LANE = "worker (CPU ray tracing)"
VOLUME_LANE = "worker (volume kernels)"
VOLUME_THREAD = "serenity-volumes"  # the volume worker's thread name prefix


@dataclass
class Frame:
    """One rendered frame.

    hdr: (H, W, 3) float32 linear radiance, W·m⁻²·sr⁻¹ (row 0 = top).
    ldr: (H, W, 3) uint8 sRGB after exposure + Reinhard.
    aovs: named (H, W, C) float32 layers: albedo, normal (world), position (world, m),
        depth (H, W, 1; view-space distance along the camera axis, m; inf = background),
        material (H, W, 1; index into ``scene.materials``, -1 = background), direct,
        ao (H, W, 1; SSAO, 1 = open; when enabled), rt_mask (H, W, 1; 1 where rays were traced).
    timings: stage name → milliseconds, in pipeline order (the worker's stages included).
    wall_ms: the frame's duration; below ``sum(timings)`` when ray tracing overlapped GL work.
    events: (lane, stage, start_ms, end_ms) from the frame's start — the timeline.
    cpu_ms: CPU time the frame took on every core, ms: this process's threads (the GL driver's, the
    Warp launches', Python's) plus the tracer process's work. ``cpu_ms / cores`` bounds the wall
    time from below whatever the schedule (``serenity bench`` reports it).
    nonfinite_pixels: how many pixels of the HDR image are NaN or infinite, counted on the GL side
    by the tone-mapping pass (known without reading the image back).
    tracer_cpu_ms: CPU time of the "cpu ray tracing" stage, ms: the tracer process's (overlapped, on
    the CPU) or this process's while it traced inline (serial: no other work runs then); None when
    nothing was traced or the trace ran on the CUDA worker thread. Beside the stage's wall time it
    says whether the tracer waited for a core or did more work (``benchmarks/bench_tracer_nice.py``).

    With ``render(read_back=False)`` nothing leaves the GL context: hdr and ldr are None, aovs is
    empty, and the images stay in ``Renderer.outputs``.
    """

    hdr: np.ndarray | None
    ldr: np.ndarray | None
    aovs: dict[str, np.ndarray]
    timings: dict[str, float] = field(default_factory=dict)
    exposure: float = 1.0
    wall_ms: float = 0.0
    events: list[tuple[str, str, float, float]] = field(default_factory=list)
    rays: int = 0
    cpu_ms: float = 0.0
    nonfinite_pixels: int = 0
    tracer_cpu_ms: float | None = None

    @property
    def total_ms(self) -> float:
        """Sum of the stage timings (the serial cost)."""
        return float(sum(self.timings.values()))


class ChangeTracker:
    """What changed since the previous frame, by named parts (the sun, the sky, the camera): each
    ``changed(**parts)`` call compares every part's value with the one it saw last time."""

    def __init__(self):
        self._seen: dict[str, bytes] = {}

    def changed(self, **parts) -> set[str]:
        out = set()
        for name, value in parts.items():
            key = np.asarray(value, np.float64).tobytes()
            if self._seen.get(name) != key:
                out.add(name)
                self._seen[name] = key
        return out

    def forget(self, *names: str) -> None:
        for name in names:
            self._seen.pop(name, None)


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


class Renderer:
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
            self.traces = cfg.ray_tracing and any(m.needs_ray_tracing for m in scene.materials)
            self._tracing: RestartingTracer | None = None  # the ray tracer (``_ensure_tracer``)
            self._build_reported = False
            if self.traces and self._tracer_in_process():  # first: its start-up runs beside the set-up below
                self._ensure_tracer()
            self.scene_gl = SceneGL(self.ctx, scene)
            self.shadow_size = cfg.shadow.size_for(self.width, self.height)
            self.shadow_pass = ShadowPass(self.ctx, self.scene_gl, self.shadow_size, cfg.shadow.cascades)
            self.gbuffer_pass = GBufferPass(self.ctx, self.scene_gl, cfg.texture_taps)
            self.deferred_pass = DeferredPass(self.ctx)
            self.tonemap_pass = TonemapPass(self.ctx)
            self.ssao_pass = SSAOPass(self.ctx, cfg.ssao, cfg.indirect_scale, cfg.lowres_tile_balance)
            self.lowres_guide = LowResGuide(self.ctx, cfg.indirect_scale, cfg.lowres_tile_balance)
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
                self.osm_pass = (ShadowPass(self.ctx, self.scene_gl, cfg.osm_size, 3)
                                 if cfg.rt_sun_shadows == "osm" else None)
                self.rt_upload = RTGBufferUpload(self.ctx)
                self.rt_upload.resize(self.width, self.height)
                self.rt_deferred = DeferredPass(self.ctx)
                self.rt_deferred.resize(self.width, 2 * self.height)
                self.composite_pass = CompositePass(self.ctx)
            self._init_gi()
            # the volumes' kernels beside the GL passes (``_render``): on the CPU only, where the GL
            # passes are llvmpipe's threads and the kernels would otherwise wait for them in turn
            # ("gather" sky volumes stay on the main thread: their passes are split over every core
            # already, and beside the GL passes they only slowed both)
            self._sky_in_worker = self.sky_volume is not None and cfg.sky.method != "gather"
            self._volume_pool = (ThreadPoolExecutor(max_workers=1, thread_name_prefix=VOLUME_THREAD,
                                                    initializer=lower_thread_priority, initargs=(cfg.volume_nice,))
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
        sync = self.config.sync_stages
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

    def _init_gi(self) -> None:
        """The volumes: the sky irradiance volume (paper §7) and the light propagation volumes
        (paper §8), each when enabled."""
        cfg, ctx = self.config, self.ctx
        self.lowres = None
        self.indirect_history = None
        self.indirect_refinement = None
        if cfg.indirect_scale > 1 and (cfg.sky.enabled or cfg.lpv.enabled):
            self.lowres = LowResIndirect(ctx, cfg.indirect_scale, cfg.lowres_tile_balance)
            self.lowres.resize(self.width, self.height)
            if cfg.indirect_refine_below > 0.0:  # full resolution where the upsampling has no match
                self.indirect_refinement = IndirectRefinement(ctx, cfg.indirect_scale, cfg.indirect_refine_below)
                self.indirect_refinement.resize(self.width, self.height)
            if cfg.indirect_history < 1.0:  # the upsampled light blended with the last frame's (raster/temporal.py)
                self.indirect_history = IndirectHistory(ctx)
                self.indirect_history.resize(self.width, self.height)
        self.sky_volume = None
        self._sky_map_version = -1
        self._sky_volume_version = 0  # counts the sky volume's updates (the sky-light VPLs read it)
        if cfg.sky.enabled:
            self.sky_volume = SkyVolume(self.scene, cfg.sky, self.device)
            self.sky_gl = SkyTexturesGL(ctx)
            sky_defines = {"SKY_GLOSSY": int(cfg.sky.glossy),
                           "SKY_VISIBILITY": int(cfg.sky.method == "gather" and cfg.sky.gather_visibility)}
            self.sky_pass = IndirectPass(ctx, "sky", defines=sky_defines)
            self.sky_pass_lo = IndirectPass(ctx, "sky", lowres=True, defines=sky_defines) if self.lowres else None
            self._sky_built = False
            self._sky_map_version = -1
        self.lpv = None
        if cfg.lpv.enabled:
            self.rsm_pass = RSMPass(ctx, self.scene_gl, cfg.rsm_size)
            self.lpv = LightPropagationVolume(cfg.lpv, self.device)
            self.gbuffer_samples = GBufferSamples(ctx, cfg.sky_vpl_stride)
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
            if self.sky_volume is not None and sky_job is None:  # a "gather" sky volume: here, in turn
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
        #: direct, ao (None without SSAO; 1/indirect_scale resolution), the main view's gbuffer, and
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

    def _start_ray_tracing(self, view_proj, gbuf):
        """The ray-casting buffer (which pixels reflect or refract, and their rays; read from the
        G-buffer), read back; the tracer starts on them at once. Returns (rcb or None, a callable
        that joins the tracer)."""
        if not self.traces:
            return None, None
        with self._stage("ray casting buffer"):
            self.raycast_pass.render(view_proj, self.scene.camera, gbuf)
            rcb = self.raycast_pass.read().select(self.config.reflections, self.config.refractions)
        if not rcb.count:
            return rcb, None
        tracing = self._ensure_tracer()
        handle = tracing.submit(self._ray_batches(rcb))
        return rcb, lambda: self._join_tracer(handle)

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

    def _light_main_view(self, gbuf, shadow, light: LightingInputs, ao, guide):
        """Phong + CSM/PCSS and the sky volume's and the LPV's light: at full resolution added onto
        the lit image; at 1/indirect_scale drawn first and upsampled by the deferred pass."""
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
                history = (self.indirect_history, self.scene.camera, self.config.indirect_history)
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
        osm = None  # rt_sun_shadows == "traced": the tracer's shadow rays (eye.w) instead
        if self.osm_pass is not None:
            with self._stage("shadow maps (OSM)"):
                stagger = cfg.shadow.stagger
                osm = self.osm_pass.render(fit_overlapped(cam.position, scene.sun.direction, self.scene_gl.bounds, 3,
                                                          cfg.osm_size, pad=STAGGER_PAD if stagger else 0.0),
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

    # ---------------------------------------------------------------------------------- volumes

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
        frame; then by transfer, or ``sky_layers_per_frame`` layers of the paper's sweep), and the
        host side of its upload is prepared: the sky map when rebaked, the open sky's coefficients,
        the texture arrays of the layers that changed. No GL: the volume worker may run it. Returns
        what ``_upload_sky`` writes, or None when no probe changed."""
        sv = self.sky_volume
        first = not self._sky_built
        with self._cpu_stage("sky volume build" if first else "sky volume update"):
            changed = sv.update(layers=sv.resolution[1] if first else self.config.sky_layers_per_frame)
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
        """Every ``sky_vpl_stride``-th pixel of the G-buffer, gathered on the GL side and read back
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

    # ------------------------------------------------------------------------------ ray tracing

    @property
    def tracer_niceness(self) -> int | None:
        """The tracer process's niceness relative to this process's, as the OS granted
        ``RenderConfig.tracer_nice`` (None before the first traced frame, or without the process)."""
        return None if self._tracer_proc is None else self._tracer_proc.niceness

    def _tracer_starts_idle(self) -> bool:
        """Whether sync 1 waits for the main thread's idle point (``RenderConfig.tracer_start``):
        "auto" does once the tracer process is known to run in a scheduling group of its own
        (``TracerProcess.own_group``); a tracer sharing the renderer's group at nice 19 would only
        start later and still wait for a core."""
        where = self.config.tracer_start
        if where == "auto":
            return self._tracer_proc is not None and self._tracer_proc.own_group
        return where == "idle"

    def _volumes_in_worker(self) -> bool:
        """Whether the volumes' kernels run on a worker thread (``_volume_pool``), known from the
        config alone (the tracer process, started before the volumes exist, asks it too)."""
        cfg = self.config
        return (cfg.overlap and cfg.overlap_volumes and str(self.device).startswith("cpu")
                and ((cfg.sky.enabled and cfg.sky.method != "gather") or cfg.lpv.enabled))

    def _tracer_in_process(self) -> bool:
        """Whether the tracer runs in a process of its own (the overlapped schedule on the CPU)."""
        return self.config.overlap and str(self.device).startswith("cpu")

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
                session = cfg.tracer_session
                if session is None:  # a group of its own where the main thread will wait for a volume worker
                    session = self._volumes_in_worker()

                def make():
                    return TracerProcess(scene, device, nice=cfg.tracer_nice, session=session)
            elif cfg.overlap:
                def make():
                    return ThreadTracer(scene, device)
            else:
                def make():
                    return InlineTracer(scene, device)
            self._tracing = RestartingTracer(make)
        return self._tracing

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
                                         (rcb.refraction_rays(), rcb.refract_dirs, self.config.transmissions)):
            out.append((rcb.origins[sel], dirs[sel], rcb.cone_width[sel], rcb.cone_spread[sel], transmissions, sun)
                       if sel.any() else None)
        return out

    def _traced_sun(self):
        """The sun direction the tracer casts shadow rays to (``rt_sun_shadows == "traced"``), or None."""
        if self.config.rt_sun_shadows != "traced":
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
        """A 1/indirect_scale image (SSAO) as a full-size AOV: each texel repeated over its block.
        Texel (i, j) covers the pixels (i·s.., j·s..) counted from GL's bottom-left corner, so in the
        top-down image a partial block row (height not a multiple of s) is the top one."""
        s = self.config.indirect_scale
        if s == 1:
            return img
        full = np.repeat(np.repeat(img, s, axis=0), s, axis=1)
        return np.ascontiguousarray(full[full.shape[0] - self.height:, :self.width])

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


def format_timings(timings: dict[str, float], wall_ms: float | None = None) -> str:
    """A small table: stage, ms; then the sum, and the frame's wall time when it differs."""
    width = max([len(k) for k in timings] + [len("total (sum of stages)")])
    lines = [f"{'stage':<{width}}  {'ms':>9}"]
    lines += [f"{k:<{width}}  {v:9.2f}" for k, v in timings.items()]
    lines.append(f"{'total (sum of stages)':<{width}}  {sum(timings.values()):9.2f}")
    if wall_ms is not None:
        lines.append(f"{'frame (wall clock)':<{width}}  {wall_ms:9.2f}")
    return "\n".join(lines)

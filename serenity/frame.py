"""The frame pipeline of DESIGN.md §1 as code: named stages, no maths, each stage timed.

    renderer = Renderer(scene, 640, 360)
    frame = renderer.render()          # Frame(hdr, ldr, aovs, timings)

Stages present today: upload (first frame only), shadow, gbuffer, deferred, tonemap, readback.
The ray-casting buffer, CPU ray tracing, sky volume and LPV stages slot in as their issues land.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from serenity.config import RenderConfig
from serenity.device import resolve_device
from serenity.errors import SerenityError
from serenity.raster.context import get_context
from serenity.raster.deferred import DeferredPass, LightingInputs
from serenity.raster.gbuffer import GBufferPass
from serenity.raster.interop import read_texture
from serenity.raster.scene_gl import SceneGL
from serenity.raster.shadow import ShadowPass, fit_cascades
from serenity.raster.ssao import SSAOPass
from serenity.raster.tonemap import TonemapPass

MAX_SIZE = 8192


@dataclass
class Frame:
    """One rendered frame.

    hdr: (H, W, 3) float32 linear radiance, W·m⁻²·sr⁻¹ (row 0 = top).
    ldr: (H, W, 3) uint8 sRGB after exposure + Reinhard.
    aovs: named (H, W, C) float32 layers: albedo, normal (world), position (world, m),
        depth (H, W, 1; view-space distance along the camera axis, m; inf = background), direct,
        ao (H, W, 1; SSAO, 1 = open; when enabled).
    timings: stage name → milliseconds, in pipeline order.
    """

    hdr: np.ndarray
    ldr: np.ndarray
    aovs: dict[str, np.ndarray]
    timings: dict[str, float] = field(default_factory=dict)
    exposure: float = 1.0

    @property
    def total_ms(self) -> float:
        return float(sum(self.timings.values()))


class Renderer:
    """Renders a ``Scene`` at a fixed size. Static data (geometry, textures) is uploaded once."""

    def __init__(self, scene, width: int, height: int, device: str | None = None,
                 config: RenderConfig | None = None):
        if not (1 <= int(width) <= MAX_SIZE and 1 <= int(height) <= MAX_SIZE):
            raise SerenityError(f"image size must be within 1..{MAX_SIZE} pixels per side, got {width}x{height}")
        self.scene = scene
        self.width, self.height = int(width), int(height)
        self.config = config or RenderConfig()
        self.device = resolve_device(device)
        self.ctx = get_context()
        self._timings: dict[str, float] = {}
        with self._stage("upload"):
            self.scene_gl = SceneGL(self.ctx, scene)
            self.shadow_pass = ShadowPass(self.ctx, self.scene_gl, self.config.shadow.size, self.config.shadow.cascades)
            self.gbuffer_pass = GBufferPass(self.ctx, self.scene_gl)
            self.deferred_pass = DeferredPass(self.ctx)
            self.tonemap_pass = TonemapPass(self.ctx)
            self.ssao_pass = SSAOPass(self.ctx, self.config.ssao)
            for p in (self.gbuffer_pass, self.deferred_pass, self.tonemap_pass, self.ssao_pass):
                p.resize(self.width, self.height)
        self._upload_ms = self._timings.pop("upload")
        self._first = True

    @contextmanager
    def _stage(self, name: str) -> Iterator[None]:
        t0 = time.perf_counter()
        yield
        if self.config.sync_stages:
            self.ctx.finish()
        self._timings[name] = (time.perf_counter() - t0) * 1e3

    def _lighting_inputs(self, view_proj: np.ndarray) -> LightingInputs:
        sun, sky, cam = self.scene.sun, self.scene.sky, self.scene.camera
        ambient = np.zeros(3)
        if self.config.ambient == "constant":
            ambient = math.pi * sky.radiance
        return LightingInputs(
            sun_direction=sun.direction,
            sun_irradiance=sun.irradiance if sun.is_up else np.zeros(3),
            sun_radiance=sun.radiance,
            sun_cos_radius=math.cos(math.radians(sun.angular_diameter_deg) / 2),
            sky_radiance=sky.radiance,
            ambient_irradiance=ambient,
            camera_position=cam.position,
            inv_view_proj=np.linalg.inv(view_proj),
            camera_forward=cam.forward,
            sun_tan_half=math.tan(math.radians(sun.angular_diameter_deg) / 2),
            shadow=self.config.shadow,
        )

    def render(self) -> Frame:
        self._timings = {}
        if self._first:
            self._timings["upload"] = self._upload_ms
            self._first = False
        cam = self.scene.camera
        view = cam.view_matrix()
        view_proj = cam.projection_matrix(self.width / self.height) @ view
        with self._stage("shadow"):
            sc = self.config.shadow
            cascades = fit_cascades(cam, self.width / self.height, self.scene.sun.direction, self.scene.bounds,
                                    sc.cascades, sc.size, sc.split_lambda, sc.max_distance)
            shadow = self.shadow_pass.render(cascades)
        with self._stage("gbuffer"):
            gbuf = self.gbuffer_pass.render(view_proj, cam.position)
        ao = None
        if self.config.ssao.enabled:
            with self._stage("ssao"):
                ao = self.ssao_pass.render(gbuf, view_proj, cam.position, cam.forward)
        with self._stage("deferred"):
            lit = self.deferred_pass.render(gbuf, shadow, self._lighting_inputs(view_proj), ao)
        with self._stage("tonemap"):
            self.tonemap_pass.render(lit.hdr, self.config.exposure)
        with self._stage("readback"):
            hdr = read_texture(lit.hdr, 3)
            ldr = self.tonemap_pass.read()
            aovs = self._read_aovs(gbuf, lit, cam)
            if ao is not None:
                aovs["ao"] = read_texture(ao, 1)
        return Frame(hdr=hdr, ldr=ldr, aovs=aovs, timings=dict(self._timings), exposure=self.config.exposure)

    def _read_aovs(self, gbuf, lit, cam) -> dict[str, np.ndarray]:
        pos = read_texture(gbuf.position, 4)
        covered = pos[..., 3] > 0
        depth = np.where(covered, (pos[..., :3] - cam.position) @ cam.forward, np.inf).astype(np.float32)
        return {
            "albedo": read_texture(gbuf.albedo, 3),
            "normal": read_texture(gbuf.normal, 3),
            "position": np.where(covered[..., None], pos[..., :3], 0.0).astype(np.float32),
            "depth": depth[..., None],
            "direct": read_texture(lit.direct, 3),
        }


def format_timings(timings: dict[str, float]) -> str:
    """A small table: stage, ms; then the total."""
    width = max([len(k) for k in timings] + [5])
    lines = [f"{'stage':<{width}}  {'ms':>9}"]
    lines += [f"{k:<{width}}  {v:9.2f}" for k, v in timings.items()]
    lines.append(f"{'total':<{width}}  {sum(timings.values()):9.2f}")
    return "\n".join(lines)

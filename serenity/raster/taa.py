"""Temporal anti-aliasing (``RenderConfig.antialiasing = "taa"``; ``glsl/taa.glsl``).

A deferred renderer shades one point per pixel, so an edge steps from pixel to pixel. With TAA each
frame's projection is shifted within the pixel by the next point of a short Halton(2, 3) cycle
(``TAAConfig.cycle``; the first frame after a reset is unjittered, so a single frame is the same as
without anti-aliasing), and a resolve pass before the tone map blends each pixel's new sample with
its history — the last resolved image, reprojected through the pixel's surface point into the last
frame's unjittered view (``glsl/reproject.glsl``, shared with the indirect light's history), clipped
to the range of this frame's 3×3 neighbourhood, a sample brighter than all its neighbours weighted
down by its tone-mapped excess. A
still view converges to the mean of the cycle's sub-pixel samples (what
``Renderer.render_accumulated`` computes), and a moving one keeps most of it: the history follows
the surfaces; where a surface was hidden in the last frame (a disocclusion) or came in from off the
image the pixel starts afresh from this frame's sample.

The history restarts (``reset``) on a resize, on a camera cut (``TAAConfig.cut_angle_deg``,
``cut_distance``) and when the renderer's config changes. Its cost: one fullscreen pass that reads
per pixel a 3×3 neighbourhood of colour and position, a reprojection and up to 9 history taps, and
two RGBA32F targets (this frame's, the last frame's). ``docs/techniques.md`` says why its settings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from serenity.errors import SerenityError
from serenity.raster.context import fullscreen_vao, load_program, uniform
from serenity.raster.temporal import HistoryTargets


def halton(index: int, base: int) -> float:
    """The ``index``-th (from 0) element of the van der Corput / Halton sequence in ``base``, in [0, 1)."""
    f, r, i = 1.0, 0.0, index + 1
    while i > 0:
        f /= base
        r += f * (i % base)
        i //= base
    return r


def jitter_offset(index: int) -> tuple[float, float]:
    """Sub-pixel offset (x right, y up; pixels, in [−0.5, 0.5)) of sample ``index`` of the Halton(2, 3)
    sequence ``Renderer.render_accumulated`` uses: sample 0 is the pixel's centre."""
    return (halton(index, 2) - 0.5, halton(index, 3) - 0.5) if index else (0.0, 0.0)


WEIGHTS = ("none", "karis", "excess")


@dataclass(frozen=True)
class TAAConfig:
    alpha: float = 0.1
    """Weight of each new frame's sample once the history holds ``1 / alpha`` frames (before that,
    ``1 / frames``: the first frames after a reset average evenly). 0.1 keeps about 10 frames: more
    smooths further but lags a changing image (a moving shadow, the indirect light's updates) longer."""
    alpha_still: float = 1.0 / 64.0
    """... where the image stands still (the reprojection moves it under a pixel: ``alpha`` at a pixel
    a frame and more, in between by the distance): a still view averages 8 jitter cycles evenly before
    the blend turns exponential. With 0.1 an edge's pixels step by about a tenth of the edge's contrast
    every frame as the jitter cycles; with 1/64 a still view's 99th-percentile step under a sinking sun
    is 1.6 % in the courtyard (``lpv``; 2.6 % with 1/32)."""
    gamma: float = 0.75
    """Half-width of the box the history is clipped to, in standard deviations of this frame's 3×3
    neighbourhood (variance clipping; smaller rejects more history: less ghosting and blur, more
    flicker). With a moving camera 0.75 scores best of 0.5, 0.75, 1 and 1.25 on the edges of both
    benchmark scenes (``benchmarks/bench_aa.py``), and the camera pan's steps are those of 1.25."""
    weights: str = "excess"
    """How the sample and the history are weighed as they are blended (besides ``alpha``): "excess"
    divides the sample's weight by 1 + exposure × its luminance above its brightest neighbour's (a
    firefly counts for little, an edge's samples all alike), "karis" each one's by 1 + exposure × its
    luminance (Karis 2014: the blend of tone-mapped values, which darkens every edge between a bright
    and a dark surface against a linear box filter), "none" neither."""
    gamma_still: float = 2.0
    """... where the image stands still (in between by the distance it moves, as ``alpha_still``): each
    frame's neighbourhood holds other sub-pixel samples, and a tight box clipped the converged
    history of an edge differently every frame (a still view's edges stepped by 3 % a frame)."""
    clip: bool = True
    """False leaves the history unclipped (to see what the clip does: ghosts where the depth test
    passes)."""
    cycle: int = 8
    """Jitter positions before the sequence repeats (1 = no jitter: the resolve only smooths)."""
    catmull_rom: bool = True
    """Sample the history with a Catmull-Rom filter where all 4 bilinear taps show the pixel's surface
    (bilinear otherwise): bilinear resampling blurs a moving image a little more every frame."""
    cut_angle_deg: float = 30.0
    """A camera turn by more than this between frames is a cut: the history restarts."""
    cut_distance: float = 0.1
    """... and so is a move by more than this fraction of the scene's bounding-box diagonal."""

    def __post_init__(self):
        if self.weights not in WEIGHTS:
            raise SerenityError(f"TAAConfig.weights must be one of {WEIGHTS}, got {self.weights!r}")
        if not (0.0 < self.alpha <= 1.0 and 0.0 < self.alpha_still <= 1.0 and 0.0 < self.gamma <= 8.0
                and 0.0 < self.gamma_still <= 8.0 and isinstance(self.cycle, int) and 1 <= self.cycle <= 256
                and 0.0 < self.cut_angle_deg and 0.0 < self.cut_distance):
            raise SerenityError(f"TAAConfig: need 0 < alpha, alpha_still <= 1, 0 < gamma, gamma_still <= 8, an int "
                                f"cycle in 1..256 and positive cut thresholds, got {self}")


class TAAPass:
    """The resolve pass and its two history targets (this frame's output, the last frame's)."""

    SHADER = "taa.glsl"

    def __init__(self, ctx, config: TAAConfig | None = None):
        self.ctx = ctx
        self.config = config or TAAConfig()
        self.program = load_program(ctx, self.SHADER)
        self.vao = fullscreen_vao(ctx, self.program)
        #: the resolved images (rgb, view depth in a) and the last frame's unjittered camera
        self.history = HistoryTargets(ctx, linear=True)
        self.reset()

    @property
    def size(self):
        return self.history.size

    def resize(self, width: int, height: int) -> None:
        """(Re)allocate the targets for a width×height view; a new size restarts the history."""
        if self.history.size != (width, height):
            self.history.resize(width, height)
            self.reset()

    def reset(self) -> None:
        """Forget the history: the next frame is unjittered and shown as rendered."""
        self.history.prev = None
        self.frames = 0    # frames in the history (resolved since the reset)
        self._key = None

    @property
    def has_history(self) -> bool:
        return self.history.prev is not None

    def begin(self, camera, scene_extent: float, key=None) -> tuple[float, float]:
        """At a frame's start: restart the history on a camera cut or when ``key`` (the renderer's
        config) differs from the last frame's; returns this frame's jitter (x right, y up; pixels)."""
        cfg = self.config
        if self._key is not None and key != self._key:
            self.reset()
        self._key = key
        if self.history.prev is not None:
            _, pos, fwd, fov = self.history.prev
            turn = math.degrees(math.acos(float(np.clip(np.dot(fwd, camera.forward), -1.0, 1.0))))
            move = float(np.linalg.norm(np.asarray(camera.position, np.float64) - pos))
            if (turn > cfg.cut_angle_deg or move > cfg.cut_distance * max(scene_extent, 1e-9)
                    or abs(camera.fov_y_deg - fov) > 1e-6 * max(fov, 1.0)):
                self.reset()
                self._key = key
        return jitter_offset(self.frames % cfg.cycle)

    def render(self, hdr_texture, gbuffer, camera, view_proj: np.ndarray, jitter: tuple[float, float],
               exposure: float):
        """The resolved image (a texture of this pass's, RGBA32F: rgb, view depth in a) of this
        frame's ``hdr_texture``, drawn with the projection shifted by ``jitter``; ``view_proj`` is the
        frame's unjittered world → clip. It becomes the next frame's history."""
        cfg, p, hist = self.config, self.program, self.history
        out = hist.target
        ramp = 1.0 if hist.prev is None else 1.0 / (self.frames + 1)
        alpha, alpha_still = max(cfg.alpha, ramp), max(cfg.alpha_still, ramp)
        with self.ctx.debug_scope("taa"):
            hist.fbo.use()
            hdr_texture.use(location=0)
            gbuffer.position.use(location=1)
            gbuffer.normal.use(location=2)
            hist.last.use(location=3)
            values = {"u_hdr": 0, "u_position": 1, "u_normal": 2, "u_history": 3,
                      "u_jitter": (float(jitter[0]), float(jitter[1])), "u_alpha": float(alpha),
                      "u_alpha_still": float(alpha_still),
                      "u_gamma": float(cfg.gamma) if cfg.clip else 0.0,
                      "u_gamma_still": float(cfg.gamma_still), "u_exposure": float(exposure),
                      "u_weights": WEIGHTS.index(cfg.weights), "u_catmull_rom": bool(cfg.catmull_rom),
                      "u_camera_pos": tuple(float(v) for v in camera.position),
                      "u_camera_forward": tuple(float(v) for v in camera.forward)}
            for name, value in values.items():
                if (u := uniform(p, name)) is not None:
                    u.value = value
            if (u := uniform(p, "u_inv_view_proj")) is not None:
                u.write(np.linalg.inv(view_proj).T.astype(np.float32).tobytes())
            hist.set_reproject_uniforms(p, camera)
            self.vao.render(vertices=3)
        hist.end(view_proj, camera)
        self.frames += 1
        return out

"""What a frame returns and the names of its stages: ``STAGES`` in pipeline order, the timeline's
lanes, :class:`Frame`, :class:`ChangeTracker` (what changed since a part of the frame was last
redone) and ``format_timings``."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

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
``indirect.scale`` > 1 "sky lighting" and "lpv lighting" run at low resolution before "direct
lighting", which then includes their upsampling: one full-resolution pass). "rsm" includes the
read-back of the RSM and of the G-buffer's samples; with the volume worker
(``ScheduleConfig.overlap_volumes``) "sky volume update", "lpv inputs", "lpv inject" and "lpv
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

def format_timings(timings: dict[str, float], wall_ms: float | None = None) -> str:
    """A small table: stage, ms; then the sum, and the frame's wall time when it differs."""
    width = max([len(k) for k in timings] + [len("total (sum of stages)")])
    lines = [f"{'stage':<{width}}  {'ms':>9}"]
    lines += [f"{k:<{width}}  {v:9.2f}" for k, v in timings.items()]
    lines.append(f"{'total (sum of stages)':<{width}}  {sum(timings.values()):9.2f}")
    if wall_ms is not None:
        lines.append(f"{'frame (wall clock)':<{width}}  {wall_ms:9.2f}")
    return "\n".join(lines)

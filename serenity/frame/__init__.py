"""The frame pipeline of docs/architecture.md ("The frame") and paper §10 as code: named stages, no maths, each timed.

    renderer = Renderer(scene, 640, 360)
    frame = renderer.render()          # Frame(hdr, ldr, aovs, timings, events)

The schedule (paper §10): the ray-casting buffer is drawn first and read back (sync 1); the CPU
ray tracing of the reflective/refractive pixels starts in the tracer process (on CUDA: a worker
thread); meanwhile the main thread issues the GL work (shadow cascades, G-buffer, RSM, SSAO, the
lighting passes) and the volume kernels (LPV, the sky volume); then it joins the tracer (sync 2),
uploads the ray-traced G-buffers, lights them with the overlapped shadow maps and composites them
with a Fresnel blend; last the tone map. (With a volume worker the tracer process runs in a session of its own by
default, ``ScheduleConfig.tracer_session``, and where that gives it a scheduling group of its own sync
1 moves to just before the main thread waits for the volume worker, ``tracer_start = "auto"``;
with ``tracer_nice`` they set how the tracer process shares the cores.) ``ScheduleConfig.overlap=False``
(``--serial``) runs the ray tracing inline before the GL work, for comparison. ``STAGES`` names every stage in order;
each stage of ``Renderer.render`` is one short method (``renderer.py``; the volumes' in ``volumes.py``,
the ray tracing's in ``tracing.py``; ``record.py`` names the stages and holds the ``Frame``).

Stage names follow the paper's Table 1 where it has one. ``Frame.timings`` holds each stage's
milliseconds (the worker's ``cpu ray tracing`` included); ``Frame.wall_ms`` is the frame's real
duration, less than the sum when the tracer overlaps the GL work; ``Frame.events`` is the
timeline (lane, stage, start, end in ms from the frame start) that ``serenity bench`` charts.

Stage timing: GL is asynchronous, so with ``ScheduleConfig.sync_stages`` = "each" (default) each GL
stage ends with ``ctx.finish()`` and is timed by the wall clock; "cpu" waits only before the stages
that run on the CPU, so a GL stage's time is then what it took to queue and the queued work shows up
in the next wait (or the frame's final one). GL timer queries would not perturb the
pipeline, but Mesa's llvmpipe returns garbage for them (elapsed = 0xFFFFFFFF), and the CPU
"GPU" of this project's CI runs the GL work synchronously anyway.
"""

from serenity.frame.record import (
    LPV_UPDATE_STAGES,
    MAIN_LANE,
    READ_BACK,
    RT_LANE,
    SKY_UPDATE_STAGES,
    STAGES,
    VOLUME_LANE,
    VOLUME_THREAD,
    ChangeTracker,
    Frame,
    format_timings,
)
from serenity.frame.renderer import Renderer, lighting_inputs
from serenity.raster.taa import halton

__all__ = ["LPV_UPDATE_STAGES", "MAIN_LANE", "READ_BACK", "RT_LANE", "SKY_UPDATE_STAGES", "STAGES", "VOLUME_LANE",
           "VOLUME_THREAD", "ChangeTracker", "Frame", "Renderer", "format_timings", "halton", "lighting_inputs"]

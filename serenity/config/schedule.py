"""How a frame's work is scheduled on this machine: ``ScheduleConfig`` (none of it changes the image)."""

from __future__ import annotations

from dataclasses import dataclass

from serenity.errors import ConfigError


@dataclass(frozen=True)
class ScheduleConfig:
    """How a frame's work is scheduled on this machine: which parts run beside which (paper §10),
    at what priority, and when the frame waits for the GL queue. None of it changes the image
    (tests compare the schedules' images); ``benchmarks/bench_tracer_nice.py``,
    ``bench_frame_threads.py`` and ``bench_pass_ab.py`` measure what each costs."""

    overlap: bool = True
    """Run the CPU ray tracing in a worker thread while the GL work proceeds (paper §10); False
    traces inline first (the serial schedule, for comparison)."""
    overlap_volumes: bool = True
    """With ``overlap``, on the CPU: the volumes' kernels (the sky volume's update from the frame's
    start; the LPV's VPLs, injection and propagation once its RSM is read back) run in a worker
    thread while the main thread issues the GL passes that do not need them (G-buffer, ray-casting
    buffer, shadow cascades, SSAO), as on a GPU they would queue beside them. False: on the main
    thread between those passes (the serial schedule always does)."""
    volume_nice: int = 4
    """With the volume worker: the niceness (0..19) its thread adds to this process's, set from the
    thread itself when the worker starts (a thread may lower its own priority without privileges).
    0 = the frame's priority, so that the volumes' kernels take a share of the cores from llvmpipe's
    threads while these render; higher, the GL passes beside them keep more of the cores and the
    volumes run more in what they leave idle, at the risk of the frame waiting for them where it
    joins them ("wait for volumes"). 4: the G-buffer, CSM and SSAO get faster by more than the wait
    grows (frame −1.4 to −3.3 % against 0 at 320×180 and 640×360; 10: about −1 %, the frame waiting
    2.4 ms for the volumes; ``benchmarks/bench_pass_ab.py --a-config schedule.volume_nice=0``)."""
    tracer_nice: int = 19
    """The niceness (-20..19), relative to this process's, of the tracer process that the overlapped
    schedule on the CPU traces in (``kernels/tracer_process``): 19 = the lowest priority, so that it
    takes a core only where the frame's own threads leave one idle; 0 = the frame's; below 0 it
    preempts the frame's threads (allowed only with CAP_SYS_NICE, e.g. as root; elsewhere it runs at
    0). ``benchmarks/bench_tracer_nice.py`` measures the trade: the lower, the shorter the tracer's
    stage and the slower the frame. In a scheduling group of its own (``tracer_session``, where it
    takes effect) the niceness orders nothing; 19 is the default for the machines where it does not."""
    tracer_session: bool | None = None
    """Start the tracer process in a session of its own (``setsid``). Where Linux groups processes by
    session for scheduling (autogroup: ``/proc/sys/kernel/sched_autogroup_enabled`` = 1, and neither
    process in a CPU cgroup of its own), the tracer then shares the cores with the renderer as one
    group against another, instead of as one more thread beside llvmpipe's, the Warp launches' and
    the main thread; ``tracer_nice`` then orders nothing (the tracer is alone in its group).
    Elsewhere nothing changes (``TracerProcess.own_group`` says which). No privilege needed.
    None (default) = a session of its own where the frame has a volume worker (the overlapped CPU
    schedule of the LPV presets), whose wait leaves a core idle: with ``tracer_start = "auto"`` it
    is the one setting that meets both of the overlap's bars (tracer stage ≤ 1.5x the inline trace,
    frame ≤ the serial one) at 320×180 and 640×360 in every sweep of
    ``benchmarks/bench_tracer_nice.py``, and it keeps the frame at or under the serial one beside a
    busy process, where nice 19 alone starves the tracer; its price on an idle machine is a frame
    1-4 % slower than nice 19 in the renderer's group. Without a volume worker ("traced-probes": its
    gathered sky volume keeps every core busy from the main thread) the tracer stays in the
    renderer's session, where a group of its own only takes cores from that work (frame 1.040x
    the serial one against 1.001x at 320×180, 1.019x against 1.009x at 640×360)."""
    tracer_start: str = "auto"
    """With the volume worker on the CPU: where the frame reads the ray-casting buffer back and hands
    its rays to the tracer process (sync 1). "g-buffer": right after the G-buffer, as in the paper;
    "idle": just before the main thread waits for the volume worker, when the worker has work this
    frame (otherwise right after the G-buffer), so that the tracer starts where a core may fall idle;
    "auto" (default): "idle" where the tracer process runs in a scheduling group of its own
    (``tracer_session`` took effect), else "g-buffer" — at nice 19 in the renderer's group a later
    start only delays a tracer that still waits for a core (tracer stage 5.0x the inline trace at
    640×360 against 3.3x from the G-buffer). The same images in every case (tests)."""
    sync_stages: str = "each"
    """When the frame waits for the GL queue (``ctx.finish()``): "each" = after every GL stage, so each
    stage's wall time is its own (the profile ``serenity bench`` reports); "cpu" = only before the
    stages that run on the CPU (the volumes' kernels, the wait for the tracer), so GL work never runs
    beside them but a run of GL passes is not cut into waits (a GL stage's time is then only what
    it took to queue); "none" = never before the read-back. (True / False read as "each" / "none".)
    "each" by default, as every figure of a stage assumes; "cpu" is what an application that reads
    no per-stage times would use (the frontier does): still frames 3-12 % faster in four of five
    interleaved A/Bs (1 % slower in the fifth), the same images."""

    def __post_init__(self):
        if not (isinstance(self.volume_nice, int) and 0 <= self.volume_nice <= 19):
            raise ConfigError(f"ScheduleConfig.volume_nice must be an int in 0..19, got {self.volume_nice!r}")
        if not (isinstance(self.tracer_nice, int) and -20 <= self.tracer_nice <= 19):
            raise ConfigError(f"ScheduleConfig.tracer_nice must be an int in -20..19, got {self.tracer_nice!r}")
        if self.tracer_session not in (None, True, False):
            raise ConfigError(f"ScheduleConfig.tracer_session must be None, True or False, got {self.tracer_session!r}")
        if self.tracer_start not in ("auto", "g-buffer", "idle"):
            raise ConfigError(f"ScheduleConfig.tracer_start must be auto, g-buffer or idle, got {self.tracer_start!r}")
        if isinstance(self.sync_stages, bool):
            object.__setattr__(self, "sync_stages", "each" if self.sync_stages else "none")
        if self.sync_stages not in ("each", "cpu", "none"):
            raise ConfigError(f"ScheduleConfig.sync_stages must be each, cpu or none, got {self.sync_stages!r}")

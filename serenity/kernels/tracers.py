"""The renderer's ray tracer behind one protocol, whichever way it runs.

    handle = tracer.submit(batches)               # one frame's ray batches, at sync 1
    results, t0, t1 = tracer.result(handle, timeout)   # at sync 2
    tracer.close()

``batches`` is a list of ``(origins, directions, cone_width, cone_spread, transmissions,
sun_direction)`` or None (``Renderer._ray_batches``: the reflected and the refracted rays);
``results`` the :meth:`RayTracer.trace` dict of each (None for None), ``t0``/``t1`` the
``time.perf_counter()`` around the work. After ``result`` each tracer says what the frame cost:
``cpu_seconds`` (CPU time of the work, every thread of whichever process did it), and
``build_seconds`` (the tracer's set-up: its kd-tree; None until it is known).

- :class:`InlineTracer`: traces in ``submit`` on the calling thread (the serial schedule).
- :class:`ThreadTracer`: a worker thread (CUDA, whose launches run asynchronously while the GL
  passes go on).
- :class:`~serenity.kernels.tracer_process.TracerProcess`: a child process (the overlapped schedule
  on the CPU, where a thread would wait for the GIL the GL calls hold).
- :class:`SharedRayTracer`: the one :class:`RayTracer` of a scene in this process, built by whichever
  of its users asks first — the in-process tracers above and the sky volume's traced probes
  (``SkyVolume(tracer=...)``): a renderer holds one kd-tree and one copy of the textures in its
  process (the tracer process keeps its own).
- :class:`RestartingTracer` wraps any of them: a tracer that stops or hangs
  (:class:`~serenity.kernels.tracer_process.TracerStopped`) is closed, made anew once and given the
  frame's rays again; a second failure in the same frame is a one-line :class:`SerenityError`.
"""

from __future__ import annotations

import concurrent.futures
import threading
import time
from concurrent.futures import ThreadPoolExecutor

from serenity.errors import SerenityError
from serenity.kernels.raytrace import RayTracer
from serenity.kernels.tracer_process import RESULT_TIMEOUT, TracerProcess, TracerStopped

__all__ = ["InlineTracer", "RestartingTracer", "SharedRayTracer", "ThreadTracer", "TracerProcess", "TracerStopped",
           "trace_batches"]


def trace_batches(tracer: RayTracer, batches: list) -> list:
    """``tracer.trace`` of each batch (None for None)."""
    return [None if b is None else tracer.trace(*b[:4], transmissions=b[4], sun_direction=b[5]) for b in batches]


class SharedRayTracer:
    """The :class:`RayTracer` of ``scene`` that every user in this process shares: ``shared()`` builds
    it on the first call (one build, however many threads ask) and returns it; ``ray_tracer`` is it,
    or None before."""

    def __init__(self, scene, device: str = "cpu"):
        self.scene, self.device = scene, device
        self.ray_tracer: RayTracer | None = None
        self._lock = threading.Lock()

    def __call__(self) -> RayTracer:
        if self.ray_tracer is None:
            with self._lock:
                if self.ray_tracer is None:
                    self.ray_tracer = RayTracer(self.scene, device=self.device)
        return self.ray_tracer


class _InProcess:
    """The tracers in this process: the :class:`RayTracer` of ``shared`` (a :class:`SharedRayTracer`;
    None: one of their own), built on the first ``submit`` unless another of its users built it
    before (a frame that shows no traced pixel never builds it), exposed as ``ray_tracer``;
    ``build_seconds`` is the time the first ``submit`` spent on it (0 where it was built already)."""

    def __init__(self, scene, device: str, shared: SharedRayTracer | None = None):
        self.scene, self.device = scene, device
        self.shared = shared if shared is not None else SharedRayTracer(scene, device)
        self.build_seconds: float | None = None
        self.cpu_seconds = 0.0
        self._handles = 0

    @property
    def ray_tracer(self) -> RayTracer | None:
        return self.shared.ray_tracer

    def _ensure(self) -> RayTracer:
        if self.build_seconds is None:
            t0 = time.perf_counter()
            self.shared()
            self.build_seconds = time.perf_counter() - t0
        return self.shared()

    def _timed(self, batches: list):
        tracer = self._ensure()
        t0, c0 = time.perf_counter(), time.process_time()
        results = trace_batches(tracer, batches)
        return results, t0, time.perf_counter(), time.process_time() - c0

    def close(self) -> None:
        pass


class InlineTracer(_InProcess):
    """Traces in ``submit``, on the calling thread; ``result`` hands the hits over."""

    def __init__(self, scene, device: str = "cpu", shared: SharedRayTracer | None = None):
        super().__init__(scene, device, shared)
        self._done: dict[int, tuple] = {}

    def submit(self, batches: list) -> int:
        self._done.clear()  # a frame that failed before it collected its hits
        *out, cpu = self._timed(batches)
        self._handles += 1
        self._done[self._handles] = (tuple(out), cpu)
        return self._handles

    def result(self, handle: int, timeout: float | None = None):
        if handle not in self._done:
            raise SerenityError(f"no ray batches in flight under handle {handle}")
        out, self.cpu_seconds = self._done.pop(handle)
        return out


class ThreadTracer(_InProcess):
    """Traces on a worker thread of its own; ``result`` waits for it, up to ``timeout`` seconds."""

    def __init__(self, scene, device: str = "cpu", shared: SharedRayTracer | None = None):
        super().__init__(scene, device, shared)
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="serenity-rt")
        self._futures: dict[int, concurrent.futures.Future] = {}

    def submit(self, batches: list) -> int:
        self._futures.clear()  # a frame that failed before it collected its hits: the pool runs in order
        self._ensure()  # built on the calling thread, where the device's context is current
        self._handles += 1
        self._futures[self._handles] = self._pool.submit(self._timed, batches)
        return self._handles

    def result(self, handle: int, timeout: float | None = RESULT_TIMEOUT):
        future = self._futures.pop(handle, None)
        if future is None:
            raise SerenityError(f"no ray batches in flight under handle {handle}")
        try:
            *out, self.cpu_seconds = future.result(timeout)
        except concurrent.futures.TimeoutError:
            raise TracerStopped(f"ray tracing gave no answer within {timeout:.0f} s") from None
        return tuple(out)

    def close(self) -> None:
        self._pool.shutdown(wait=True)


class RestartingTracer:
    """A tracer made by ``make()`` that is made anew once when it stops or hangs (module doc).
    Attributes other than the protocol's are the current tracer's (``build_seconds``, a process's
    ``niceness``); ``restarts`` counts the restarts so far."""

    def __init__(self, make, timeout: float | None = RESULT_TIMEOUT):
        self._make = make
        self.timeout = timeout
        self.tracer = make()
        self.restarts = 0
        self._handles = 0
        self._pending: dict[int, tuple[list, int]] = {}  # handle -> (the frame's batches, the tracer's handle)

    def __getattr__(self, name):
        if name == "tracer":  # not yet set: __init__ failed
            raise AttributeError(name)
        return getattr(self.tracer, name)

    def _restart(self, error: TracerStopped) -> None:
        try:
            self.tracer.close()
        except Exception:  # noqa: BLE001 - the tracer is being replaced because it failed
            pass
        try:
            self.tracer = self._make()
        except SerenityError as e:
            raise SerenityError(f"{error}; restarting the ray tracer failed: {e}") from None
        self.restarts += 1

    def submit(self, batches: list) -> int:
        self._pending.clear()  # a frame that failed before it collected its hits
        try:
            inner = self.tracer.submit(batches)
        except TracerStopped as e:
            self._restart(e)
            inner = self.tracer.submit(batches)
        self._handles += 1
        self._pending[self._handles] = (batches, inner)
        return self._handles

    def result(self, handle: int, timeout: float | None = None):
        if handle not in self._pending:
            raise SerenityError(f"no ray batches in flight under handle {handle}")
        timeout = self.timeout if timeout is None else timeout
        batches, inner = self._pending.pop(handle)
        try:
            return self.tracer.result(inner, timeout)
        except TracerStopped as e:
            self._restart(e)
        try:
            return self.tracer.result(self.tracer.submit(batches), timeout)
        except TracerStopped as e:
            raise SerenityError(f"ray tracing failed again after a restart of the tracer: {e}") from None

    def close(self) -> None:
        self.tracer.close()

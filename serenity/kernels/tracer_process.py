"""The CPU ray tracer in a process of its own, so that it really runs beside the GL work (paper §10).

In a thread, the tracer stalls while the GL thread renders: moderngl holds the GIL during calls that
wait for Mesa's llvmpipe (``finish()``, texture reads), and the tracer's Python between its Warp
launches then waits for it (measured: 5 ms of tracing took 130–220 ms beside the GL work). A child
process has its own interpreter and GIL: the frame hands it the rays at sync 1 and collects the
hits at sync 2, and nothing in between needs the parent's GIL. The child's CPU time for each frame
comes back too (``cpu_seconds``), so a frame's CPU cost counts both processes. The child runs at
the lowest priority (``NICE``), in the cores' idle gaps, and its pipes are widened (``PIPE_BYTES``)
so that neither side blocks halfway through a frame's message. With ``session=True`` the child starts a
session of its own (``setsid``): where Linux schedules by autogroup (one group per session), it
then competes with the renderer's process as a whole rather than with each of its threads, and its
niceness, alone in its group, orders nothing (``ScheduleConfig.tracer_session``).

Protocol (private): the child is ``python -m serenity.kernels.tracer_process IN OUT NICE`` with two pipe
file descriptors and its niceness; messages are length-prefixed pickles. First message in: (path, device), path a
file holding the scene's pickle (``SCENE_DIR``: written at once, where the pipe made the parent wait
until the child had imported its modules and read 80 MB of a textured scene); the child loads it,
deletes it, builds its :class:`~serenity.kernels.raytrace.RayTracer` (the kd-tree comes from the disk
cache when a process built it before, or waits for the one building it: ``RayTracer``), only then
takes its niceness (its start-up is the renderer's first frame's wait), and answers ("ready", build
seconds). Then per frame: a list of ray
batches ``(origins, directions, cone_width, cone_spread, transmissions, sun_direction)`` in, ("ok",
results, t0, t1, cpu) out, where cpu is the child's CPU seconds (``time.process_time``) for the
work, results are the tracer's dicts (None for an empty batch) and t0/t1 the child's
``time.perf_counter()`` around the work — the same monotonic clock as the parent's on Linux, so the
frame's timeline places the child's work exactly. Errors come back as ("error", message). An empty
message (None) stops the child.
"""

from __future__ import annotations

import os
import pickle
import select

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: the pipes keep their size
    fcntl = None
import struct
import subprocess
import sys
import tempfile
import time

from serenity.errors import SerenityError
from serenity.kernels.raytrace import RayTracer
from serenity.threads import single_threaded_blas

_HEADER = struct.Struct("<Q")

#: seconds ``TracerProcess.result`` waits for the child's tracer to be built (a large scene's kd-tree
#: with an empty cache) and then for one frame's hits, before it calls the child hung
READY_TIMEOUT = 600.0
RESULT_TIMEOUT = 60.0


class TracerStopped(SerenityError):
    """The tracer process died, closed its pipe or gave no answer in time (a restart may help; an
    error the tracer itself reported is a plain :class:`SerenityError`)."""

#: where the scene's pickle waits for the child: memory (tmpfs) where there is one
SCENE_DIR = "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else None


#: the child's niceness: the lowest priority, so that the tracer takes a core only where the frame's
#: own threads (llvmpipe's, the volumes' Warp launches) leave it idle, instead of sharing cores
#: they would keep busy. Measured on the 2-core machine (``serenity bench courtyard --size
#: 640x360``, the schedules interleaved, wide pipes, 3 runs each): overlapped / serial 0.96-0.99 at
#: nice 19 (0.95-1.00 with the tracer on one thread), 1.01-1.02 at nice 0 (one thread). The wait
#: at sync 2 stays short: there the main thread waits and a core is free. ``ScheduleConfig.tracer_nice``
#: overrides it; ``benchmarks/bench_tracer_nice.py`` sweeps it (results/tracer_nice.json).
NICE = 19

#: bytes a pipe holds (Linux' F_SETPIPE_SZ; its default is 64 KiB): a frame's rays (~0.24 MB for
#: 3.5k rays) and hits go through without the writer blocking on the reader chunk by chunk
PIPE_BYTES = 1 << 20


def _widen(fd: int) -> None:
    """Let ``fd``'s pipe hold PIPE_BYTES (or 256 KiB), where the OS allows (Linux)."""
    if fcntl is None:  # pragma: no cover - not POSIX
        return
    for size in (PIPE_BYTES, 1 << 18):
        try:
            fcntl.fcntl(fd, getattr(fcntl, "F_SETPIPE_SZ", 1031), size)
            return
        except OSError:
            continue


def _write(fd: int, obj) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    view = memoryview(_HEADER.pack(len(data)) + data)
    while view:
        view = view[os.write(fd, view):]


def _read_exact(fd: int, n: int) -> bytes:
    chunks, left = [], n
    while left:
        chunk = os.read(fd, min(left, 1 << 20))
        if not chunk:
            raise EOFError("the tracer process closed its pipe")
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def _read(fd: int):
    (n,) = _HEADER.unpack(_read_exact(fd, _HEADER.size))
    return pickle.loads(_read_exact(fd, n))


def _dump_scene(scene) -> str:
    """The path of a new file holding ``scene``'s pickle: in ``SCENE_DIR``, or where that is full (a
    container's /dev/shm is often 64 MB) in the temporary folder."""
    for folder in dict.fromkeys((SCENE_DIR, None)):
        fd, path = tempfile.mkstemp(prefix="serenity-scene-", suffix=".pickle", dir=folder)
        try:
            with os.fdopen(fd, "wb") as f:
                pickle.dump(scene, f, protocol=pickle.HIGHEST_PROTOCOL)
            return path
        except BaseException as e:
            os.unlink(path)
            if not isinstance(e, OSError) or folder is None:
                raise
    raise AssertionError("unreachable")


def _autogroup(pid) -> str | None:
    """``/proc/PID/autogroup`` (PID a process id or "self"), None where it is absent or empty."""
    try:
        with open(f"/proc/{pid}/autogroup") as f:
            return f.read().strip() or None
    except OSError:
        return None


class TracerProcess:
    """A :class:`~serenity.kernels.raytrace.RayTracer` of ``scene`` in a child process, behind the
    tracers' protocol (``serenity.kernels.tracers``): ``submit(batches)`` sends one frame's ray
    batches and returns a handle at once; ``result(handle, timeout)`` waits for them and returns
    (results, t0, t1). One frame in flight at a time: a submit after a frame that never collected its
    result (the frame failed in between) first reads and drops that result. A child that has died,
    closed its pipe or gives no answer within the timeout is a :class:`TracerStopped` (and is
    killed); an exception in the child's tracing is a :class:`SerenityError` with its message."""

    def __init__(self, scene, device: str = "cpu", nice: int = NICE, session: bool = False):
        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "serenity.kernels.tracer_process", str(to_child_r), str(from_child_w),
             str(int(nice))],
            pass_fds=(to_child_r, from_child_w), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            start_new_session=bool(session) and os.name == "posix")
        os.close(to_child_r)
        os.close(from_child_w)
        _widen(to_child_w)
        _widen(from_child_r)
        self._out, self._in = to_child_w, from_child_r
        self._pending: int | None = None  # the handle of the frame in flight
        self._handles = 0
        self._own_group: bool | None = None
        self.build_seconds: float | None = None
        """Seconds the child took to build its tracer (None until it has said it is ready)."""
        self.cpu_seconds = 0.0
        """CPU seconds the child spent on the last frame's rays (all its threads)."""
        self._scene_path = None
        try:
            self._scene_path = _dump_scene(scene)
            _write(self._out, (self._scene_path, device))
        except BaseException:
            self._proc.kill()
            self.close()
            raise


    def _remove_scene(self) -> None:
        if self._scene_path is not None:
            try:
                os.unlink(self._scene_path)
            except OSError:
                pass  # the child deleted it
            self._scene_path = None

    @property
    def niceness(self) -> int | None:
        """The child's niceness now, relative to this process's (``ScheduleConfig.tracer_nice`` when the
        OS allowed it: a negative one needs CAP_SYS_NICE, e.g. root); None where unknown."""
        try:
            return os.getpriority(os.PRIO_PROCESS, self._proc.pid) - os.getpriority(os.PRIO_PROCESS, 0)
        except (AttributeError, OSError):  # pragma: no cover - not POSIX, or the child is gone
            return None

    @property
    def scheduling_group(self) -> str | None:
        """The child's scheduling group as Linux' autogroup names it (``/proc/PID/autogroup``, e.g.
        "/autogroup-12 nice 0"; one per session where ``/proc/sys/kernel/sched_autogroup_enabled``
        is 1), or None where there is none to read. The file is empty where the process sits in a
        cgroup with a CPU controller of its own (containers, CI runners): the kernel schedules it by
        that cgroup, not by autogroup, and a session of its own changes nothing there."""
        return _autogroup(self._proc.pid)

    @property
    def own_group(self) -> bool:
        """Whether the kernel schedules the child in a group of its own, apart from this process's
        (``session=True`` where Linux has autogroups and neither process sits in a CPU cgroup of its
        own): then it gets its share of the cores against the renderer as a whole, whatever its
        niceness. Read once: a process's group changes only with its session."""
        if self._own_group is None:
            child, mine = self.scheduling_group, _autogroup("self")
            self._own_group = None not in (child, mine) and child.split()[0] != mine.split()[0]
        return self._own_group

    @property
    def alive(self) -> bool:
        """Whether the child is still running."""
        return self._proc.poll() is None

    def _wait_ready(self, timeout: float | None) -> None:
        if self.build_seconds is None:
            try:
                self.build_seconds = self._receive(max(timeout or 0.0, READY_TIMEOUT))[1]
            finally:
                self._remove_scene()

    def _receive(self, timeout: float | None):
        try:
            ready, _, _ = select.select([self._in], [], [], timeout)
            if not ready:
                self._proc.kill()
                raise TracerStopped(f"the ray-tracing process gave no answer within {timeout:.0f} s and was stopped")
            msg = _read(self._in)
        except (EOFError, OSError, ValueError) as e:
            raise TracerStopped(f"the ray-tracing process stopped ({e}); exit code {self._proc.poll()}") from None
        if msg[0] == "error":
            raise SerenityError(f"ray tracing failed in the tracer process: {msg[1]}")
        return msg

    def submit(self, batches: list) -> int:
        """Send one frame's ray batches; returns the handle ``result`` takes."""
        if self._pending is not None:  # a frame that failed before it collected its hits: drop them
            self._wait_ready(None)
            self._pending = None
            self._receive(RESULT_TIMEOUT)
        try:
            _write(self._out, batches)
        except OSError as e:
            raise TracerStopped(f"the ray-tracing process stopped ({e}); exit code {self._proc.poll()}") from None
        self._handles += 1
        self._pending = self._handles
        return self._handles

    def result(self, handle: int, timeout: float | None = RESULT_TIMEOUT):
        """(list of per-batch results, t0, t1) of the submit that returned ``handle``; waits up to
        ``timeout`` seconds for them (None: for ever) once the child's tracer is built."""
        if handle != self._pending:
            raise SerenityError(f"no ray batches in flight under handle {handle}")
        self._wait_ready(timeout)
        self._pending = None
        _, results, t0, t1, self.cpu_seconds = self._receive(timeout)
        return results, t0, t1

    def close(self) -> None:
        if self._proc.poll() is None:
            try:
                _write(self._out, None)
                self._proc.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                self._proc.kill()
        for fd in (self._out, self._in):
            try:
                os.close(fd)
            except OSError:
                pass
        self._remove_scene()


def _serve(fd_in: int, fd_out: int, nice: int = NICE) -> None:
    try:
        with single_threaded_blas():
            _serve_frames(fd_in, fd_out, nice)
    except EOFError:  # the parent went away without saying goodbye
        return


def _load_scene(path: str):
    try:
        with open(path, "rb") as f:
            return pickle.load(f)
    finally:
        try:
            os.unlink(path)
        except OSError:
            pass


def _serve_frames(fd_in: int, fd_out: int, nice: int = NICE) -> None:
    path, device = _read(fd_in)
    t0 = time.perf_counter()
    try:
        tracer = RayTracer(_load_scene(path), device=device)
        tracer.data  # noqa: B018 - uploaded now, beside the renderer's set-up, not in its first frame
    except Exception as e:  # reported to the parent, which raises it as a SerenityError
        _write(fd_out, ("error", f"{type(e).__name__}: {e}"))
        return
    try:
        if nice:
            os.nice(nice)
    except OSError:  # not allowed (a negative niceness without CAP_SYS_NICE): the parent's priority
        pass
    _write(fd_out, ("ready", time.perf_counter() - t0))
    while True:
        batches = _read(fd_in)
        if batches is None:
            return
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            results = [None if b is None else tracer.trace(*b[:4], transmissions=b[4], sun_direction=b[5])
                       for b in batches]
        except Exception as e:
            _write(fd_out, ("error", f"{type(e).__name__}: {e}"))
            continue
        _write(fd_out, ("ok", results, t0, time.perf_counter(), time.process_time() - c0))


if __name__ == "__main__":
    _serve(int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]) if len(sys.argv) > 3 else NICE)

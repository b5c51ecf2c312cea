"""A path-traced reference of the viewer's current view, rendered in another process so that the
interactive frame never waits for it (``serenity.eval.reference.render_reference``, Mitsuba 3).

    job = ReferenceJob(scene, 320, 180, spp=64)   # a copy of the scene as it is now
    job.poll()        # -> progress in [0, 1]; job.result is the (H, W, 3) radiance when done
    job.cancel()

The spp are rendered in ``chunks`` passes with different seeds and averaged, so the panel can show
real progress (each pass is one ``render_reference`` call: same exporter, camera and sun, cached
like ``serenity reference``). Errors in the worker come back as ``job.error`` (one line).
"""

from __future__ import annotations

import copy
import multiprocessing as mp
import queue
import time

import numpy as np

from serenity.eval.reference import render_reference


def chunk_plan(spp: int, chunks: int) -> list[tuple[int, int]]:
    """(spp, seed) of each pass: ``spp`` split over ``min(chunks, spp)`` passes, seeds 0, 1, ..."""
    chunks = max(1, min(int(chunks), int(spp)))
    return [(spp // chunks + (1 if i < spp % chunks else 0), i) for i in range(chunks)]


def _worker(scene, width: int, height: int, spp: int, chunks: int, out) -> None:
    try:
        acc = np.zeros((height, width, 3), np.float64)
        done = 0
        for n, seed in chunk_plan(spp, chunks):
            acc += render_reference(scene, width, height, spp=n, seed=seed, progress=False) * n
            done += n
            out.put(("progress", done / spp))
        out.put(("done", (acc / spp).astype(np.float32)))
    except Exception as e:  # reported in the panel, the viewer keeps running
        text = str(e).splitlines()[0] if str(e) else type(e).__name__
        out.put(("error", f"{type(e).__name__}: {text}"))


class ReferenceJob:
    def __init__(self, scene, width: int, height: int, spp: int = 64, chunks: int = 8):
        snap = copy.copy(scene)
        snap.camera = copy.deepcopy(scene.camera)
        snap.sun = copy.deepcopy(scene.sun)
        self.camera, self.sun = snap.camera, snap.sun
        self.width, self.height, self.spp = int(width), int(height), int(spp)
        self.progress = 0.0
        self.result: np.ndarray | None = None
        self.error: str | None = None
        ctx = mp.get_context("spawn")
        self._queue = ctx.Queue()
        self._proc = ctx.Process(target=_worker, args=(snap, self.width, self.height, self.spp, chunks, self._queue),
                                 daemon=True, name="serenity-reference")
        self._proc.start()

    @property
    def running(self) -> bool:
        return self.result is None and self.error is None

    def poll(self) -> float:
        """Take the worker's news without waiting; returns the progress in [0, 1]."""
        while self.running:
            try:
                kind, value = self._queue.get_nowait()
            except queue.Empty:
                if not self._proc.is_alive() and self._queue.empty():
                    self.error = f"the reference process ended unexpectedly (exit code {self._proc.exitcode})"
                break
            if kind == "progress":
                self.progress = float(value)
            elif kind == "done":
                self.result, self.progress = value, 1.0
            else:
                self.error = str(value)
        return self.progress

    def wait(self, timeout: float | None = None) -> None:
        """Block until the job ends (scripted mode and tests)."""
        t_end = None if timeout is None else time.monotonic() + timeout
        while self.running and (t_end is None or time.monotonic() < t_end):
            self.poll()
            time.sleep(0.05)

    def cancel(self) -> None:
        if self._proc.is_alive():
            self._proc.terminate()
            self._proc.join(timeout=5)

"""What a Dask worker runs: one frame, one reference or one comparison, returned as arrays.

Each worker is its own process (a Dask nanny's child) with one thread, so it holds its own headless
GL context (``serenity.raster.context``) and its own Warp runtime and kernel cache in memory; the
on-disk caches (Warp's kernels, the references under ``SERENITY_CACHE``) are shared by the workers of
a machine. Results travel back to the client, which alone writes the results directory: workers on
other machines need no shared file system.

A task never raises for a reason of its own (a bad scene file, an invalid preset): it returns
``{"status": "error", "error": "<one line>"}`` so the sweep records it and carries on. A worker
that dies mid-task (killed, out of memory) is another matter: Dask reschedules its task elsewhere.
"""

from __future__ import annotations

import contextlib
import copy
import gc
import os
import socket
import time
from dataclasses import replace

import numpy as np

from serenity.errors import SerenityError
from serenity.eval.metrics import compare, flip_png, rel_mse
from serenity.eval.reference import render_reference
from serenity.frame import Renderer
from serenity.raster.context import get_context
from serenity.scene import load
from serenity.scene.sun import DEFAULT_LOCATION, sun_from_time
from serenity.sweep.spec import quality_config

REL_MSE_TRIM = 1e-3
"""Fraction of the worst pixels left out of ``rel_mse_trim`` (one pixel where only one renderer shows
the sun's disc can otherwise outweigh the whole image)."""


def one_line(e: BaseException) -> str:
    """A one-line message: a ``SerenityError``'s own text, else ``Type: first line``."""
    text = str(e).strip().splitlines()[0] if str(e).strip() else ""
    if isinstance(e, SerenityError):
        return text or type(e).__name__
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


def _announce() -> None:
    """Tell the client (topic ``serenity-sweep``) that this worker starts the current task."""
    try:
        from distributed import get_worker

        w = get_worker()
        w.log_event("serenity-sweep", {"key": str(w.get_current_task()), "worker": w.address, "pid": os.getpid()})
    except (ImportError, ValueError):
        pass


def _where() -> dict:
    try:
        from distributed import get_worker

        addr = get_worker().address
    except (ImportError, ValueError):
        addr = None
    return {"worker": addr, "host": socket.gethostname(), "pid": os.getpid()}


@contextlib.contextmanager
def _cache_env(cache: str | None):
    """``SERENITY_CACHE`` set to ``cache`` for the duration (the reference module reads it per call)."""
    if cache is None:
        yield
        return
    old = os.environ.get("SERENITY_CACHE")
    os.environ["SERENITY_CACHE"] = cache
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("SERENITY_CACHE", None)
        else:
            os.environ["SERENITY_CACHE"] = old


def load_scene_at(inputs: dict):
    """The task's scene, its sun moved to ``inputs["time"]`` (when given) at the sweep's place, else
    the scene's location, else Lisbon; the sun's angular size is kept."""
    scene = load(inputs["scene"])
    if inputs.get("time") is not None:
        if scene is inputs["scene"]:  # a Scene object given in-process: leave the caller's alone
            scene = copy.copy(scene)
        if inputs.get("latitude") is not None:
            lat, lon = inputs["latitude"], inputs["longitude"]
        else:
            lat, lon = getattr(scene, "location", None) or DEFAULT_LOCATION
        old = scene.sun
        scene.sun = sun_from_time(inputs["time"], lat, lon)
        scene.sun.angular_diameter_deg = old.angular_diameter_deg
    return scene


def _sun_info(scene) -> dict:
    return {"sun_elevation_deg": float(scene.sun.elevation_deg), "sun_azimuth_deg": float(scene.sun.azimuth_deg)}


def _release_gl() -> None:
    """Free the GL objects of the renderers this worker no longer holds before its next task.

    moderngl frees an object only on ``release()``; in ``context_gc`` mode a collected wrapper
    queues its GL object on the context instead, and this releases the queue (skipping objects that
    were released already: moderngl queues those as ``InvalidObject``)."""
    ctx = get_context()
    if ctx.gc_mode != "context_gc":
        ctx.gc_mode = "context_gc"
    gc.collect()
    while ctx.objects:
        obj = ctx.objects.popleft()
        release = getattr(obj, "release", None)
        if release is not None:
            release()


def run_frame(inputs: dict) -> dict:
    """Our renderer at one point: ``hdr`` (H, W, 3) float32 W·m⁻²·sr⁻¹, ``ldr`` (H, W, 3) uint8 at the
    sweep's exposure, the last frame's stage timings (ms) and wall time (ms)."""
    _announce()
    t0 = time.perf_counter()
    renderer = None
    try:
        config = replace(quality_config(inputs["quality"]), exposure=inputs["exposure"])
        scene = load_scene_at(inputs)
        renderer = Renderer(scene, inputs["width"], inputs["height"], device=inputs.get("device"), config=config)
        frame = None
        for _ in range(inputs["frames"]):
            frame = renderer.render()
        return {"status": "done", "hdr": frame.hdr, "ldr": frame.ldr, "frame_wall_ms": float(frame.wall_ms),
                "stages_ms": {k: float(v) for k, v in frame.timings.items()}, "device": renderer.device,
                **_sun_info(scene), "task_s": time.perf_counter() - t0, **_where()}
    except Exception as e:
        return {"status": "error", "error": one_line(e), "task_s": time.perf_counter() - t0, **_where()}
    finally:
        if renderer is not None:
            renderer.close()
            del renderer
            _release_gl()


def run_reference(inputs: dict, cache: str | None = None) -> dict:
    """The Mitsuba 3 reference at one point (``hdr`` as in :func:`run_frame`), through the shared
    reference cache ``cache`` (default: ``SERENITY_CACHE`` or the user's cache directory)."""
    _announce()
    t0 = time.perf_counter()
    try:
        scene = load_scene_at(inputs)
        info: dict = {}
        with _cache_env(cache):
            img = render_reference(scene, inputs["width"], inputs["height"], spp=inputs["spp"],
                                   component=inputs.get("component", "full"), seed=inputs.get("seed", 0),
                                   max_depth=inputs.get("max_depth"), progress=False, info=info)
        return {"status": "done", "hdr": img, "cached": bool(info.get("cached")), **_sun_info(scene),
                "task_s": time.perf_counter() - t0, **_where()}
    except Exception as e:
        return {"status": "error", "error": one_line(e), "task_s": time.perf_counter() - t0, **_where()}


def run_compare(frame, reference, exposure: float) -> dict:
    """relMSE and FLIP of our frame against the reference (``serenity.eval.metrics.compare``), relMSE
    without the :data:`REL_MSE_TRIM` worst pixels, and the FLIP map as a magma PNG.
    ``frame``/``reference``: a task's result, or its (H, W, 3) HDR array."""
    t0 = time.perf_counter()
    for name, r in (("frame", frame), ("reference", reference)):
        if isinstance(r, dict) and r.get("status") != "done":
            return {"status": "error", "error": f"no {name} to compare: {r.get('error', 'it failed')}", **_where()}
    try:
        ours = frame["hdr"] if isinstance(frame, dict) else np.asarray(frame)
        ref = reference["hdr"] if isinstance(reference, dict) else np.asarray(reference)
        r = compare(ours, ref, exposure=exposure)
        trimmed = rel_mse(ours, ref, trim=REL_MSE_TRIM)
        return {"status": "done", "rel_mse": r["rel_mse"], "rel_mse_rgb": r["rel_mse_rgb"], "rel_mse_trim": trimmed,
                "flip": r["flip"],
                "flip_png": flip_png(r["flip_map"]), "task_s": time.perf_counter() - t0, **_where()}
    except Exception as e:
        return {"status": "error", "error": one_line(e), "task_s": time.perf_counter() - t0, **_where()}

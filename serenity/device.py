"""Resolve the compute device once and initialise Warp lazily.

A device is a Warp device string: ``"cpu"`` always exists, ``"cuda:N"`` where a CUDA driver and
GPU are present. ``resolve_device(None)`` picks ``cuda:0`` when available, else ``cpu``. Nothing
happens at import time: Warp is initialised on the first call (quietly), so importing
``serenity`` costs nothing and never touches a GPU.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass

_lock = threading.Lock()
_initialised = False


class DeviceError(RuntimeError):
    """A requested device does not exist on this machine."""


def init_warp():
    """Initialise Warp once (quiet, no backward passes); return the ``warp`` module."""
    global _initialised
    import warp as wp

    if not _initialised:
        with _lock:
            if not _initialised:
                wp.config.quiet = True
                if hasattr(wp, "LOG_WARNING"):  # Warp >= 1.13 logs by level
                    wp.config.log_level = wp.LOG_WARNING
                _init_quietly(wp)
                _initialised = True
    return wp


def _init_quietly(wp) -> None:
    """``wp.init()`` with the native "no CUDA driver" notice filtered out of stderr: on a machine
    without a GPU that is the expected state, not news (other native messages pass through)."""
    import sys
    import tempfile

    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):  # stderr replaced (pytest capture, notebooks)
        wp.init()
        return
    sys.stderr.flush()
    saved = os.dup(fd)
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        os.dup2(tmp.fileno(), fd)
        try:
            wp.init()
        finally:
            os.dup2(saved, fd)
            os.close(saved)
        tmp.seek(0)
        text = tmp.read().decode(errors="replace")
    kept = [ln for ln in text.splitlines() if ln.strip() and "Could not find or load the NVIDIA CUDA driver" not in ln]
    if kept:
        print("\n".join(kept), file=sys.stderr)


def available_devices() -> list[str]:
    """All Warp devices on this machine, ``cpu`` first."""
    wp = init_warp()
    return [str(d) for d in wp.get_devices()]


def resolve_device(device: str | None = None) -> str:
    """Return a valid Warp device string for ``device`` (None → cuda:0 if present, else cpu).

    ``SERENITY_DEVICE`` in the environment overrides the default (not an explicit argument).
    """
    wp = init_warp()
    if device is None:
        device = os.environ.get("SERENITY_DEVICE") or None
    if device is None:
        return "cuda:0" if wp.is_cuda_available() else "cpu"
    device = str(device)
    if device == "cuda":
        device = "cuda:0"
    names = available_devices()
    if device not in names:
        raise DeviceError(f"device {device!r} is not available here (available: {', '.join(names)})")
    return device


@dataclass(frozen=True)
class DeviceInfo:
    """Capability flags of a resolved device."""

    name: str
    is_cuda: bool
    threads: int  # worker threads a CPU launch is split over (1 on CUDA: one launch)


def device_info(device: str | None = None) -> DeviceInfo:
    name = resolve_device(device)
    is_cuda = name.startswith("cuda")
    return DeviceInfo(name=name, is_cuda=is_cuda, threads=1 if is_cuda else cpu_threads())


def cpu_threads() -> int:
    """Worker threads for CPU launches: ``SERENITY_THREADS`` or the CPUs this process may use."""
    env = os.environ.get("SERENITY_THREADS")
    if env:
        return max(1, int(env))
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)

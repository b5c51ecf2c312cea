"""Resolve the compute device once and initialise Warp lazily.

A device is a Warp device string: ``"cpu"`` always exists, ``"cuda:N"`` where a CUDA driver and
GPU are present. ``resolve_device(None)`` is ``SERENITY_DEVICE`` if set, else ``cuda:0`` where there
is one, else ``cpu``; the CUDA path (the LPV's atomic scatter and staging, the single-launch path of
``kernels/launch.py``) has run on an NVIDIA H200 (the test suite on ``cpu,cuda:0``, and
``benchmarks/bench_cuda.py``: its images agree with the CPU's). A device that does not exist raises
``DeviceError`` (a ``SerenityError``: the CLI prints one line). Nothing happens at
import time: Warp is imported but initialised on the first call (quietly), so importing this
module never touches a GPU (and ``import serenity`` does not import it).
"""

from __future__ import annotations

import os
import sys
import tempfile
import threading
from dataclasses import dataclass

import warp as wp

from serenity.errors import SerenityError

_lock = threading.Lock()
_initialised = False


class DeviceError(SerenityError, RuntimeError):
    """A requested device does not exist on this machine."""


def init_warp():
    """Initialise Warp once (quiet, no backward passes); return the ``warp`` module."""
    global _initialised
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
    """Return a valid Warp device string for ``device`` (None → ``cuda:0`` where there is one, else
    ``cpu``). ``SERENITY_DEVICE`` in the environment overrides that default (not an explicit argument)."""
    init_warp()
    names = available_devices()
    if device is None:
        device = os.environ.get("SERENITY_DEVICE") or ("cuda:0" if "cuda:0" in names else "cpu")
    device = str(device)
    if device == "cuda":
        device = "cuda:0"
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

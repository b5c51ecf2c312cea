"""Resolve the compute device once and initialise Warp lazily.

A device is a Warp device string: ``"cpu"`` always exists, ``"cuda:N"`` where a CUDA driver and
GPU are present. ``resolve_device(None)`` is ``cpu`` (or ``SERENITY_DEVICE``): the CUDA path (the
LPV's atomic scatter and staging, the single-launch path of ``kernels/launch.py``) compiles for
GPUs (``tests/kernels/test_cuda_compile.py``) but has not run on one yet, so it is chosen only
explicitly (``--device cuda:0``) and says so once, in one line on stderr. A device that does not
exist raises ``DeviceError`` (a ``SerenityError``: the CLI prints one line). Nothing happens at
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
_cuda_noted = False

#: printed once per process the first time a CUDA device is resolved
CUDA_UNVERIFIED_NOTICE = ("serenity: note: the CUDA path has not been run on a GPU yet (its kernels compile for "
                          "sm_75/sm_90); results on {device} are unverified, --device cpu is the tested path")


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
    """Return a valid Warp device string for ``device`` (None → ``cpu``; CUDA only when asked for).

    ``SERENITY_DEVICE`` in the environment overrides the default (not an explicit argument). The
    first CUDA device resolved in a process prints ``CUDA_UNVERIFIED_NOTICE`` (one line, stderr).
    """
    global _cuda_noted
    init_warp()
    if device is None:
        device = os.environ.get("SERENITY_DEVICE") or "cpu"
    device = str(device)
    if device == "cuda":
        device = "cuda:0"
    names = available_devices()
    if device not in names:
        raise DeviceError(f"device {device!r} is not available here (available: {', '.join(names)})")
    if device.startswith("cuda") and not _cuda_noted:
        _cuda_noted = True
        print(CUDA_UNVERIFIED_NOTICE.format(device=device), file=sys.stderr)
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

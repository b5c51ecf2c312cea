"""Keeping the BLAS library's own thread pool out of the frame's way.

numpy's matrix products call OpenBLAS (or MKL), which by default starts one thread per core and,
after each call, keeps them spinning for a while waiting for the next one. Inside a frame the
cores are already taken — llvmpipe renders on its own threads and every Warp CPU launch is split
over a thread per core (``kernels/launch.py``) — so those spinning threads steal the cores from
the real work. Measured on the 2-core machine while other jobs ran: the sky projection's
(26 × 7232) @ (7232 × 3) product took 2–10 ms with OpenBLAS's default pool and 0.15 ms on one
thread, and the sky transfer's Warp launch next to it went from ~15 to ~5.5 CPU-ms.

:func:`lower_thread_priority` lowers one worker thread's priority (``ScheduleConfig.volume_nice``).

:func:`single_threaded_blas` limits the BLAS pool to one thread for the duration of a ``with``
block (``threadpoolctl``, the library scikit-learn uses for the same purpose) and restores the
caller's setting afterwards, so a program that renders between its own large matrix products
keeps its BLAS threads for them.
"""

from __future__ import annotations

import os
import threading
from contextlib import AbstractContextManager

from threadpoolctl import ThreadpoolController

_controller: ThreadpoolController | None = None


def single_threaded_blas() -> AbstractContextManager:
    """A context manager under which numpy's BLAS runs on the calling thread only."""
    global _controller
    if _controller is None:  # scans the loaded libraries once (a few ms)
        _controller = ThreadpoolController()
    return _controller.limit(limits=1, user_api="blas")


def lower_thread_priority(nice: int) -> None:
    """Add ``nice`` (≥ 0) to the calling thread's niceness, where the OS allows (Linux: niceness is
    per thread, and a thread may always lower its own priority); a no-op for 0 or elsewhere. Used as
    a worker pool's initializer, so it acts on the worker's own thread only."""
    if nice <= 0 or not hasattr(os, "setpriority"):
        return
    try:
        tid = threading.get_native_id()
        os.setpriority(os.PRIO_PROCESS, tid, min(19, os.getpriority(os.PRIO_PROCESS, tid) + int(nice)))
    except OSError:  # not permitted here: the thread keeps the process's priority
        pass

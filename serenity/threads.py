"""Keeping the BLAS library's own thread pool out of the frame's way, and llvmpipe's rasteriser
threads out of the CPU ray tracer's.

numpy's matrix products call OpenBLAS (or MKL), which by default starts one thread per core and,
after each call, keeps them spinning for a while waiting for the next one. Inside a frame the
cores are already taken — llvmpipe renders on its own threads and every Warp CPU launch is split
over a thread per core (``kernels/launch.py``) — so those spinning threads steal the cores from
the real work. Measured on the 2-core machine while other jobs ran: the sky projection's
(26 × 7232) @ (7232 × 3) product took 2–10 ms with OpenBLAS's default pool and 0.15 ms on one
thread, and the sky transfer's Warp launch next to it went from ~15 to ~5.5 CPU-ms.

:func:`single_threaded_blas` limits the BLAS pool to one thread for the duration of a ``with``
block (``threadpoolctl``, the library scikit-learn uses for the same purpose) and restores the
caller's setting afterwards, so a program that renders between its own large matrix products
keeps its BLAS threads for them.

:func:`yield_gl_threads` lowers the scheduling priority (raises the nice value) of llvmpipe's
rasteriser threads ("llvmpipe-N"; Linux only). The overlapped schedule runs the CPU ray tracer in a
child process beside the GL passes (``kernels/tracer_process.py``); on two cores llvmpipe's
threads and the tracer want the same cores, and with equal priority the tracer took 1.6–2.2× its
inline time beside them. With the rasteriser threads at nice 10 the kernel gives the tracer the
core whenever both are runnable (the paper's model: the GPU renders while a CPU core traces), and
GL work takes whatever the tracer leaves; a frame's total work is unchanged. Raising one's own
threads' nice value needs no privilege; it is per thread and stays for the life of the threads
(llvmpipe's belong to the process's one GL context).
"""

from __future__ import annotations

import os
from contextlib import AbstractContextManager

from threadpoolctl import ThreadpoolController

_controller: ThreadpoolController | None = None


def single_threaded_blas() -> AbstractContextManager:
    """A context manager under which numpy's BLAS runs on the calling thread only."""
    global _controller
    if _controller is None:  # scans the loaded libraries once (a few ms)
        _controller = ThreadpoolController()
    return _controller.limit(limits=1, user_api="blas")


#: nice value of llvmpipe's rasteriser threads while a tracer process runs beside them
GL_THREAD_NICE = 10


def yield_gl_threads(nice: int = GL_THREAD_NICE) -> int:
    """Set the nice value of this process's llvmpipe rasteriser threads to ``nice`` (never lowering
    one already higher); returns how many threads were changed (0 where there are none, off Linux,
    or when the kernel refuses)."""
    if not hasattr(os, "setpriority") or not os.path.isdir("/proc/self/task"):
        return 0
    changed = 0
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/comm") as f:
                if not f.read().startswith("llvmpipe"):
                    continue
            if os.getpriority(os.PRIO_PROCESS, int(tid)) < nice:
                os.setpriority(os.PRIO_PROCESS, int(tid), nice)
                changed += 1
        except (OSError, ValueError):  # the thread ended, or no permission: leave it
            continue
    return changed

"""Launch a 1-D Warp kernel over all CPU cores, or once on CUDA.

Warp runs a CPU launch on a single thread. Warp releases the GIL while a CPU kernel runs, so
splitting the index range into contiguous chunks and launching each chunk from its own Python
thread scales with the cores (1.9x with 2 threads on the 2-core CI machine).

Convention for a splittable kernel: its **last parameter is** ``offset: int`` and it computes its
index as ``i = wp.tid() + offset``. ``launch`` appends that offset; on CUDA it is 0 and the whole
range goes in one launch. Chunks are contiguous so that neighbouring (coherent) items stay on one
thread. Kernels must write only to their own index (or use atomics): chunks run concurrently.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Any

from serenity.device import cpu_threads, init_warp

_pool: ThreadPoolExecutor | None = None
_pool_size = 0

#: below this many items per thread, splitting costs more than it saves
MIN_ITEMS_PER_THREAD = 256


def _executor(n: int) -> ThreadPoolExecutor:
    global _pool, _pool_size
    if _pool is None or _pool_size < n:
        if _pool is not None:
            _pool.shutdown(wait=True)
        _pool = ThreadPoolExecutor(max_workers=n, thread_name_prefix="serenity-launch")
        _pool_size = n
    return _pool


def chunk_ranges(dim: int, threads: int, min_items: int = MIN_ITEMS_PER_THREAD) -> list[tuple[int, int]]:
    """Split ``[0, dim)`` into at most ``threads`` contiguous ``(start, count)`` chunks."""
    if dim <= 0:
        return []
    n = max(1, min(threads, dim // max(1, min_items)))
    base, extra = divmod(dim, n)
    out, start = [], 0
    for k in range(n):
        count = base + (1 if k < extra else 0)
        out.append((start, count))
        start += count
    return out


def launch(kernel: Any, dim: int, inputs: list, device: str, threads: int | None = None, start: int = 0) -> None:
    """Launch ``kernel`` over ``[start, start + dim)``; the kernel's trailing ``offset: int`` is appended.

    On ``cpu`` the range is split over ``threads`` worker threads (default: all usable CPUs,
    ``SERENITY_THREADS`` overrides) and this call returns when every chunk is done. On CUDA it is a
    single asynchronous launch, as ``wp.launch`` is.
    """
    wp = init_warp()
    dim = int(dim)
    if dim <= 0:
        return
    if not str(device).startswith("cpu"):
        wp.launch(kernel, dim=dim, inputs=[*inputs, int(start)], device=device)
        return
    chunks = chunk_ranges(dim, threads or cpu_threads())
    if len(chunks) == 1:
        wp.launch(kernel, dim=dim, inputs=[*inputs, int(start)], device=device)
        return
    # compile/load the module on this thread first so worker threads never race to build it
    kernel.module.load(wp.get_device(device))
    pool = _executor(len(chunks))
    futures = [
        pool.submit(wp.launch, kernel, dim=count, inputs=[*inputs, int(start) + first], device=device)
        for first, count in chunks
    ]
    for f in futures:
        f.result()

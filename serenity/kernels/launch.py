"""Launch a 1-D Warp kernel over all CPU cores, or once on CUDA.

Warp runs a CPU launch on a single thread. Warp releases the GIL while a CPU kernel runs, so
splitting the index range into contiguous chunks and launching each chunk from its own Python
thread scales with the cores (1.9x with 2 threads on the 2-core CI machine). The calling thread is
one of the workers (worker 0) and the pool supplies the others; whichever is free takes the next
chunk, and the call returns when every chunk is done (:func:`_run_chunks`: a pool thread on an idle
vCPU can take a millisecond or more to wake, and meanwhile the calling thread works).

Convention for a splittable kernel: its **last parameter is** ``offset: int`` and it computes its
index as ``i = wp.tid() + offset``. ``launch`` appends that offset; on CUDA it is 0 and the whole
range goes in one launch. Chunks are contiguous so that neighbouring (coherent) items stay on one
thread. Kernels must write only to their own index (or use atomics): chunks run concurrently.

Scatter kernels (many items adding into shared cells) use a ``ScatterGrid``: Warp 1.19's CPU
``atomic_add`` is a plain read-modify-write (warp/native/builtin.h), not atomic, so on the CPU each
launch chunk adds into its own private copy of the grid (a "slot", found from the chunk's
``offset`` by ``slot_base``) and ``gather`` sums the slots into the grid; on CUDA the kernel adds
straight into the grid with real atomics. ``Staging`` turns numpy inputs into device arrays (a
zero-copy wrap on the CPU, a copy into a grow-only buffer on CUDA). Callers never branch on the
device: those two differences live here.

Balance (``balanced=True``): when items cost very different amounts — rays into the sky beside
rays into geometry, the upper half of a camera's image beside the lower — one chunk per thread
leaves a thread idle while the other finishes: on the kd-tree benchmark's rays that caps 2
threads at 1.45× one (``bench_kdtree``: Σ thread CPU / busiest thread). A balanced launch cuts the
range into contiguous chunks that shrink as it is used up (guided scheduling,
:func:`guided_ranges`), and the workers take the next chunk as they finish one, so they end
together: the first chunks are big (few launches: each costs one ``wp.launch``, ~0.1 ms of Python
under the GIL, while the other workers run native code), the last ones short (the worker that
finishes first waits at most one short chunk). Equal chunks, 16 per thread, would leave a thread
idle for up to a sixteenth of the launch at its end: on the incoherent kd-tree query on 2 threads
they reach 1.74× one thread, guided chunks 1.79× (timed in one process). Chunks stay
contiguous and at least ``min_chunk`` items long, so outputs share a cache line only at chunk
borders (no false sharing to speak of). Unbalanced, the chunks are exactly ``chunk_ranges(dim,
threads)`` (callers that key per-worker buffers on the chunk offsets rely on that).
"""

from __future__ import annotations

import itertools
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import warp as wp

from serenity.device import cpu_threads, init_warp

_pool: ThreadPoolExecutor | None = None
_pool_size = 0

#: below this many items per thread, splitting costs more than it saves
MIN_ITEMS_PER_THREAD = 256
#: a balanced launch's chunks are not made smaller than this (each is one ``wp.launch``)
MIN_ITEMS_PER_CHUNK = 4096
#: ``min_items`` for kernels with ~0.1 µs of work per item (a volume's cells, VPLs scattered into
#: it): a chunk handed to a worker costs ~0.2 ms of Python under the GIL, so a 3 x 12³ LPV
#: propagation step (5184 cells, ~0.6 ms) took 8.3 ms for 8 steps on 2 threads against 5.1 ms on
#: 1, and 19.4 ms on 16 (the 2-core machine; 32³: 100.8 ms on 1 thread, 85.7 on 2)
MIN_CHEAP_ITEMS_PER_THREAD = 16384


_pool_lock = threading.Lock()
_retired: list[ThreadPoolExecutor] = []


def _executor(n: int) -> ThreadPoolExecutor:
    """The launch threads' pool, with at least ``n`` workers. The main thread and the volume worker
    both launch: the pool is swapped under a lock, and a smaller one it replaces is kept, not shut
    down, since the other thread may still be submitting to it (its idle workers cost nothing)."""
    global _pool, _pool_size
    with _pool_lock:
        if _pool is None or _pool_size < n:
            if _pool is not None:
                _retired.append(_pool)
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


def guided_ranges(dim: int, workers: int, min_chunk: int = MIN_ITEMS_PER_CHUNK) -> list[tuple[int, int]]:
    """Split ``[0, dim)`` into contiguous ``(start, count)`` chunks that shrink as the range is used
    up (guided scheduling): each takes 1 / (2 · workers) of what is left, but at least ``min_chunk``
    items; one chunk for one worker. Handed out in order to whichever worker is free, the first
    chunks keep the launches few and the last ones short, so the workers end together."""
    if dim <= 0:
        return []
    if workers <= 1:
        return [(0, dim)]
    out, start = [], 0
    while start < dim:
        count = min(dim - start, max(max(1, min_chunk), (dim - start) // (2 * workers)))
        out.append((start, count))
        start += count
    return out


def launch(kernel: Any, dim: int, inputs: list, device: str, threads: int | None = None, start: int = 0,
           balanced: bool = False, min_items: int = MIN_ITEMS_PER_THREAD, worker_arg: bool = False,
           min_chunk: int = MIN_ITEMS_PER_CHUNK, chunks_per_thread: int | None = None) -> None:
    """Launch ``kernel`` over ``[start, start + dim)``; the kernel's trailing ``offset: int`` is appended.

    On ``cpu`` the range is split over ``threads`` worker threads (default: all usable CPUs,
    ``SERENITY_THREADS`` overrides) and this call returns when every chunk is done; ``balanced``:
    into contiguous chunks that shrink as the range is used up (:func:`guided_ranges`), taken in
    order by whichever worker is free (module docstring). A thread gets at least ``min_items`` items (fewer
    threads when ``dim`` is small: ``MIN_CHEAP_ITEMS_PER_THREAD`` for cheap per-item kernels). On CUDA it
    is a single asynchronous launch, as ``wp.launch`` is.

    ``worker_arg``: the kernel's trailing parameters are ``worker: int, offset: int``; ``worker`` is
    the index (0 … threads − 1) of the worker thread running the chunk, so that a kernel can keep
    per-worker working memory (no two chunks with the same index run at once; 0 on CUDA).
    ``min_chunk``: a balanced launch's chunks are not made smaller than this many items
    (``MIN_ITEMS_PER_CHUNK`` for items of about one ray's work; fewer for items that each do more).
    ``chunks_per_thread`` > 1 is another spelling of ``balanced=True``, accepted for the earlier
    versions of the kd-tree that ``bench_kdtree_steps.py`` loads beside this module.
    """
    wp = init_warp()
    dim = int(dim)
    if dim <= 0:
        return

    def args(worker: int, offset: int) -> list:
        return [*inputs, worker, offset] if worker_arg else [*inputs, offset]

    if not str(device).startswith("cpu"):
        wp.launch(kernel, dim=dim, inputs=args(0, int(start)), device=device)
        return
    workers = threads or cpu_threads()
    balanced = balanced or (chunks_per_thread or 1) > 1
    chunks = guided_ranges(dim, workers, min_chunk) if balanced else chunk_ranges(dim, workers, min_items)
    if len(chunks) == 1:
        wp.launch(kernel, dim=dim, inputs=args(0, int(start)), device=device)
        return
    # compile/load the module on this thread first so worker threads never race to build it
    kernel.module.load(wp.get_device(device))
    workers = min(workers, len(chunks))
    _run_chunks(lambda worker, first, count: wp.launch(kernel, dim=count, inputs=args(worker, int(start) + first),
                                                       device=device), chunks, workers)


class _Chunks:
    """One launch's chunks, taken in order by whichever thread is free (``next`` on an
    ``itertools.count`` is atomic under the GIL), and the count of those not finished yet."""

    def __init__(self, run, chunks: list[tuple[int, int]]):
        self.run, self.chunks = run, chunks
        self.ticket = itertools.count()
        self.left = len(chunks)
        self.lock = threading.Lock()
        self.done = threading.Event()
        self.error: BaseException | None = None

    def work(self, worker: int) -> None:
        while (k := next(self.ticket)) < len(self.chunks):
            try:
                if self.error is None:
                    self.run(worker, *self.chunks[k])
            except BaseException as exc:  # handed to the calling thread
                self.error = exc
            with self.lock:
                self.left -= 1
                if self.left == 0:
                    self.done.set()


def _run_chunks(run, chunks: list[tuple[int, int]], workers: int) -> None:
    """``run(worker, first, count)`` for each chunk on ``workers`` threads: this one (worker 0) and
    ``workers`` − 1 of the pool. The calling thread works too, and returns when every chunk is done,
    not when every pool thread has looked for one: a pool thread whose CPU was idle can take a
    millisecond or more to wake on a 2-vCPU VM, and by then the calling thread may have run the
    chunks it would have taken (a pool that waited for every thread ran 2-chunk launches on one
    thread after the other: the counting sort's passes took 10-13 ms where they take 6-8 split)."""
    state = _Chunks(run, chunks)
    pool = _executor(workers - 1)
    for w in range(1, workers):
        pool.submit(state.work, w)
    state.work(0)
    state.done.wait()
    if state.error is not None:
        raise state.error


# ---------------------------------------------------------------------------------------------
# scatter into private slots (CPU) or with atomics (CUDA)
# ---------------------------------------------------------------------------------------------

#: private scatter grids on the CPU (one per worker thread, capped)
MAX_SLOTS = 8


@wp.func
def slot_base(offset: int, slot_starts: wp.array(dtype=int), slot_stride: int) -> int:
    """First element of the private grid of the launch chunk starting at ``offset`` (0 when the
    kernel writes straight into the grid: CUDA, or one CPU chunk)."""
    s = int(0)
    for k in range(slot_starts.shape[0]):
        if slot_starts[k] == offset:
            s = k
    return s * slot_stride


@wp.kernel(enable_backward=False)
def gather_slots(
    # inputs
    slots: wp.array(dtype=wp.vec4),
    n_slots: int,
    stride: int,
    # outputs
    grid: wp.array(dtype=wp.vec4),
    offset: int,
):
    """grid[i] += Σ_s slots[s·stride + i], and zero the slots (ready for the next scatter)."""
    i = wp.tid() + offset
    acc = grid[i]
    for s in range(n_slots):
        acc += slots[s * stride + i]
        slots[s * stride + i] = wp.vec4()
    grid[i] = acc


class ScatterGrid:
    """A float4 array that scatter kernels add into from every thread (module doc).

    A scatter kernel's trailing parameters are ``slot_starts: wp.array(dtype=int), slot_stride: int,
    out: wp.array(dtype=wp.vec4), offset: int``; it adds item i's contribution to cell j with
    ``wp.atomic_add(out, slot_base(offset, slot_starts, slot_stride) + j, value)``. ``array`` holds
    the sum once ``gather`` has run.
    """

    def __init__(self, size: int, device: str, threads: int | None = None):
        self.size = int(size)
        self.device = device
        self.threads = threads
        self.array = wp.zeros(self.size, dtype=wp.vec4, device=device)
        on_cpu = str(device).startswith("cpu")
        self.n_slots = max(1, min(MAX_SLOTS, threads or cpu_threads())) if on_cpu else 1
        self._slots = wp.zeros(self.n_slots * self.size, dtype=wp.vec4, device=device) if self.n_slots > 1 else None
        self._used = 0  # slots holding un-gathered values
        self._no_slots = wp.zeros(1, dtype=int, device=device)

    def scatter(self, kernel: Any, dim: int, inputs: list) -> None:
        """Launch ``kernel`` over ``dim`` items, adding into this grid (its slots on the CPU)."""
        if dim <= 0:
            return
        chunks = chunk_ranges(dim, min(self.n_slots, self.threads or cpu_threads()), MIN_CHEAP_ITEMS_PER_THREAD)
        if self._slots is None or len(chunks) == 1:
            launch(kernel, dim, [*inputs, self._no_slots, 0, self.array], device=self.device, threads=1)
            return
        starts = wp.array(np.array([s for s, _ in chunks], np.int32), dtype=int, device=self.device)
        launch(kernel, dim, [*inputs, starts, self.size, self._slots], device=self.device, threads=len(chunks),
               min_items=MIN_CHEAP_ITEMS_PER_THREAD)  # the same chunks as above: slot_starts match
        self._used = max(self._used, len(chunks))

    def gather(self) -> None:
        """Sum the private slots into ``array`` (nothing to do on CUDA or after one-chunk launches)."""
        if self._used:
            launch(gather_slots, self.size, [self._slots, self._used, self.size, self.array], device=self.device,
                   threads=self.threads, min_items=MIN_CHEAP_ITEMS_PER_THREAD)
            self._used = 0

    def zero(self) -> None:
        """Zero the grid and any un-gathered slots."""
        self.array.zero_()
        if self._used:
            self._slots.zero_()
            self._used = 0


# ---------------------------------------------------------------------------------------------
# host inputs
# ---------------------------------------------------------------------------------------------


class Staging:
    """Device arrays for host inputs, by name: numpy is wrapped without a copy on the CPU and copied
    into a grow-only buffer (power-of-two sizes) on CUDA; Warp arrays pass through (on this device)."""

    def __init__(self, device: str):
        self.device = device
        self._copy = not str(device).startswith("cpu")
        self._buffers: dict[tuple, wp.array] = {}
        self._fills: dict[tuple, tuple] = {}  # (buffer, value's bytes, elements filled) per filled buffer

    def buffer(self, name: str, n: int, dtype) -> wp.array:
        """The first ``n`` elements of the grow-only buffer ``name`` of ``dtype`` (for outputs, or staged
        inputs; one name may hold one buffer per dtype)."""
        key = (name, dtype)
        buf = self._buffers.get(key)
        if buf is None or buf.shape[0] < n:
            buf = wp.empty(max(n, 1 << max(0, int(n - 1).bit_length())), dtype=dtype, device=self.device)
            self._buffers[key] = buf
        return buf[:n]

    def filled(self, name: str, n: int, dtype, value: float) -> wp.array:
        """The first ``n`` elements of the grow-only buffer ``name``, each ``value``: filled only
        when the buffer's last fill was of another value or of fewer elements (a query's scalar tmax
        as a per-ray array: filling 0.92 M floats each query took ~0.5 ms before any thread works)."""
        view = self.buffer(name, n, dtype)
        key = (name, dtype)
        bits = np.asarray(value, dtype=np.float64).tobytes()  # a numeric scalar
        last = self._fills.get(key)
        if last is None or last[0] is not self._buffers[key] or last[1] != bits or last[2] < n:
            view.fill_(value)
            self._fills[key] = (self._buffers[key], bits, n)
        return view

    def input(self, a, name: str, dtype, width: int) -> wp.array:
        """A device array for ``a`` (numpy-like of ``width`` float32 per item, or a Warp array)."""
        if isinstance(a, wp.array):
            if str(a.device) != self.device:
                raise ValueError(f"{name}: array on {a.device}, expected {self.device}")
            return a
        shape = (-1, width) if width > 1 else (-1,)
        arr = np.ascontiguousarray(np.asarray(a, dtype=np.float32).reshape(shape))
        host = wp.array(arr, dtype=dtype, device="cpu", copy=False)
        if not self._copy:
            return host
        view = self.buffer(name, host.shape[0], dtype)
        wp.copy(view, host, count=host.shape[0])
        return view


def host_array(a) -> np.ndarray | None:
    """``a`` as numpy without a device copy: numpy-likes and CPU Warp arrays; None for device arrays."""
    if isinstance(a, wp.array):
        return a.numpy() if a.device.is_cpu else None
    return np.ascontiguousarray(a)

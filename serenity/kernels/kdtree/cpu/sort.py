"""The CPU's reordering passes (docs/kdtree.md, "Ray reordering"): the keys of 16 rays per kernel
thread as SIMD lanes, the stable counting sort of the keys (:func:`counting_order`), and the gather
and scatter of per-ray arrays in that order with prefetches. CPU only: their natives (``sort.h``)
are clang's vector extensions and prefetches, each a ``__trap()`` on CUDA, where ``reorder`` uses
Warp's radix sort and one element per kernel thread instead.
"""

from __future__ import annotations

from pathlib import Path

import warp as wp

from serenity.device import cpu_threads
from serenity.kernels.launch import Staging, launch

from ..keys import (
    KEY_MASKS,
    SORT_DIGIT_BITS,
    SORT_DIRECTION_BITS,
    SORT_FINE_BITS,
    SORT_ORIGIN_BITS,
)
from ..layout import FLT_MAX, TRACE_MODULE_OPTIONS, workspace_buffer
from ..native import native_body

wp.set_module_options(TRACE_MODULE_OPTIONS)

HEADER = Path(__file__).with_name("sort.h")

#: rays per thread of the CPU's key kernel (:func:`sort_keys_simd`; ``lanes16.h`` loads 16)
KEY_LANES = 16
assert KEY_LANES == 16  # sort_keys_simd's loads (``lanes16.h``)
#: the CPU's counting sort gives each thread a contiguous run of at least this many keys to count
#: (below it, one thread: zeroing and summing a thread's bins costs about as much as counting them)
SORT_MIN_KEYS_PER_THREAD = 1 << 16
#: how many keys ahead the counting sort's placing passes prefetch, for writing, the line of the place
#: a key will take (its bin's next free place now; 0: none): on one thread the placing of the
#: benchmark's incoherent rays' keys is a few per cent faster with cold caches, on two within the
#: noise; 32 or 64 ahead alike, 16 gains nothing
SORT_PREFETCH = 32
#: rays per kernel thread of the CPU's reordering passes (:func:`move_in_order`, :func:`scatter_hits`),
#: and how many rays ahead each prefetches the lines it will read or write at random: the
#: out-of-order core alone keeps too few of those misses in flight (on the benchmark's 0.92 M
#: incoherent rays with cold caches the gather takes about 1/6 less time and the scatter 1/4 less,
#: against one ray per kernel thread without prefetches; docs/kdtree.md, "Reordering")
REORDER_BLOCK = 4096
GATHER_PREFETCH = 64
SCATTER_PREFETCH = 128


_SORT_BINS = wp.constant(1 << SORT_DIGIT_BITS)
_SORT_DIGIT = wp.constant(SORT_DIGIT_BITS)
_SORT_DIGIT_MASK = wp.constant((1 << SORT_DIGIT_BITS) - 1)

#: the C natives' constants (``sort.h``)
_C = {"KEY_LANES": KEY_LANES, **KEY_MASKS, "ORIGIN_CELLS_MAX": float((1 << SORT_ORIGIN_BITS) - 1),
      "DIRECTION_CELLS": float(1 << SORT_DIRECTION_BITS),
      "DIRECTION_CELLS_MAX": float((1 << SORT_DIRECTION_BITS) - 1), "FINE_BITS": SORT_FINE_BITS,
      "FINE_MASK": (1 << SORT_FINE_BITS) - 1, "DIRECTION_KEY_BITS": 2 * SORT_DIRECTION_BITS, "FLT_MAX_F": FLT_MAX,
      "GATHER_PREFETCH": GATHER_PREFETCH, "SCATTER_PREFETCH": SCATTER_PREFETCH}


def _native(name: str) -> str:
    return native_body(HEADER, name, cpu_only=True, defines=_C)


@wp.func_native(_native("keys_simd"))
def keys_simd(box_lo: wp.vec3, scale: wp.vec3, origins: wp.array(dtype=wp.vec3), directions: wp.array(dtype=wp.vec3),
              keys: wp.array(dtype=wp.uint32), first: int):
    """:func:`ray_sort_key` of rays ``first`` … ``first + KEY_LANES - 1`` into ``keys``, the rays as
    SIMD lanes (clang's vector extensions; contiguous arrays): the same float32 operations and the
    same bits (tests), the Morton spreads as shifts and masks of all lanes."""
    ...


@wp.func_native(_native("prefetch_low_place"))
def prefetch_low_place(keys: wp.array(dtype=wp.uint32), starts: wp.array(dtype=wp.int32),
                       first: wp.array(dtype=wp.int32), high: wp.array(dtype=wp.uint16), base: int, mask: int,
                       ahead: int, end: int):
    """Prefetch, for writing, the places in ``first`` and ``high`` that key ``ahead`` would take now."""
    ...


@wp.func_native(_native("prefetch_high_place"))
def prefetch_high_place(high: wp.array(dtype=wp.uint16), starts: wp.array(dtype=wp.int32),
                        order: wp.array(dtype=wp.int32), base: int, ahead: int, end: int):
    """Prefetch, for writing, the place in ``order`` that the key at ``ahead`` would take now."""
    ...


@wp.func_native(_native("move_range"))
def move_range(order: wp.array(dtype=wp.int32), src: wp.uint64, dst: wp.uint64, size: int, scatter: int,
               first: int, count: int):
    """For i in ``[first, first + count)``: element ``order[i]`` of ``src`` to element i of ``dst``
    (a gather), or element i to element ``order[i]`` (``scatter``); elements of ``size`` bytes,
    contiguous arrays at the addresses ``src``, ``dst``."""
    ...


@wp.func_native(_native("scatter_hits_range"))
def scatter_hits_range(order: wp.array(dtype=wp.int32), t: wp.array(dtype=float), prim: wp.array(dtype=wp.int32),
                       u: wp.array(dtype=float), v: wp.array(dtype=float), records: wp.array(dtype=wp.vec4),
                       first: int, count: int):
    """``records[order[i]] = (t[i], prim[i]'s bits, u[i], v[i])`` for i in ``[first, first + count)``
    (contiguous arrays)."""
    ...


@wp.kernel(enable_backward=False)
def sort_keys_simd(
    # inputs
    box_lo: wp.vec3,
    scale: wp.vec3,
    origins: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    # outputs
    keys: wp.array(dtype=wp.uint32),
    offset: int,
):
    """:func:`sort_keys` for ``KEY_LANES`` rays per thread (:func:`keys_simd`; CPU)."""
    keys_simd(box_lo, scale, origins, directions, keys, (wp.tid() + offset) * KEY_LANES)


@wp.kernel(enable_backward=False)
def count_keys(
    # inputs
    keys: wp.array(dtype=wp.uint32),
    n: int,
    per_run: int,
    # outputs
    counts: wp.array(dtype=wp.int32),
    offset: int,
):
    """Run r = tid + offset of :func:`counting_order`: how many of keys ``[r·per_run, (r+1)·per_run)``
    have each low digit, into ``counts[2r·B + digit]``, and each high digit, into
    ``counts[(2r+1)·B + digit]``, B = 2^SORT_DIGIT_BITS (its own bins: zeroed first, no atomics)."""
    r = wp.tid() + offset
    low = 2 * r * _SORT_BINS
    high = low + _SORT_BINS
    for b in range(2 * _SORT_BINS):
        counts[low + b] = 0
    for i in range(r * per_run, wp.min(n, (r + 1) * per_run)):
        k = int(keys[i])
        a = low + (k & _SORT_DIGIT_MASK)
        counts[a] = counts[a] + 1
        c = high + (k >> _SORT_DIGIT)
        counts[c] = counts[c] + 1


@wp.kernel(enable_backward=False)
def place_keys(
    # inputs
    keys: wp.array(dtype=wp.uint32),
    n: int,
    # outputs
    starts: wp.array(dtype=wp.int32),
    first: wp.array(dtype=wp.int32),
    high: wp.array(dtype=wp.uint16),
    order: wp.array(dtype=wp.int32),
    offset: int,
):
    """The placing passes of :func:`counting_order`, on one thread (a stable LSD radix sort of two
    digits): each key's index, in the keys' order, at the next free place of its low digit's bin
    (``starts[digit]``, advanced), into ``first``, its high digit beside it into ``high`` (so that the
    second pass reads them in order, not at random); then each of those, in that order, at the next
    free place of its high digit's bin (``starts[2^SORT_DIGIT_BITS + digit]``), into ``order``."""
    for i in range(n):
        if wp.static(SORT_PREFETCH > 0):
            prefetch_low_place(keys, starts, first, high, 0, _SORT_DIGIT_MASK, i + SORT_PREFETCH, n)
        k = int(keys[i])
        b = k & _SORT_DIGIT_MASK
        j = starts[b]
        first[j] = i
        high[j] = wp.uint16(k >> _SORT_DIGIT)
        starts[b] = j + 1
    for j in range(n):
        if wp.static(SORT_PREFETCH > 0):
            prefetch_high_place(high, starts, order, _SORT_BINS, j + SORT_PREFETCH, n)
        b = _SORT_BINS + int(high[j])
        p = starts[b]
        order[p] = first[j]
        starts[b] = p + 1


@wp.kernel(enable_backward=False)
def place_low_runs(
    # inputs
    keys: wp.array(dtype=wp.uint32),
    n: int,
    per_run: int,
    owner: wp.array(dtype=wp.int32),
    # outputs
    starts: wp.array(dtype=wp.int32),
    first: wp.array(dtype=wp.int32),
    high: wp.array(dtype=wp.uint16),
    high_counts: wp.array(dtype=wp.int32),
    offset: int,
):
    """:func:`place_keys`' first pass for run r = tid + offset of the keys, within the run's own
    places ``[r·per_run, (r+1)·per_run)``: its keys sorted by their low digit there (bin b's next free
    place ``starts[r·B + b]``, advanced), so that no two threads write one cache line. For the second
    pass, whose thread q takes the low digits' bins ``owner[b] = q``, it also counts the high digits
    of this run's keys by that thread, into ``high_counts[(r·R + q)·B + digit]`` (R runs; zeroed by
    the caller)."""
    r = wp.tid() + offset
    base = r * _SORT_BINS
    runs = (n + per_run - 1) // per_run
    hbase = r * runs * _SORT_BINS
    end = wp.min(n, (r + 1) * per_run)
    for i in range(r * per_run, end):
        if wp.static(SORT_PREFETCH > 0):
            prefetch_low_place(keys, starts, first, high, base, _SORT_DIGIT_MASK, i + SORT_PREFETCH, end)
        k = int(keys[i])
        b = k & _SORT_DIGIT_MASK
        j = starts[base + b]
        first[j] = i
        h = k >> _SORT_DIGIT
        high[j] = wp.uint16(h)
        starts[base + b] = j + 1
        c = hbase + owner[b] * _SORT_BINS + h
        high_counts[c] = high_counts[c] + 1


@wp.kernel(enable_backward=False)
def place_high_runs(
    # inputs
    first: wp.array(dtype=wp.int32),
    high: wp.array(dtype=wp.uint16),
    runs: int,
    bin_lo: wp.array(dtype=wp.int32),
    seg_lo: wp.array(dtype=wp.int32),
    seg_hi: wp.array(dtype=wp.int32),
    # outputs
    starts: wp.array(dtype=wp.int32),
    order: wp.array(dtype=wp.int32),
    offset: int,
):
    """:func:`place_keys`' second pass for thread q = tid + offset: the low digits' bins
    ``[bin_lo[q], bin_lo[q+1])``, each bin's keys run after run (run r's at places
    ``[seg_lo[r·B + b], seg_hi[r·B + b])`` of the first pass, :func:`place_low_runs`): the keys in
    the order of a one-thread first pass, each placed at the next free place of its high digit's
    bin among thread q's (``starts[q·B + digit]``)."""
    q = wp.tid() + offset
    base = q * _SORT_BINS
    for b in range(bin_lo[q], bin_lo[q + 1]):
        for r in range(runs):
            end = seg_hi[r * _SORT_BINS + b]
            for j in range(seg_lo[r * _SORT_BINS + b], end):
                if wp.static(SORT_PREFETCH > 0):
                    prefetch_high_place(high, starts, order, base, j + SORT_PREFETCH, end)
                c = base + int(high[j])
                p = starts[c]
                order[p] = first[j]
                starts[c] = p + 1


@wp.kernel(enable_backward=False)
def sort_starts_one(
    # inputs
    counts: wp.array(dtype=wp.int32),
    # outputs
    starts: wp.array(dtype=wp.int32),
    offset: int,
):
    """:func:`counting_order` on one thread: where each bin of each digit starts (exclusive prefix
    sums of one run's counts, :func:`count_keys`)."""
    for digit in range(2):
        acc = int(0)
        for b in range(_SORT_BINS):
            starts[digit * _SORT_BINS + b] = acc
            acc += counts[digit * _SORT_BINS + b]


@wp.kernel(enable_backward=False)
def sort_starts_low(
    # inputs
    counts: wp.array(dtype=wp.int32),
    n: int,
    runs: int,
    per_run: int,
    # outputs
    seg: wp.array(dtype=wp.int32),
    starts: wp.array(dtype=wp.int32),
    owner: wp.array(dtype=wp.int32),
    bin_lo: wp.array(dtype=wp.int32),
    high_counts: wp.array(dtype=wp.int32),
    offset: int,
):
    """:func:`counting_order` on several threads, before the first pass (one kernel thread): each
    run's first place of each low bin within its own places (``seg`` and ``starts``, which the pass
    advances); the low bins' shares of the second pass's threads — thread q takes bins
    ``[bin_lo[q], bin_lo[q+1])`` (``owner[b] = q``), whose keys before them number about q·n / runs;
    and ``high_counts`` zeroed."""
    for r in range(runs):
        acc = r * per_run
        for b in range(_SORT_BINS):
            seg[r * _SORT_BINS + b] = acc
            starts[r * _SORT_BINS + b] = acc
            acc += counts[2 * r * _SORT_BINS + b]
    bin_lo[0] = 0
    last = int(0)
    before = wp.int64(0)  # keys in the bins before b
    for b in range(_SORT_BINS):
        q = int(wp.min(wp.int64(runs - 1), before * wp.int64(runs) // wp.int64(n)))
        for k in range(last + 1, q + 1):
            bin_lo[k] = b
        last = wp.max(last, q)
        owner[b] = last
        for r in range(runs):
            before += wp.int64(counts[2 * r * _SORT_BINS + b])
    for k in range(last + 1, runs + 1):
        bin_lo[k] = _SORT_BINS
    for i in range(runs * runs * _SORT_BINS):
        high_counts[i] = 0


@wp.kernel(enable_backward=False)
def sort_starts_high(
    # inputs
    high_counts: wp.array(dtype=wp.int32),
    runs: int,
    # outputs
    starts: wp.array(dtype=wp.int32),
    offset: int,
):
    """:func:`counting_order` on several threads, before the second pass (one kernel thread): where
    thread q's keys of each high digit go, ``starts[q·B + digit]``: after every key of a lower digit,
    and after those of that digit of the threads before q (counted by :func:`place_low_runs`)."""
    acc = int(0)
    for h in range(_SORT_BINS):
        for q in range(runs):
            starts[q * _SORT_BINS + h] = acc
            for r in range(runs):
                acc += high_counts[(r * runs + q) * _SORT_BINS + h]


def counting_order(keys: wp.array, n: int, threads: int | None = None, workspace: Staging | None = None) -> wp.array:
    """The stable ascending order of ``n`` 32-bit ``keys`` (below 2^(2·SORT_DIGIT_BITS)) on the CPU:
    a radix sort of two digits by counting. The threads count contiguous runs of the keys per digit
    and bin (:func:`count_keys`), a one-thread kernel sums the runs' counts into each bin's first
    place (:func:`sort_starts_one`, :func:`sort_starts_low`, :func:`sort_starts_high`), and one
    thread places the keys by the low digit, then by the high one (:func:`place_keys`). On several
    threads each run of keys is sorted by its low digit within its own places
    (:func:`place_low_runs`), then each thread takes a share of the low digits' bins and places their
    keys, run after run, by the high digit (:func:`place_high_runs`: the order a one-thread first
    pass gives, so the same result). The same order as ``np.argsort(keys, kind="stable")`` (tests).
    On one thread it takes about half the time of numpy's radix sort of the same keys. Each run's
    keys are placed within the run's own places so that two threads' writes do not meet at every
    bin's border and share the cache lines of the 2-byte high digits (placed at the run's places in
    every global bin, the first pass on two threads took as long as the one-thread sort's two
    passes). Split by spans of bins instead (each thread reading every key and placing its own) it
    is no faster than one thread; three digits of 9-10 bits are slower (docs/kdtree.md)."""
    runs = max(1, min(threads or cpu_threads(), n // SORT_MIN_KEYS_PER_THREAD))
    per_run = -(-n // runs)
    bins = 1 << SORT_DIGIT_BITS
    counts = workspace_buffer(workspace, "sort_counts", runs * 2 * bins, wp.int32, "cpu")
    launch(count_keys, runs, [keys, n, per_run, counts], device="cpu", threads=runs, min_items=1)
    first = workspace_buffer(workspace, "sort_first", n, wp.int32, "cpu")
    high = workspace_buffer(workspace, "sort_high", n, wp.uint16, "cpu")
    order = workspace_buffer(workspace, "order", n, wp.int32, "cpu")
    starts = workspace_buffer(workspace, "sort_starts", max(runs, 2) * bins, wp.int32, "cpu")  # one run: both digits
    if runs == 1:
        wp.launch(sort_starts_one, 1, [counts, starts, 0], device="cpu")
        wp.launch(place_keys, 1, [keys, n, starts, first, high, order, 0], device="cpu")
        return order
    # several runs: each sorts its own keys by the low digit within its own places, then thread q
    # places the keys of its share of the low digits' bins, run after run, by the high digit; the
    # prefix sums between the passes are one-thread kernels (numpy's took ~0.6 ms per step with
    # its array views, all of it time the other thread waits)
    seg = workspace_buffer(workspace, "sort_seg", runs * bins, wp.int32, "cpu")
    owner = workspace_buffer(workspace, "sort_owner", bins, wp.int32, "cpu")
    bin_lo = workspace_buffer(workspace, "sort_bin_lo", runs + 1, wp.int32, "cpu")
    hc = workspace_buffer(workspace, "sort_high_counts", runs * runs * bins, wp.int32, "cpu")
    wp.launch(sort_starts_low, 1, [counts, n, runs, per_run, seg, starts, owner, bin_lo, hc, 0], device="cpu")
    launch(place_low_runs, runs, [keys, n, per_run, owner, starts, first, high, hc], device="cpu", threads=runs,
           min_items=1)
    starts2 = workspace_buffer(workspace, "sort_starts2", runs * bins, wp.int32, "cpu")
    wp.launch(sort_starts_high, 1, [hc, runs, starts2, 0], device="cpu")
    launch(place_high_runs, runs, [first, high, runs, bin_lo, seg, starts, starts2, order], device="cpu",
           threads=runs, min_items=1)
    return order


@wp.kernel(enable_backward=False)
def move_in_order(
    # inputs
    order: wp.array(dtype=wp.int32),
    src: wp.uint64,
    size: int,
    scatter: int,
    # outputs
    dst: wp.uint64,
    offset: int,
):
    """:func:`gather_in_order`'s and :func:`scatter_in_order`'s pass on the CPU, ``REORDER_BLOCK`` rays
    per kernel thread, each ray's line prefetched ``GATHER_PREFETCH`` (``SCATTER_PREFETCH``, for
    writing) rays ahead (:func:`move_range`)."""
    first = (wp.tid() + offset) * REORDER_BLOCK
    move_range(order, src, dst, size, scatter, first, wp.min(REORDER_BLOCK, order.shape[0] - first))


@wp.kernel(enable_backward=False)
def scatter_hits(
    # inputs
    order: wp.array(dtype=wp.int32),
    t: wp.array(dtype=float),
    prim: wp.array(dtype=wp.int32),
    u: wp.array(dtype=float),
    v: wp.array(dtype=float),
    # outputs
    records: wp.array(dtype=wp.vec4),
    offset: int,
):
    """The closest-hit query's four results, traced in the order of :func:`ray_order`, back at their
    rays' own indices in one 16-byte record per ray (t, prim's bits, u, v; :func:`hit_outputs`),
    ``REORDER_BLOCK`` rays per kernel thread, each record's line prefetched for writing
    ``SCATTER_PREFETCH`` rays ahead (CPU only)."""
    first = (wp.tid() + offset) * REORDER_BLOCK
    scatter_hits_range(order, t, prim, u, v, records, first, wp.min(REORDER_BLOCK, order.shape[0] - first))

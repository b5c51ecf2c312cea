"""Ray reordering (docs/kdtree.md, "Ray reordering"): whether a batch is coherent, the order in which
to trace it (its rays sorted by :func:`~serenity.kernels.kdtree.keys.ray_sort_key`, stable), and the
passes that put per-ray arrays into that order and the results back into the caller's.

Each step has one form per device: on the CPU the keys of 16 rays per kernel thread, the counting
sort and the prefetching gather and scatter of ``cpu/sort``; on CUDA the one-ray key kernel, Warp's
radix sort of the keys with the rays' indices (``wp.utils.radix_sort_pairs``, stable, on the
device) and one element per kernel thread. Both give the same order: the stable ascending order of
the keys.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from serenity.kernels.launch import Staging, launch

from .cpu.sort import KEY_LANES, REORDER_BLOCK, counting_order, move_in_order, sort_keys_simd
from .keys import SORT_MIN_RAYS, SORT_MIN_RUN, SORT_SAMPLE_PAIRS, sample_key_changes, sort_keys, sort_scale
from .layout import TRACE_MODULE_OPTIONS, buffers_like, is_cpu, workspace_buffer

wp.set_module_options(TRACE_MODULE_OPTIONS)


@wp.kernel(enable_backward=False)
def gather_array(
    # inputs
    order: wp.array(dtype=wp.int32),
    src: wp.array(dtype=Any),
    # outputs
    dst: wp.array(dtype=Any),
    offset: int,
):
    """``dst[i] = src[order[i]]``: a per-ray array in the traced order (:func:`gather_in_order`;
    compiled for the ray input types in ``GATHER_DTYPES``)."""
    i = wp.tid() + offset
    dst[i] = src[order[i]]


#: the per-ray input types :func:`gather_array` is compiled for (origins, directions, tmax, cones)
GATHER_DTYPES = (wp.vec3, wp.float32)
for _dtype in GATHER_DTYPES:
    wp.overload(gather_array, {"src": wp.array(dtype=_dtype), "dst": wp.array(dtype=_dtype)})


@wp.kernel(enable_backward=False)
def scatter_array(
    # inputs
    order: wp.array(dtype=wp.int32),
    src: wp.array(dtype=Any),
    # outputs
    dst: wp.array(dtype=Any),
    offset: int,
):
    """``dst[order[i]] = src[i]``: a per-ray result traced in the order of :func:`ray_order` back in
    the caller's (:func:`scatter_in_order`; compiled for the result types in ``SCATTER_DTYPES``)."""
    i = wp.tid() + offset
    dst[order[i]] = src[i]


#: the per-ray result types :func:`scatter_array` is compiled for (hits, flags, ray-traced G-buffers)
SCATTER_DTYPES = (wp.int32, wp.float32, wp.vec4)
for _dtype in SCATTER_DTYPES:
    wp.overload(scatter_array, {"src": wp.array(dtype=_dtype), "dst": wp.array(dtype=_dtype)})


@wp.kernel(enable_backward=False)
def ray_indices(
    # outputs
    indices: wp.array(dtype=wp.int32),
    offset: int,
):
    """``indices[i] = i``: the values the radix sort carries with the keys (CUDA's :func:`ray_order`)."""
    i = wp.tid() + offset
    indices[i] = i


def ray_order(box_lo: wp.vec3, box_hi: wp.vec3, origins: wp.array, directions: wp.array, n: int, sort: bool | None,
              device: str, threads: int | None = None, workspace: Staging | None = None) -> wp.array:
    """The order in which to trace ``n`` rays: their indices sorted by their keys (stable: ties keep
    the caller's order), or an empty array = as they come. ``sort=None`` sorts batches of
    ≥ ``SORT_MIN_RAYS`` that are not coherent already (:func:`batch_is_coherent`: camera rays,
    reflections of a smooth surface in pixel order are left as they are), before any key per ray
    is made; ``True`` always, ``False`` never. On the CPU the keys are made 16 rays per kernel
    thread (``cpu.sort.sort_keys_simd``, over all cores) and sorted by a counting sort
    (``cpu.sort.counting_order``); on CUDA one ray per kernel thread and sorted by Warp's radix sort
    with the rays' indices, on the device. ``workspace``: where the keys and the order go (grow-only
    buffers, :meth:`KdTree.workspace`), else new arrays."""
    if (sort is False) or n < 2 or (sort is None and n < SORT_MIN_RAYS):
        return wp.empty(0, dtype=wp.int32, device=device)
    if sort is None and batch_is_coherent(box_lo, box_hi, origins, directions, n, device, threads):
        return wp.empty(0, dtype=wp.int32, device=device)
    scale = sort_scale(box_lo, box_hi)
    if is_cpu(device):
        keys = workspace_buffer(workspace, "keys", n, wp.uint32, device)
        simd = 0
        if origins.is_contiguous and directions.is_contiguous:
            simd = n // KEY_LANES
            launch(sort_keys_simd, simd, [box_lo, scale, origins, directions, keys], device=device, threads=threads)
        launch(sort_keys, n - simd * KEY_LANES, [box_lo, scale, origins, directions, keys], device=device,
               threads=threads, start=simd * KEY_LANES)
        return counting_order(keys, n, threads, workspace)
    # the radix sort takes twice n of each (its second halves are its working space); the keys are below
    # 2^SORT_KEY_BITS < 2^31, so they sort as int32 in the order of their uint32 values
    keys = workspace_buffer(workspace, "keys_pairs", 2 * n, wp.int32, device)
    order = workspace_buffer(workspace, "order_pairs", 2 * n, wp.int32, device)
    launch(sort_keys, n, [box_lo, scale, origins, directions, keys.view(wp.uint32)], device=device)
    launch(ray_indices, n, [order], device=device)
    wp.utils.radix_sort_pairs(keys, order, n)
    return order[:n]


def batch_is_coherent(box_lo: wp.vec3, box_hi: wp.vec3, origins: wp.array, directions: wp.array, n: int,
                      device: str, threads: int | None = None) -> bool:
    """Are ``n`` rays (n ≥ 2) already in a coherent order? True when the keys without their low bits
    (``SORT_SAMPLE_SHIFT``) change, on ``SORT_SAMPLE_PAIRS`` evenly spaced pairs of consecutive rays,
    less often than every ``SORT_MIN_RUN`` rays (camera rays, reflections of a smooth surface in pixel
    order): such a batch is not reordered (:func:`ray_order`) and is traced in packets on the CPU
    (``query``)."""
    m = min(SORT_SAMPLE_PAIRS, n - 1)
    changes = wp.empty(m, dtype=wp.int32, device=device)
    launch(sample_key_changes, m, [box_lo, sort_scale(box_lo, box_hi), origins, directions, (n - 1) // m, changes],
           device=device, threads=threads)
    return int(np.count_nonzero(changes.numpy())) * SORT_MIN_RUN < m


def gather_in_order(order: wp.array, arrays: list, device: str, threads: int | None = None,
                    workspace: Staging | None = None) -> list:
    """Per-ray arrays (vec3 or float) in the traced order of :func:`ray_order`: ``out[i] = a[order[i]]``
    (a separate pass: a random read per ray inside the traversal costs more). ``workspace``: the
    outputs are its grow-only buffers (:func:`buffers_like`), else new arrays."""
    out = buffers_like(arrays, "gather", device, workspace)
    for a, b in zip(arrays, out, strict=True):
        _move(order, a, b, False, device, threads)
    return out


def scatter_in_order(order: wp.array, arrays: list, outs: list, device: str, threads: int | None = None) -> None:
    """The inverse of :func:`gather_in_order`: ``out[order[i]] = a[i]`` for each pair, results traced
    in the reordered order written back at their rays' own indices (a pass of its own: random stores
    from inside the traversal compete with its loads). Empty arrays are skipped."""
    for a, b in zip(arrays, outs, strict=True):
        if a.shape[0]:
            _move(order, a, b, True, device, threads)


def _move(order: wp.array, src: wp.array, dst: wp.array, scatter: bool, device: str, threads: int | None) -> None:
    """One array's pass of :func:`gather_in_order` (``scatter`` False) or :func:`scatter_in_order`:
    on the CPU the prefetching loops of ``cpu.sort.move_in_order`` (contiguous arrays), else one
    element per kernel thread (:func:`gather_array`, :func:`scatter_array`)."""
    n = order.shape[0]
    if is_cpu(device) and src.is_contiguous and dst.is_contiguous:
        size = wp.types.type_size_in_bytes(src.dtype)
        launch(move_in_order, -(-n // REORDER_BLOCK), [order, src.ptr, size, int(scatter), dst.ptr], device=device,
               threads=threads, min_items=1)
    else:
        launch(scatter_array if scatter else gather_array, n, [order, src, dst], device=device, threads=threads)

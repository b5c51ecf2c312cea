"""Ray reordering keys (docs/kdtree.md, "Ray reordering"): a ray's ``SORT_KEY_BITS``-bit key
(:func:`ray_sort_key`), so that rays in the order of their keys walk the same nodes and triangles,
and the kernels that make the keys of a batch and sample them to tell whether a batch is already
coherent. The keys' order is found in ``reorder`` (a radix sort on CUDA, ``cpu/sort``'s counting
sort on the CPU).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import warp as wp

from .layout import FLT_MAX_W, TRACE_MODULE_OPTIONS
from .native import native_body

wp.set_module_options(TRACE_MODULE_OPTIONS)

HEADER = Path(__file__).with_name("keys.h")

#: ray reordering (``sort=None`` in the queries): batches of at least this many rays are traced in
#: the order of a ``SORT_KEY_BITS``-bit key (:func:`ray_sort_key`): the Morton code of the origin's cell on a
#: ``SORT_COARSE_BITS``-bit grid per axis over the root box, the direction's octant, the origin's
#: cell on the finer ``SORT_ORIGIN_BITS``-bit grid within the coarse cell, then the direction's cell
#: on a ``SORT_DIRECTION_BITS``-bit grid per coordinate of the octant's octahedral map, so that
#: consecutive rays walk the same nodes and triangles (docs/kdtree.md, "Ray reordering")
SORT_MIN_RAYS = 1 << 15
SORT_MIN_RUN = 4  # ... whose keys change on average more often than every this many rays (``ray_order``)
#: ... estimated from this many evenly spaced pairs of consecutive rays (a coherent batch is then
#: traced without a key per ray: 3 % of a camera batch's time)
SORT_SAMPLE_PAIRS = 4096
SORT_COARSE_BITS = 3
SORT_ORIGIN_BITS = 5
SORT_DIRECTION_BITS = 5
#: the key's bits, sorted on the CPU as two digits of ``SORT_DIGIT_BITS`` (``cpu.sort.counting_order``)
SORT_KEY_BITS = 3 * SORT_ORIGIN_BITS + 3 + 2 * SORT_DIRECTION_BITS
SORT_DIGIT_BITS = 14
assert SORT_KEY_BITS <= 2 * SORT_DIGIT_BITS and SORT_KEY_BITS < 32 and SORT_COARSE_BITS <= SORT_ORIGIN_BITS
assert SORT_ORIGIN_BITS <= 5 and SORT_DIRECTION_BITS <= 5  # the Morton spreads (``spread.h``)
#: :func:`batch_is_coherent` compares keys without their low bits: the origin's fine cell and the
#: octant stay, the direction's cell only to its 2 top bits per coordinate (a camera's neighbouring
#: pixels share it)
SORT_SAMPLE_SHIFT = 2 * (SORT_DIRECTION_BITS - 2)
#: the bits of the origin's fine cell within its coarse one (3 per axis)
SORT_FINE_BITS = 3 * (SORT_ORIGIN_BITS - SORT_COARSE_BITS)

_SORT_CELLS = wp.constant(float(1 << SORT_ORIGIN_BITS))
_SORT_FINE = wp.constant(SORT_FINE_BITS)
_SORT_DIR_CELLS = wp.constant(float(1 << SORT_DIRECTION_BITS))
_SORT_SAMPLE_SHIFT = wp.constant(SORT_SAMPLE_SHIFT)

#: the C natives' constants (``keys.h``)
KEY_MASKS = {"ORIGIN_MASK": (1 << SORT_ORIGIN_BITS) - 1, "DIRECTION_MASK": (1 << SORT_DIRECTION_BITS) - 1}


@wp.func
def origin_cell(o: float, lo: float, scale: float) -> int:
    """The cell of coordinate ``o`` on the sort grid of one axis, ``scale`` = cells / the box's extent
    (outside the box, or NaN: the border cell)."""
    f = (o - lo) * scale
    f = wp.where(f >= 0.0, f, 0.0)
    return int(wp.min(f, _SORT_CELLS - 1.0))


@wp.func_native(native_body(HEADER, "spread_bits", defines=KEY_MASKS))
def spread_bits(q: int) -> int:
    """Bit b of ``q`` (b < SORT_ORIGIN_BITS) moved to bit 3b: one axis' share of a Morton code."""
    ...


@wp.func_native(native_body(HEADER, "spread_bits2", defines=KEY_MASKS))
def spread_bits2(q: int) -> int:
    """Bit b of ``q`` (b < SORT_DIRECTION_BITS) moved to bit 2b: one coordinate's share of a 2-D
    Morton code."""
    ...


@wp.func
def ray_sort_key(box_lo: wp.vec3, scale: wp.vec3, o: wp.vec3, d: wp.vec3) -> int:
    """The reordering key of a ray (``SORT_KEY_BITS`` bits, high to low): the Morton code of its
    origin's cell on a 2^SORT_COARSE_BITS grid per axis over the root box, its direction's octant,
    the Morton code of its origin's cell on the 2^SORT_ORIGIN_BITS grid within that coarse cell
    (``scale`` = fine cells / the box's extent per axis, :func:`sort_scale`; origins outside the box,
    or NaN, clamp to the border cells), then the Morton code of the direction's cell on a
    2^SORT_DIRECTION_BITS grid per coordinate of the octahedral map of its octant
    (|d| / (|dx| + |dy| + |dz|), x and y). So rays of
    one coarse cell heading into one octant are together, and within them rays from nearby points
    in nearby directions: 16 neighbours in the order make a packet whose lanes share nodes
    (docs/kdtree.md, "Ray reordering"). Straight-line code: loops over the axes with a run-time
    index take about twice as long."""
    origin = (spread_bits(origin_cell(o[0], box_lo[0], scale[0]))
              | (spread_bits(origin_cell(o[1], box_lo[1], scale[1])) << 1)
              | (spread_bits(origin_cell(o[2], box_lo[2], scale[2])) << 2))
    ax = wp.abs(d[0])
    ay = wp.abs(d[1])
    octant = wp.where(d[0] < 0.0, 1, 0) | wp.where(d[1] < 0.0, 2, 0) | wp.where(d[2] < 0.0, 4, 0)
    l1 = ax + ay + wp.abs(d[2])
    # zero, NaN or infinite (a miss anyway): cell 0
    s = wp.where((wp.where(l1 > 0.0, 1, 0) & wp.where(l1 <= FLT_MAX_W, 1, 0)) != 0, _SORT_DIR_CELLS / l1, 0.0)
    qu = int(wp.min(wp.where(s > 0.0, ax * s, 0.0), _SORT_DIR_CELLS - 1.0))
    qv = int(wp.min(wp.where(s > 0.0, ay * s, 0.0), _SORT_DIR_CELLS - 1.0))
    direction = spread_bits2(qu) | (spread_bits2(qv) << 1)
    coarse = origin >> _SORT_FINE
    fine = origin & ((1 << _SORT_FINE) - 1)
    return (((((coarse << 3) | octant) << _SORT_FINE) | fine) << wp.static(2 * SORT_DIRECTION_BITS)) | direction


def sort_scale(box_lo: wp.vec3, box_hi: wp.vec3) -> wp.vec3:
    """:func:`ray_sort_key`'s ``scale``: the sort grid's cells per unit length on each axis (float32,
    as the kernels compute)."""
    lo = np.array(box_lo, np.float32)
    hi = np.array(box_hi, np.float32)
    return wp.vec3(*(np.float32(1 << SORT_ORIGIN_BITS) / (hi - lo)).tolist())


@wp.kernel(enable_backward=False)
def sort_keys(
    # inputs
    box_lo: wp.vec3,
    scale: wp.vec3,
    origins: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    # outputs
    keys: wp.array(dtype=wp.uint32),
    offset: int,
):
    i = wp.tid() + offset
    keys[i] = wp.uint32(ray_sort_key(box_lo, scale, origins[i], directions[i]))


@wp.kernel(enable_backward=False)
def sample_key_changes(
    # inputs
    box_lo: wp.vec3,
    scale: wp.vec3,
    origins: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    stride: int,
    # outputs
    changes: wp.array(dtype=wp.int32),
    offset: int,
):
    """Whether the sort key changes between rays ``a`` and ``a + 1``, ``a = (tid + offset) · stride``:
    a sample of consecutive pairs, from which :func:`ray_order` estimates how coherent a batch is."""
    j = wp.tid() + offset
    a = j * stride
    ka = ray_sort_key(box_lo, scale, origins[a], directions[a]) >> _SORT_SAMPLE_SHIFT
    kb = ray_sort_key(box_lo, scale, origins[a + 1], directions[a + 1]) >> _SORT_SAMPLE_SHIFT
    changes[j] = wp.where(ka != kb, 1, 0)

"""The kd-tree on a device: its node and leaf records (:class:`KdTreeData`, made by :func:`tree_data`
from the build's arrays), the traversal's loads from them, the constants every part of the package
shares, and the queries' workspace buffers.

Layout (``nodes`` and ``refs`` contiguous, as the loads in ``layout.h`` assume):
    nodes (nodes,) KdNode, 8 bytes: inner node: ``head`` = (first child << 4) | (right child is an
        empty leaf) << 3 | (left child is an empty leaf) << 2 | axis (children are consecutive: left
        at first child, right at first child + 1), ``split`` = the split position (world units);
        leaf: ``head`` = (its block's first word in ``refs`` << 2) | 3, ``split`` = its triangle count.
    refs (W,) float32: one block of 10·k words per non-empty leaf of k triangles: the triangles'
        vertex coordinates (the k x of v0, the k y of v0, …, the k z of v2), then their indices (as
        int32 bits), 40 bytes per reference; padded by ``REF_PAD`` words.
    tri_verts (3F,) vec3: the three vertices of triangle f at 3f, 3f+1, 3f+2 (for shading a hit).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import warp as wp

from serenity.config import KD_MAX_DEPTH
from serenity.errors import SerenityError
from serenity.kernels.launch import Staging

from .native import native_body

#: Kernels that trace (in this package and in ``raytrace``) are compiled without floating-point
#: contraction (``fuse_fp``): NVRTC fuses a multiply and an add into one FMA across statements, which
#: moved the sheared vertex coordinates of Woop's test by an ulp and let 1-2 % of rays aimed at the
#: vertices and edges of closed meshes through on an NVIDIA H200 (0 with contraction off); unfused,
#: CUDA's hits are bit-identical to the CPU's (``tests/kernels/test_kdtree.py``).
TRACE_MODULE_OPTIONS = {"enable_backward": False, "fuse_fp": False}
wp.set_module_options(TRACE_MODULE_OPTIONS)

HEADER = Path(__file__).with_name("layout.h")

# ----------------------------------------------------------------------------------------------
# constants
# ----------------------------------------------------------------------------------------------

#: traversal stack entries: the stack holds at most one entry per level of the tree (the far children
#: of the current node's ancestors), so a tree of depth <= KD_MAX_DEPTH never overflows it and the
#: traversal does not test for that (:func:`tree_data` refuses a deeper tree)
STACK_SIZE = KD_MAX_DEPTH + 2
#: words of padding after the last leaf block (``refs``): SIMD leaf tests load 8 or 16 words at a time
REF_PAD = 16
#: a ray goes on through at most this many cut-out hits the alpha test rejects (``KdTree.set_alpha_test``)
MAX_CUTOUT_LAYERS = 64
T_TOLERANCE = 1e-6  # relative (to the scene scale) overlap of near/far traversal intervals
BOX_PADDING = 1e-5  # the root box is padded by this fraction of its largest extent
TINY_DIRECTION = 1e-30  # a direction whose largest |component| is below this is a miss
#: float32's largest finite value: :func:`finite`'s bound, and the SIMD natives' (``FLT_MAX_F``)
FLT_MAX = float(np.finfo(np.float32).max)
assert STACK_SIZE & (STACK_SIZE - 1) == 0  # a power of 2: the stack index is masked (``STACK_MASK``)
STACK_MASK = wp.constant(STACK_SIZE - 1)
stack_i = wp.types.vector(length=STACK_SIZE, dtype=wp.int32)
stack_f = wp.types.vector(length=STACK_SIZE, dtype=wp.float32)

INF = wp.constant(math.inf)
TOL = wp.constant(T_TOLERANCE)
TINY = wp.constant(TINY_DIRECTION)
FLT_MAX_W = wp.constant(FLT_MAX)


# ----------------------------------------------------------------------------------------------
# structs
# ----------------------------------------------------------------------------------------------


@wp.struct
class KdNode:
    """One node, 8 bytes: ``head`` = (first child << 4) | empty-children flags << 2 | axis, or
    (first reference << 2) | 3 for a leaf; ``split`` = the split position of an inner node, the
    triangle count of a leaf (module docstring)."""

    head: wp.int32
    split: wp.float32


@wp.struct
class KdTreeData:
    """The tree on one device (module docstring)."""

    nodes: wp.array(dtype=KdNode)
    refs: wp.array(dtype=wp.float32)
    tri_verts: wp.array(dtype=wp.vec3)
    box_lo: wp.vec3  # padded root box
    box_hi: wp.vec3
    scale: float  # largest |coordinate| of the root box, for the t tolerance


# ----------------------------------------------------------------------------------------------
# functions
# ----------------------------------------------------------------------------------------------


@wp.func_native(native_body(HEADER, "node_head"))
def node_head(nodes: wp.array(dtype=KdNode), i: int) -> int:
    """``nodes[i].head`` (``layout.h``: no stride multiply, no index wrap; ``i`` in range)."""
    ...


@wp.func_native(native_body(HEADER, "node_split"))
def node_split(nodes: wp.array(dtype=KdNode), i: int) -> float:
    """``nodes[i].split`` (as :func:`node_head`)."""
    ...


@wp.func_native(native_body(HEADER, "ref_vertex"))
def ref_vertex(refs: wp.array(dtype=float), i: int, k: int) -> wp.vec3:
    """A vertex of a leaf's block (module docstring, ``refs``): its x at word ``i``, y and z ``k``
    and ``2k`` words on (``k`` = the leaf's triangle count)."""
    ...


@wp.func_native(native_body(HEADER, "ref_prim"))
def ref_prim(refs: wp.array(dtype=float), i: int) -> int:
    """The triangle index stored (as its bits) at word ``i`` of a leaf's block."""
    ...


@wp.func
def finite(x: float) -> bool:
    """``wp.isfinite`` for float32, inline: false for ±inf and NaN (every comparison with NaN is
    false). Warp's CPU ``isfinite`` is a call into its runtime, ~10 per ray in ``start_ray``."""
    return wp.abs(x) <= FLT_MAX_W


# ----------------------------------------------------------------------------------------------
# host
# ----------------------------------------------------------------------------------------------


def tree_data(vertices: np.ndarray, faces: np.ndarray, node_head: np.ndarray, node_split: np.ndarray,
              prims: np.ndarray, box: np.ndarray, depth: int, device: str) -> KdTreeData:
    """The build's arrays (``serenity.kernels.kdtree_build``) as :class:`KdTreeData` on ``device``:
    the 8-byte nodes with their children's empty flags, each non-empty leaf's block of vertex
    coordinates and indices, the padded root box. A tree too big for the node's bit fields or
    deeper than the traversal stack raises :class:`SerenityError`."""
    data = KdTreeData()
    head = node_head
    leaf = (head & 3) == 3
    off = head >> 2
    count = np.where(leaf, prims[np.where(leaf, off, 0)], 0)  # the empty leaf's block: prims[0] = 0
    nodes = np.zeros(len(head), dtype=KdNode.numpy_dtype())
    child = np.where(leaf, 0, off)
    empty = leaf & (count == 0)
    if len(head) >= 1 << 27:
        raise SerenityError(f"kd-tree of {len(head):,} nodes: at most 2^27 fit the 8-byte node")
    if depth >= STACK_SIZE:
        raise SerenityError(f"kd-tree of depth {depth}: the traversal stack has {STACK_SIZE} slots")
    right = np.minimum(child + 1, len(head) - 1)
    flags = (empty[child].astype(np.int64) << 2) | (empty[right].astype(np.int64) << 3)
    tri = np.ascontiguousarray(vertices[faces], np.float32)  # (F, 3, 3)
    # each non-empty leaf's block of 10 k words: its k triangles' 9 vertex coordinates, one
    # coordinate after the other (x of v0 for all k, y of v0, ...), then their indices
    full = np.flatnonzero(leaf & (count > 0))
    k = count[full].astype(np.int64)
    block = np.concatenate([[0], np.cumsum(10 * k)]).astype(np.int64)
    if block[-1] >= 1 << 29:
        raise SerenityError(f"kd-tree of {block[-1]:,} leaf words: at most 2^29 fit the 8-byte node")
    leaf_word = np.zeros(len(head), np.int64)
    leaf_word[full] = block[:-1]
    nodes["head"] = np.where(leaf, (leaf_word << 2) | 3, (child << 4) | flags | (head & 3))
    nodes["split"] = np.where(leaf, count, node_split).astype(np.float32)
    data.nodes = wp.array(nodes, dtype=KdNode, device=device)
    j = np.arange(k.sum()) - np.repeat(block[:-1] // 10, k)  # the triangle's place in its leaf
    tri_ids = prims[np.repeat(off[full] + 1, k) + j]
    at = np.repeat(block[:-1], k) + j
    kk = np.repeat(k, k)
    words = np.zeros(block[-1] + REF_PAD, np.float32)  # padded: SIMD loads may read past a leaf
    coords = tri[tri_ids].reshape(-1, 9)
    for c in range(9):
        words[at + c * kk] = coords[:, c]
    words.view(np.int32)[at + 9 * kk] = tri_ids
    data.refs = wp.array(words, dtype=wp.float32, device=device)
    data.tri_verts = wp.array(tri.reshape(-1, 3), dtype=wp.vec3, device=device)
    lo = box[0].astype(np.float64)
    hi = box[1].astype(np.float64)
    pad = BOX_PADDING * float(np.max(hi - lo)) + 1e-30
    data.box_lo = wp.vec3(*(lo - pad).tolist())
    data.box_hi = wp.vec3(*(hi + pad).tolist())
    data.scale = float(np.max(np.abs(np.concatenate([lo - pad, hi + pad]))))
    return data


def is_cpu(device: str) -> bool:
    """Whether ``device`` (a resolved name: ``cpu``, ``cuda:0``, ...) is the CPU."""
    return str(device).startswith("cpu")


def workspace_buffer(workspace: Staging | None, name: str, n: int, dtype, device: str) -> wp.array:
    """``n`` elements of ``dtype``: ``workspace``'s grow-only buffer ``name`` (valid until its next use;
    :meth:`KdTree.workspace`), or a new array without one."""
    return wp.empty(n, dtype=dtype, device=device) if workspace is None else workspace.buffer(name, n, dtype)


def buffers_like(arrays: list, prefix: str, device: str, workspace: Staging | None = None) -> list:
    """An array of the shape and dtype of each of ``arrays`` (:func:`workspace_buffer`: ``workspace``'s
    buffers ``prefix``0, ``prefix``1, ..., or new ones)."""
    return [workspace_buffer(workspace, f"{prefix}{k}", a.shape[0], a.dtype, device) for k, a in enumerate(arrays)]

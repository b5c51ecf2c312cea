"""SAH kd-tree build over a triangle mesh: binned SAH, one tree level at a time (paper §9).

The paper's CPU ray tracer follows Wald's thesis ("Realtime Ray Tracing and Interactive Global
Illumination", 2004): a kd-tree whose split planes minimise the surface area heuristic (SAH).
Traversal lives in :mod:`serenity.kernels.kdtree`; this module makes the arrays it walks.

Build — *binned SAH, level by level* (not Wald & Havran 2006's sorted event sweep, whose per-node
event lists are millions of interpreter-level steps in Python). Every level holds its nodes'
triangle references sorted by node, so each node owns a contiguous range. Per level, three Warp
kernels (:mod:`serenity.kernels.kdtree_build_kernels`) run with one thread per node (split over
the CPU cores by :func:`serenity.kernels.launch.launch`; a node writes only its own outputs and its
own reference range, so the result does not depend on the thread count):
    1. ``node_splits``: the node's tight geometry bounds, per axis a histogram of its references'
       min and max bins, and the SAH cost of every bin plane and of the tight bounds;
    2. ``clip_refs``: for a split node, each reference's side(s), the clipped boxes of the
       straddling ones, and the children's reference counts;
    3. ``scatter_refs``: the children's references written at their prefix-sum offsets.
numpy does the O(nodes) glue (prefix sums, child cells, leaf blocks). Each level is O(R) for its R
references and there are O(log N) levels: O(N log N). The price of binning is that split candidates
are the ``bins − 1`` equally spaced planes over each node's geometry bounds (plus those bounds),
not every triangle boundary — a slightly worse tree than an exact sweep.
Details:
- Cost = C_trav + C_isect·(SA_L·N_L + SA_R·N_R)/SA, with the *empty-space bonus*: a split with an
  empty side costs (1 − ``empty_bonus``) of that. The node's tight geometry bounds are always
  candidates, so empty space around geometry is cut off first (Wald thesis §7.3; Havran).
  A node becomes a leaf when no split is cheaper than C_isect·N or at the depth limit.
- Triangles that straddle a split are *clipped* to each side ("split clipping"): the bounding box
  of the triangle ∩ half-space, computed in float64 and rounded outwards to float32, intersected
  with the reference's previous box and the child's cell. Conservative, so no triangle is ever
  missing from a cell it overlaps.
- Triangles with a non-finite vertex or zero area (exactly, in float64) are left out: never hit.
- Built trees are cached on disk (``.npz``, no pickle) keyed by a hash of the vertices, faces and
  build settings (:class:`serenity.config.KdBuildConfig`), in ``$SERENITY_CACHE`` or
  ``~/.cache/serenity`` (``kdtree-<hash>.npz``). Builds of more than ``PROGRESS_MIN_TRIANGLES``
  triangles show a tqdm progress bar (one step per level).

Layout (numpy):
    node_head (nodes,) int32: inner = (first child << 2) | axis (children are consecutive: left at
        first child, right at first child + 1); leaf = (offset into ``prims`` << 2) | 3.
        Nodes are stored depth first, each pair of children followed by the left child's subtree.
    node_split (nodes,) float32: the split position of an inner node (world units).
    prims (P,) int32: per leaf a count then that many triangle indices; ``prims[0] = 0`` is the
        shared empty leaf.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import warp as wp
from tqdm import tqdm

from serenity.config import KdBuildConfig
from serenity.device import init_warp
from serenity.errors import SerenityError
from serenity.kernels.kdtree_build_kernels import clip_refs, emit_leaves, node_splits, scatter_refs, triangle_boxes
from serenity.kernels.launch import launch

FORMAT_VERSION = 2  # bump when the build or the cached layout changes
CACHE_MIN_TRIANGLES = 10_000  # cache=None caches builds of at least this many triangles
PROGRESS_MIN_TRIANGLES = 200_000  # progress=None shows a bar from this many triangles


@dataclass
class KdStats:
    """What a build made: triangle counts, node counts, references in leaves, depth and seconds."""

    triangles: int
    valid_triangles: int
    nodes: int
    leaves: int
    empty_leaves: int
    references: int
    depth: int
    build_seconds: float
    from_cache: bool = False


# ----------------------------------------------------------------------------------------------
# host: the level loop
# ----------------------------------------------------------------------------------------------


class _Workspace:
    """Warp arrays on the CPU reused from level to level (fresh memory costs page faults): ``get``
    returns the first n elements of a buffer of at least n, grown by half when too small."""

    def __init__(self, wp_):
        self.wp = wp_
        self.arrays: dict[str, object] = {}

    def get(self, name: str, n: int, dtype):
        arr = self.arrays.get(name)
        n = max(int(n), 1)
        if arr is None or arr.shape[0] < n:
            arr = self.wp.empty(n + n // 2, dtype=dtype, device="cpu")
            self.arrays[name] = arr
        return arr[:n]

    def put(self, name: str, values: np.ndarray, dtype):
        arr = self.get(name, len(values), dtype)
        if len(values):
            arr.numpy()[:len(values)] = values
        return arr


def build_arrays(vertices: np.ndarray, faces: np.ndarray, cfg: KdBuildConfig, progress: bool,
                 threads: int | None = None) -> dict:
    """The binned, level-by-level SAH build of ``vertices`` (V,3) float32 and ``faces`` (F,3) int32
    (validated). Returns ``node_head``, ``node_split``, ``prims``, ``box`` (2,3) (the geometry's
    bounds) and ``stats`` (a dict of :class:`KdStats` fields without times). ``threads``: CPU
    threads of the per-node kernels (None: all)."""
    wp_ = init_warp()
    dev = "cpu"

    def run(kernel, dim: int, inputs: list) -> None:
        launch(kernel, dim, inputs, device=dev, threads=threads, balanced=True)

    w_verts = wp_.array(vertices, dtype=wp.vec3, device=dev)
    w_faces = wp_.array(faces, dtype=wp.vec3i, device=dev)
    nf = len(faces)
    valid_w = wp_.empty(nf, dtype=wp.int32, device=dev)
    lo_w = wp_.empty(nf, dtype=wp.vec3, device=dev)
    hi_w = wp_.empty(nf, dtype=wp.vec3, device=dev)
    run(triangle_boxes, nf, [w_verts, w_faces, valid_w, lo_w, hi_w])
    ids = np.flatnonzero(valid_w.numpy()).astype(np.int32)
    nvalid = len(ids)
    if nvalid == 0:
        return dict(node_head=np.array([3], np.int32), node_split=np.zeros(1, np.float32),
                    prims=np.zeros(1, np.int32), box=np.zeros((2, 3), np.float32),
                    stats=dict(nodes=1, leaves=1, empty_leaves=1, references=0, depth=0, valid_triangles=0))
    workspace = _Workspace(wp_)
    buf = [("tri_a", "lo_a", "hi_a"), ("tri_b", "lo_b", "hi_b")]  # ping-pong reference buffers
    lo0, hi0 = lo_w.numpy()[ids], hi_w.numpy()[ids]
    root_box = np.stack([lo0.min(axis=0), hi0.max(axis=0)])
    r_tri = workspace.put("tri_a", ids, wp.int32)
    r_lo = workspace.put("lo_a", lo0, wp.vec3)
    r_hi = workspace.put("hi_a", hi0, wp.vec3)
    del lo0, hi0, valid_w, lo_w, hi_w
    ref_start = np.array([0, nvalid], np.int32)
    n_lo, n_hi = root_box[:1].copy(), root_box[1:].copy()
    ct, ci = float(cfg.traversal_cost), float(cfg.intersection_cost)
    max_depth = cfg.depth_limit(nvalid)
    heads: list[np.ndarray] = []
    splits: list[np.ndarray] = []
    prims: list[np.ndarray] = [np.zeros(1, np.int32)]
    prim_len = 1
    n_nodes_total = leaves = empty_leaves = refs_total = 0
    bar = None
    if progress:
        bar = tqdm(total=max_depth + 1, desc=f"kd-tree ({nf:,} triangles)", unit="level", leave=False)
    depth = 0
    while True:
        m = len(n_lo)
        n_ref = int(ref_start[-1])
        counts = np.diff(ref_start)
        w_start = workspace.put("start", ref_start, wp.int32)
        w_nlo = workspace.put("n_lo", n_lo, wp.vec3)
        w_nhi = workspace.put("n_hi", n_hi, wp.vec3)
        w_axis = workspace.get("axis", m, wp.int32)
        w_pos = workspace.get("pos", m, float)
        run(node_splits, m, [w_start, r_lo, r_hi, w_nlo, w_nhi, int(depth < max_depth), int(cfg.bins), ct, ci,
                                 float(cfg.empty_bonus), float(cfg.min_empty_fraction), w_axis, w_pos])
        best_axis = w_axis.numpy()[:m].copy()
        best_pos = w_pos.numpy()[:m].copy()
        split = best_axis >= 0
        is_leaf = ~split
        n_split = int(split.sum())
        # --- emit this level's nodes
        head = np.zeros(m, np.int64)
        base_next = n_nodes_total + m
        rank = np.cumsum(split) - 1
        head[split] = ((base_next + 2 * rank[split]) << 2) | best_axis[split]
        # leaves: blocks [count, prims...] appended to the prim list
        has = is_leaf & (counts > 0)
        block = np.where(has, counts + 1, 0)
        block_start = prim_len + np.concatenate([[0], np.cumsum(block)[:-1]])
        head[is_leaf] = (np.where(has, block_start, 0)[is_leaf] << 2) | 3
        total_block = int(block.sum())
        if total_block:
            arr = wp_.empty(total_block, dtype=wp.int32, device=dev)
            run(emit_leaves, m, [w_start, r_tri, w_axis,
                                     workspace.put("block", (block_start - prim_len).astype(np.int32), wp.int32), arr])
            prims.append(arr.numpy())
            prim_len += total_block
        heads.append(head)
        splits.append(np.where(split, best_pos, 0).astype(np.float32))
        leaves += int(is_leaf.sum())
        empty_leaves += int((is_leaf & (counts == 0)).sum())
        refs_total += int(counts[is_leaf].sum())
        n_nodes_total += m
        if bar is not None:
            bar.update(1)
        if n_split == 0:
            break
        # --- distribute the references of split nodes to their children
        side = workspace.get("side", n_ref, wp.int32)
        l_lo, l_hi = workspace.get("l_lo", n_ref, wp.vec3), workspace.get("l_hi", n_ref, wp.vec3)
        q_lo, q_hi = workspace.get("q_lo", n_ref, wp.vec3), workspace.get("q_hi", n_ref, wp.vec3)
        c_l, c_r = workspace.get("c_l", m, wp.int32), workspace.get("c_r", m, wp.int32)
        run(clip_refs, m, [w_start, r_tri, r_lo, r_hi, w_nlo, w_nhi, w_axis, w_pos, w_verts, w_faces,
                               side, l_lo, l_hi, q_lo, q_hi, c_l, c_r])
        cl, cr = c_l.numpy()[:m].astype(np.int64), c_r.numpy()[:m].astype(np.int64)
        pair = cl + cr
        first_l = np.concatenate([[0], np.cumsum(pair)[:-1]])
        first_r = first_l + cl
        n_new = int(pair.sum())
        names = buf[(depth + 1) % 2]
        new_tri = workspace.get(names[0], n_new, wp.int32)
        new_lo = workspace.get(names[1], n_new, wp.vec3)
        new_hi = workspace.get(names[2], n_new, wp.vec3)
        run(scatter_refs, m, [w_start, r_tri, side, l_lo, l_hi, q_lo, q_hi, w_axis,
                                  workspace.put("first_l", first_l.astype(np.int32), wp.int32),
                                  workspace.put("first_r", first_r.astype(np.int32), wp.int32),
                                  new_tri, new_lo, new_hi])
        r_tri, r_lo, r_hi = new_tri, new_lo, new_hi
        sidx = np.flatnonzero(split)
        child_counts = np.stack([cl[sidx], cr[sidx]], axis=1).reshape(-1)
        ref_start = np.concatenate([[0], np.cumsum(child_counts)]).astype(np.int32)
        # children cells
        c_lo = np.repeat(n_lo[sidx], 2, axis=0)
        c_hi = np.repeat(n_hi[sidx], 2, axis=0)
        k = np.arange(len(sidx))
        c_hi[2 * k, best_axis[sidx]] = best_pos[sidx]
        c_lo[2 * k + 1, best_axis[sidx]] = best_pos[sidx]
        n_lo, n_hi = c_lo, c_hi
        depth += 1
    if bar is not None:
        bar.close()
    head, split_pos = _depth_first_layout(heads, splits)
    return dict(
        node_head=head,
        node_split=split_pos,
        prims=np.concatenate(prims).astype(np.int32),
        box=root_box.astype(np.float32),
        stats=dict(nodes=n_nodes_total, leaves=leaves, empty_leaves=empty_leaves, references=refs_total,
                   depth=depth, valid_triangles=nvalid),
    )


def _depth_first_layout(heads: list[np.ndarray], splits: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Reorder the level-by-level (breadth-first) nodes depth-first, children pairs kept adjacent:
    a node's pair of children is followed by the left child's subtree, then the right child's, so
    the last levels of a descent touch nearby memory. Returns (node_head, node_split)."""
    head = np.concatenate(heads).astype(np.int64)
    split = np.concatenate(splits).astype(np.float32)
    n = len(head)
    inner = (head & 3) != 3
    child = np.where(inner, head >> 2, 0)
    bounds = np.cumsum([0] + [len(h) for h in heads])
    desc = np.zeros(n, np.int64)  # number of descendants
    for k in range(len(heads) - 1, -1, -1):
        x = np.arange(bounds[k], bounds[k + 1])
        x = x[inner[x]]
        desc[x] = 2 + desc[child[x]] + desc[child[x] + 1]
    pos = np.zeros(n, np.int64)
    pair = np.zeros(n, np.int64)  # new position of each inner node's children pair
    pair[0] = 1
    for k in range(len(heads)):
        x = np.arange(bounds[k], bounds[k + 1])
        x = x[inner[x]]
        left, right = child[x], child[x] + 1
        pos[left] = pair[x]
        pos[right] = pair[x] + 1
        pair[left] = pair[x] + 2
        pair[right] = pair[x] + 2 + desc[left]
    new_head = np.empty(n, np.int64)
    new_head[pos] = np.where(inner, (pair << 2) | (head & 3), head)
    new_split = np.empty(n, np.float32)
    new_split[pos] = split
    return new_head.astype(np.int32), new_split


# ----------------------------------------------------------------------------------------------
# host: validation and the disk cache
# ----------------------------------------------------------------------------------------------


def geometry_key(vertices: np.ndarray, faces: np.ndarray, config: KdBuildConfig) -> str:
    """Hash of the geometry and the build settings (the cache key)."""
    h = hashlib.blake2b(digest_size=20)
    h.update(f"kdtree-v{FORMAT_VERSION}|{sorted(asdict(config).items())}|{vertices.shape}|{faces.shape}".encode())
    h.update(np.ascontiguousarray(vertices, np.float32).tobytes())
    h.update(np.ascontiguousarray(faces, np.int32).tobytes())
    return h.hexdigest()


def validate_mesh(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    """``vertices`` (V,3) float32 and ``faces`` (F,3) int32, contiguous; a clear error otherwise."""
    v = np.asarray(vertices)
    f = np.asarray(faces)
    if v.size == 0 or f.size == 0:
        raise SerenityError(f"cannot build a kd-tree of an empty mesh ({v.size // 3 if v.ndim else 0} vertices, "
                            f"{f.size // 3 if f.ndim else 0} triangles)")
    if v.ndim != 2 or v.shape[1] != 3:
        raise SerenityError(f"kd-tree vertices must be a (V, 3) array, got shape {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3:
        raise SerenityError(f"kd-tree faces must be an (F, 3) array, got shape {f.shape}")
    if not np.issubdtype(f.dtype, np.integer):
        raise SerenityError(f"kd-tree faces must be integer vertex indices, got {f.dtype}")
    if f.min() < 0 or f.max() >= len(v):
        raise SerenityError(f"kd-tree face indices out of range 0..{len(v) - 1}")
    return np.ascontiguousarray(v, np.float32), np.ascontiguousarray(f, np.int32)


_ARRAYS = ("node_head", "node_split", "prims", "box")


def save_tree(path: Path, arrays: dict, stats: KdStats) -> None:
    """Write a built tree to ``path`` (an ``.npz`` of plain arrays); an unwritable cache is ignored."""
    meta = np.array([FORMAT_VERSION, stats.triangles, stats.valid_triangles, stats.nodes, stats.leaves,
                     stats.empty_leaves, stats.references, stats.depth], np.int64)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
        np.savez(tmp, **{k: arrays[k] for k in _ARRAYS}, meta=meta, build_seconds=np.array([stats.build_seconds]))
        os.replace(tmp, path)
    except OSError:
        pass  # an unwritable cache only costs a rebuild next time


def load_tree(path: Path, n_faces: int) -> tuple[dict, KdStats] | None:
    """The arrays and stats cached at ``path``, or None when absent, unreadable or stale."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: np.array(z[k]) for k in _ARRAYS}
            meta = z["meta"].tolist()
            secs = float(z["build_seconds"][0])
    except (OSError, ValueError, KeyError, EOFError, IndexError):
        return None
    if len(meta) != 8 or meta[0] != FORMAT_VERSION or meta[1] != n_faces \
            or len(arrays["node_head"]) != len(arrays["node_split"]):
        return None
    stats = KdStats(triangles=meta[1], valid_triangles=meta[2], nodes=meta[3], leaves=meta[4],
                    empty_leaves=meta[5], references=meta[6], depth=meta[7], build_seconds=secs, from_cache=True)
    return arrays, stats

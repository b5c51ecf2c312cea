"""Work per ray of the kd-tree traversal: inner-node steps, non-empty leaves, triangle tests and
stack pops per ray, for the benchmark's rays and several build settings (no timing); and what a
traversal with ropes would do on the same trees and rays (the rope model, below).

    python benchmarks/kdtree_counts.py --json FILE [--configs "SPEC;SPEC;..."] [--size 1280x720]
                                       [--rope-sample 2000] [--rope-grid 32]

Each SPEC is ``key=value,...`` of :class:`serenity.config.KdBuildConfig` ('' = the defaults). The
counters are added to a copy of the kd-tree's traversal (``serenity/kernels/kdtree/traverse.py``)
by text substitution (each substitution must apply, or this stops), the package loaded under its
own name; the hits are checked
against the real traversal on the same tree. Rays as in ``bench_kdtree.py``.

The rope model answers whether a stackless traversal with ropes (Havran's neighbour links;
Popov et al. 2007) would take fewer dependent steps than the stack traversal: each leaf gets its
box and six ropes (the node across each face that holds the whole face, pushed down the tree as
far as the leaf's face allows), and a ray walks from the leaf holding its start, leaf to leaf
through the ropes, each time descending from the rope's node to the leaf it enters (a point
location: one node per step). Walked in Python on ``--rope-sample`` rays per set, up to each
ray's real hit; counted are the descent steps and the leaves entered (the empty ones too: a rope
walk reads every leaf it passes, where the stack traversal skips empty leaves by their parent's
flags), from the root and from the deepest node holding the ray's origin cell on a
``--rope-grid``³ grid over the root box (an entry-point table, for rays that start inside it).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from serenity.config import KdBuildConfig
from serenity.device import init_warp
from serenity.io.results import write_results
from serenity.scene.procedural import lumpy_mesh

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_kdtree import ray_sets  # noqa: E402
from bench_kdtree_steps import package_from_files, version_files  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
#: a rope walk that passes more leaves than this has lost its way (a bug in the model): stop
MAX_ROPE_LEAVES = 100_000

# (old, new): counters in trace_kd; u carries inner steps + pops / 1000, v leaves * 1000 + triangles
SUBSTITUTIONS = [
    ("    while not done:\n        head = node_head(tree.nodes, node)",
     "    n_inner = int(0)\n    n_leaf = int(0)\n    n_tri = int(0)\n    n_pop = int(0)\n"
     "    while not done:\n        head = node_head(tree.nodes, node)"),
    ("        if axis != 3:\n            split = node_split(tree.nodes, node)",
     "        if axis != 3:\n            n_inner += 1\n            split = node_split(tree.nodes, node)"),
    ("        else:\n            prim, best_t, hit_u, hit_v = intersect_leaf(",
     "        else:\n            n_leaf += 1\n            n_tri += int(node_split(tree.nodes, node))\n"
     "            prim, best_t, hit_u, hit_v = intersect_leaf("),
    ("                    if t0 <= best_t:\n                        popped = 1",
     "                    if t0 <= best_t:\n                        popped = 1\n                        n_pop += 1"),
    ("    if prim < 0:\n        best_t = INF\n    return prim, best_t, hit_u, hit_v",
     "    if prim < 0:\n        best_t = INF\n    return prim, best_t, float(n_inner) + 0.001 * float(n_pop), "
     "float(n_leaf) * 1000.0 + float(n_tri)"),
]


def counting_module(tmp: Path):
    files = version_files("WORKTREE")
    src = files["traverse.py"]
    for old, new in SUBSTITUTIONS:
        if src.count(old) != 1:
            raise SystemExit(f"kdtree_counts: the traversal changed, cannot place a counter at:\n{old}")
        src = src.replace(old, new)
    return package_from_files("kdtree_counting", {**files, "traverse.py": src}, tmp)


def node_boxes_and_ropes(head: np.ndarray, split: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Per node its box (float32: the split positions themselves) and per leaf its six ropes (face
    2a: the low side of axis a, 2a + 1 the high side; −1 outside the root box), built level by level
    and then pushed down: while a rope's node is inner, step to its child on the leaf's side when
    the node splits the face's axis or splits another axis outside the leaf's face."""
    n = len(head)
    leaf = (head & 3) == 3
    child = head >> 2
    blo = np.empty((n, 3), np.float32)
    bhi = np.empty((n, 3), np.float32)
    ropes = np.full((n, 6), -1, np.int64)
    blo[0], bhi[0] = lo, hi
    level = np.array([0])
    while len(level):
        inner = level[~leaf[level]]
        a, left = head[inner] & 3, child[inner]
        right = left + 1
        for c in (left, right):
            blo[c], bhi[c], ropes[c] = blo[inner], bhi[inner], ropes[inner]
        bhi[left, a] = split[inner]
        blo[right, a] = split[inner]
        ropes[left, 2 * a + 1] = right
        ropes[right, 2 * a] = left
        level = np.concatenate([left, right])
    leaves = np.flatnonzero(leaf)
    for face in range(6):
        fa, high = face // 2, face & 1
        target = ropes[leaves, face]
        while True:
            idx = np.flatnonzero((target >= 0) & ~leaf[np.maximum(target, 0)])
            t = target[idx]
            b, s, c = head[t] & 3, split[t], child[t]
            step = np.where(b == fa, np.where(high == 1, c, c + 1), -1)
            other = b != fa
            step = np.where(other & (bhi[leaves[idx], b] <= s), c, step)
            step = np.where(other & (blo[leaves[idx], b] >= s), c + 1, step)
            moved = step >= 0
            if not moved.any():
                break
            target[idx[moved]] = step[moved]
        ropes[leaves, face] = target
    return blo, bhi, ropes


def rope_walk(o, d, t_end, tree_arrays, start_node: int):
    """(descent steps, leaves entered, non-empty leaves entered) of one ray's rope walk up to
    ``t_end`` (its hit, or inf), from ``start_node`` (the root, or an entry node holding the origin)."""
    head, split, count, blo, bhi, ropes, lo, hi = tree_arrays
    with np.errstate(divide="ignore"):
        inv = np.where(d != 0, 1 / np.where(d != 0, d, 1), 0.0)
    ta, tb = (lo - o) * inv, (hi - o) * inv
    t_in = max(0.0, float(np.max(np.where(inv != 0, np.minimum(ta, tb), -np.inf))))
    t_out = float(np.min(np.where(inv != 0, np.maximum(ta, tb), np.inf)))
    steps = leaves = non_empty = 0
    node, t = start_node, t_in
    if t_in > t_out:  # misses the root box
        return steps, leaves, non_empty
    while True:
        if leaves > MAX_ROPE_LEAVES:
            raise SystemExit(f"kdtree_counts: a rope walk passed {MAX_ROPE_LEAVES} leaves (o={o}, d={d})")
        while (head[node] & 3) != 3:
            steps += 1
            a, c, s = head[node] & 3, head[node] >> 2, split[node]
            if inv[a] == 0:
                node = c + 1 if o[a] > s else c
                continue
            ts = (s - o[a]) * inv[a]
            early, late = (c, c + 1) if d[a] > 0 else (c + 1, c)
            node = late if t > ts else early
        leaves += 1
        non_empty += count[node] > 0
        far = np.where(d > 0, bhi[node], blo[node])
        te = np.where(inv != 0, (far - o) * inv, np.inf)
        axis = int(np.argmin(te))
        if t_end <= te[axis] or te[axis] >= t_out:
            break
        node = ropes[node, 2 * axis + (1 if d[axis] > 0 else 0)]
        if node < 0:
            break
        t = max(t, float(te[axis]))
    return steps, leaves, non_empty


def entry_node(cell_lo, cell_hi, head, split) -> int:
    """The deepest node whose box holds the whole cell."""
    node = 0
    while (head[node] & 3) != 3:
        a, c, s = head[node] & 3, head[node] >> 2, split[node]
        if cell_hi[a] <= s:
            node = c
        elif cell_lo[a] >= s:
            node = c + 1
        else:
            break
    return node


def rope_tables(tree) -> tuple:
    """What :func:`rope_walk` reads of ``tree`` (a ``KdTree``): nodes, splits, each leaf's triangle
    count, the boxes and ropes, and the padded root box the traversal clips rays to."""
    data = tree.device_data("cpu")
    lo = np.array([data.box_lo[i] for i in range(3)], np.float32)
    hi = np.array([data.box_hi[i] for i in range(3)], np.float32)
    head = tree.node_head.astype(np.int64)
    split = tree.node_split.astype(np.float32)
    leaf = (head & 3) == 3
    count = np.where(leaf, tree.prims[np.where(leaf, head >> 2, 0)], 0)
    blo, bhi, ropes = node_boxes_and_ropes(head, split, lo, hi)
    return head, split, count, blo, bhi, ropes, lo.astype(np.float64), hi.astype(np.float64)


def rope_model(tables: tuple, o, d, t_hit, inner_steps, non_empty, sample, grid: int) -> dict:
    """The rope walk of ``sample`` (ray indices) on :func:`rope_tables` against the stack
    traversal's counted steps."""
    head, split, lo, hi = tables[0], tables[1], tables[6], tables[7]
    ext = hi - lo
    out = {"rays": len(sample), "stack": {"inner_steps": float(inner_steps[sample].mean()),
                                          "non_empty_leaves": float(non_empty[sample].mean())}}
    for name in ("ropes_from_root", f"ropes_from_grid_{grid}"):
        walks = []
        for i in sample:
            oi, di = o[i].astype(np.float64), d[i].astype(np.float64)
            start = 0
            if name != "ropes_from_root" and np.all((oi >= lo) & (oi <= hi)):
                cell = np.clip(np.floor((oi - lo) / ext * grid), 0, grid - 1)
                start = entry_node(lo + cell * ext / grid, lo + (cell + 1) * ext / grid, head, split)
            walks.append(rope_walk(oi, di, float(t_hit[i]), tables, start))
        w = np.array(walks, np.float64)
        out[name] = {"descent_steps": float(w[:, 0].mean()), "leaves_entered": float(w[:, 1].mean()),
                     "non_empty_leaves": float(w[:, 2].mean()),
                     "node_and_leaf_reads": float(w[:, 0].mean() + w[:, 1].mean())}
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", required=True)
    ap.add_argument("--configs", default="min_empty_fraction=0.0;;max_depth=40,min_empty_fraction=0.0;"
                    "traversal_cost=1.0,max_depth=40,min_empty_fraction=0.0")
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--subdivisions", type=int, default=6)
    ap.add_argument("--rope-sample", type=int, default=2000, help="rays per set for the rope model (0: none)")
    ap.add_argument("--rope-grid", type=int, default=32, help="cells per axis of the rope model's entry table")
    args = ap.parse_args(argv)
    init_warp()
    from serenity.kernels.kdtree import KdTree

    width, height = (int(x) for x in args.size.lower().split("x"))
    v, f = lumpy_mesh(args.subdivisions)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        mod = counting_module(Path(tmp))
        for spec in args.configs.split(";"):
            cfg = KdBuildConfig(**{k: json.loads(x) for k, x in (kv.split("=") for kv in spec.split(",") if kv)})
            tree = mod.KdTree.build(v, f, config=cfg, cache=False, progress=False)
            real = KdTree(tree.vertices, tree.faces, {"node_head": tree.node_head, "node_split": tree.node_split,
                                                      "prims": tree.prims, "box": tree.box}, tree.stats)
            sets = ray_sets(real, width, height)
            rng = np.random.default_rng(1)  # the rope model's sample
            tables = rope_tables(real) if args.rope_sample > 0 else None
            st = tree.stats
            row = {"config": spec or "defaults", "nodes": st.nodes, "leaves": st.leaves,
                   "empty_leaves": st.empty_leaves, "references": st.references, "depth": st.depth,
                   "references_per_non_empty_leaf": st.references / max(1, st.leaves - st.empty_leaves),
                   "node_mib": st.nodes * 8 / 2**20, "reference_mib": len(tree.prims) * 40 / 2**20}
            for name, (o, d) in sets.items():
                c = tree.intersect(o, d, device="cpu", rays_per_thread=1)  # trace_kd, which holds the counters
                ref = real.intersect(o, d, device="cpu")
                if not (np.array_equal(c.prim, ref.prim) and np.array_equal(c.t, ref.t)):
                    raise SystemExit("kdtree_counts: the counting traversal's hits differ from the real one")
                inner = np.floor(c.u + 1e-4)
                pops = np.round((c.u - inner) * 1000)
                leaves = np.floor(c.v / 1000)
                tris = c.v - leaves * 1000
                row[name] = {"inner_steps": float(inner.mean()), "non_empty_leaves": float(leaves.mean()),
                             "triangle_tests": float(tris.mean()), "pops": float(pops.mean()),
                             "hit_fraction": float(c.hit.mean())}
                print(f"{row['config']:>36} {name:>10}: inner steps {inner.mean():5.1f}, non-empty leaves "
                      f"{leaves.mean():4.2f}, triangle tests {tris.mean():4.2f}, pops {pops.mean():4.2f}", flush=True)
                if args.rope_sample > 0:
                    sample = np.sort(rng.choice(len(o), min(args.rope_sample, len(o)), replace=False))
                    model = rope_model(tables, o, d, ref.t, inner, leaves, sample, args.rope_grid)
                    row[name]["rope_model"] = model
                    for key, m in model.items():
                        if key.startswith("ropes"):
                            print(f"{'':>36} {'':>10}  {key}: descent steps {m['descent_steps']:5.1f} + leaves "
                                  f"entered {m['leaves_entered']:4.2f} (stack traversal on the same rays: "
                                  f"{model['stack']['inner_steps']:5.1f} inner steps)", flush=True)
            rows.append(row)
    out = {"benchmark": "kdtree_counts", "triangles": len(f), "size": [width, height], "per_ray_means": rows}
    write_results(args.json, out)
    return out


if __name__ == "__main__":
    main()

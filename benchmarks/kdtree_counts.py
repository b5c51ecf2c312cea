"""Work per ray of the kd-tree traversal: inner-node steps, non-empty leaves, triangle tests and
stack pops per ray, for the benchmark's rays and several build settings (no timing).

    python benchmarks/kdtree_counts.py --json FILE [--configs "SPEC;SPEC;..."] [--size 1280x720]

Each SPEC is ``key=value,...`` of :class:`serenity.config.KdBuildConfig` ('' = the defaults). The
counters are added to a copy of ``serenity/kernels/kdtree.py``'s traversal by text substitution
(each substitution must apply, or this stops), loaded as its own module; the hits are checked
against the real traversal on the same tree. Rays as in ``bench_kdtree.py``.
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
from bench_kdtree import camera_rays  # noqa: E402
from bench_kdtree_steps import module_from_source  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent

# (old, new): counters in trace_kd; u carries inner steps + pops / 1000, v leaves * 1000 + triangles
SUBSTITUTIONS = [
    ("    while not done:\n        head = node_head(tree.nodes, node)",
     "    n_inner = int(0)\n    n_leaf = int(0)\n    n_tri = int(0)\n    n_pop = int(0)\n"
     "    while not done:\n        head = node_head(tree.nodes, node)"),
    ("        if axis != 3:\n            split = node_split(tree.nodes, node)",
     "        if axis != 3:\n            n_inner += 1\n            split = node_split(tree.nodes, node)"),
    ("            n = int(node_split(tree.nodes, node))\n            for j in range(n):",
     "            n = int(node_split(tree.nodes, node))\n            n_leaf += 1\n            n_tri += n\n"
     "            for j in range(n):"),
    ("                    if t0 <= best_t:\n                        popped = 1",
     "                    if t0 <= best_t:\n                        popped = 1\n                        n_pop += 1"),
    ("    if prim < 0:\n        best_t = _INF\n    return prim, best_t, hit_u, hit_v",
     "    if prim < 0:\n        best_t = _INF\n    return prim, best_t, float(n_inner) + 0.001 * float(n_pop), "
     "float(n_leaf) * 1000.0 + float(n_tri)"),
]


def counting_module(tmp: Path):
    src = (ROOT / "serenity/kernels/kdtree.py").read_text()
    for old, new in SUBSTITUTIONS:
        if src.count(old) != 1:
            raise SystemExit(f"kdtree_counts: the traversal changed, cannot place a counter at:\n{old}")
        src = src.replace(old, new)
    return module_from_source("kdtree_counting", src, tmp)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", required=True)
    ap.add_argument("--configs", default="min_empty_fraction=0.0;;max_depth=40,min_empty_fraction=0.0;"
                    "traversal_cost=1.0,max_depth=40,min_empty_fraction=0.0")
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--subdivisions", type=int, default=6)
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
            oc, dc = camera_rays(width, height)
            h = real.intersect(oc, dc, device="cpu")
            rng = np.random.default_rng(0)
            oi = oc.copy()
            oi[h.hit] = oc[h.hit] + dc[h.hit] * (h.t[h.hit] - 1e-3)[:, None]
            di = rng.normal(size=oc.shape).astype(np.float32)
            di /= np.linalg.norm(di, axis=1, keepdims=True)
            st = tree.stats
            row = {"config": spec or "defaults", "nodes": st.nodes, "leaves": st.leaves,
                   "empty_leaves": st.empty_leaves, "references": st.references, "depth": st.depth,
                   "references_per_non_empty_leaf": st.references / max(1, st.leaves - st.empty_leaves),
                   "node_mib": st.nodes * 8 / 2**20, "reference_mib": len(tree.prims) * 40 / 2**20}
            for name, (o, d) in {"coherent": (oc, dc), "incoherent": (oi, di)}.items():
                c = tree.intersect(o, d, device="cpu")
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
            rows.append(row)
    out = {"benchmark": "kdtree_counts", "triangles": len(f), "size": [width, height], "per_ray_means": rows}
    write_results(args.json, out)
    return out


if __name__ == "__main__":
    main()

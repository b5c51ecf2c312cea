"""kd-tree speed against Embree and Warp's own ``wp.Mesh`` BVH, measured in the same run (paper §9).

    python benchmarks/bench_kdtree.py --json FILE [--size 1280x720] [--subdivisions 6] [--repeats 5]
                                      [--build-sizes 10000,40000,160000,640000]

Scene: a displaced icosphere on a wavy terrain grid (``--subdivisions 6``: 164k triangles, 7: 655k).
Rays (the same arrays for every tracer):
- coherent: camera primary rays, one per pixel of ``--size``;
- incoherent: from the camera rays' hit points (nudged back 1 mm), uniformly random directions
  (secondary rays as a reflection pass would cast them, without any coherence).
Tracers: ours (:class:`serenity.kernels.kdtree.KdTree`, closest hit), Embree (``embreex``, closest
hit, one ``run`` call over all rays) and Warp's BVH (``wp.mesh_query_ray``, SAH constructor), each on
1 thread and on all threads (ours and Warp's through ``serenity.kernels.launch``; Embree's calls split
over Python threads — embreex holds the GIL, so that is shown only as it measures).
Times are medians of ``--repeats`` runs after a warm-up (compilation, first-touch) outside the timed
region. Figures that are claims are ratios to the anchors of this run: ``ratio_vs_embree_1t`` (ours
1 thread / Embree 1 thread), ``ratio_vs_embree_all_threads`` (ours all threads / Embree's single
call), ``speedup_vs_warp_bvh_1t`` (ours 1 thread / Warp BVH 1 thread), on incoherent rays (the
coherent figures carry a ``_coherent`` suffix). Build: median seconds of our build (no cache), its
O(N log N) fit over ``--build-sizes``, and the agreement with Embree's hits.
Prints a table and writes JSON (machine, device, scene, settings, figures).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from serenity.device import cpu_threads, init_warp
from serenity.kernels.kdtree import KdTree
from serenity.kernels.launch import launch
from serenity.scene.procedural import lumpy_mesh


def camera_rays(width: int, height: int, position=(0.0, 0.6, 3.5), target=(0.0, -0.3, 0.0), fov_deg=60.0):
    f = np.asarray(target, np.float64) - position
    f /= np.linalg.norm(f)
    r = np.cross(f, [0.0, 1.0, 0.0])
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    t = math.tan(math.radians(fov_deg) / 2)
    xs = ((np.arange(width) + 0.5) / width * 2 - 1) * t * width / height
    ys = (1 - (np.arange(height) + 0.5) / height * 2) * t
    d = f + xs[None, :, None] * r + ys[:, None, None] * u
    d = d.reshape(-1, 3)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(np.asarray(position, np.float32), d.shape)
    return np.ascontiguousarray(o, np.float32), d.astype(np.float32)


def median_time(fn, repeats: int) -> float:
    fn()  # warm-up: compile, first touch
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _warp_bvh_kernel(wp):
    @wp.kernel(enable_backward=False)
    def query_rays(mesh: wp.uint64, origins: wp.array(dtype=wp.vec3), directions: wp.array(dtype=wp.vec3),
                   out_t: wp.array(dtype=float), out_prim: wp.array(dtype=wp.int32), offset: int):
        i = wp.tid() + offset
        q = wp.mesh_query_ray(mesh, origins[i], directions[i], 1.0e30)
        if q.result:
            out_t[i] = q.t
            out_prim[i] = q.face
        else:
            out_t[i] = float(math.inf)
            out_prim[i] = -1

    return query_rays


def measure_rates(wp, tree, embree, query_rays, mesh, o, d, threads: int, repeats: int) -> dict:
    """Mrays/s of ours, Embree and Warp's BVH on the rays (o, d), on 1 and on ``threads`` threads."""
    n = len(o)
    wo, wd = wp.array(o, dtype=wp.vec3, device="cpu"), wp.array(d, dtype=wp.vec3, device="cpu")
    wt, wpr = wp.empty(n, dtype=float, device="cpu"), wp.empty(n, dtype=wp.int32, device="cpu")
    rates = {}
    for nt in (1, threads):
        rates[f"ours_{nt}t"] = n / median_time(lambda nt=nt: tree.intersect(o, d, device="cpu", threads=nt),
                                               repeats) / 1e6
        rates[f"embree_{nt}t"] = n / median_time(lambda nt=nt: embree(o, d, nt), repeats) / 1e6
        rates[f"warp_bvh_{nt}t"] = n / median_time(
            lambda nt=nt: launch(query_rays, n, [mesh.id, wo, wd, wt, wpr], device="cpu", threads=nt), repeats) / 1e6
    return rates


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", required=True, help="write the figures here")
    ap.add_argument("--size", default="1280x720", help="camera rays WxH (default 1280x720)")
    ap.add_argument("--subdivisions", type=int, default=6, help="icosphere subdivisions (6: 164k tris, 7: 655k)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--build-sizes", default="10000,40000,160000",
                    help="triangle counts for the build-time sweep (nearest lumpy scene), '' = none")
    args = ap.parse_args(argv)
    width, height = (int(x) for x in args.size.lower().split("x"))
    wp = init_warp()
    threads = cpu_threads()

    v, f = lumpy_mesh(args.subdivisions)
    build_times = []
    for _ in range(max(1, min(3, args.repeats))):
        t0 = time.perf_counter()
        tree = KdTree.build(v, f, cache=False, progress=False)
        build_times.append(time.perf_counter() - t0)
    build_s = statistics.median(build_times)

    # rays
    oc, dc = camera_rays(width, height)
    hits = tree.intersect(oc, dc, device="cpu")
    rng = np.random.default_rng(0)
    hit = hits.hit
    oi = oc.copy()
    oi[hit] = oc[hit] + dc[hit] * (hits.t[hit] - 1e-3)[:, None]
    di = rng.normal(size=oc.shape).astype(np.float32)
    di /= np.linalg.norm(di, axis=1, keepdims=True)
    ray_sets = {"coherent": (oc, dc), "incoherent": (oi, di)}

    # anchors
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    escene = rtcore_scene.EmbreeScene()
    TriangleMesh(escene, v, f)
    mesh = wp.Mesh(points=wp.array(v, dtype=wp.vec3, device="cpu"),
                   indices=wp.array(f.reshape(-1), dtype=wp.int32, device="cpu"), bvh_constructor="sah")
    query_rays = _warp_bvh_kernel(wp)
    pool = ThreadPoolExecutor(max_workers=threads)

    def embree(o, d, n_threads):
        if n_threads == 1:
            return escene.run(o, d)
        chunks = np.array_split(np.arange(len(o)), n_threads)
        return list(pool.map(lambda c: escene.run(o[c[0]:c[-1] + 1], d[c[0]:c[-1] + 1]), chunks))

    figures, table = {}, []
    for name, (o, d) in ray_sets.items():
        n = len(o)
        rates = measure_rates(wp, tree, embree, query_rays, mesh, o, d, threads, args.repeats)
        ours = tree.intersect(o, d, device="cpu")
        res = escene.run(o, d, output=1)
        e_prim = res["primID"]
        e_t = np.where(e_prim >= 0, res["tfar"], np.inf)
        both = (e_prim >= 0) & ours.hit
        close = np.zeros(n, bool)
        close[both] = np.abs(ours.t[both] - e_t[both]) <= 1e-5 * e_t[both]
        agree = float(np.mean(((e_prim == ours.prim) & ((e_prim < 0) | close)) | close))
        suffix = "" if name == "incoherent" else "_coherent"
        figures[name] = {"rays": n, "hit_fraction": float(ours.hit.mean()), "mrays_per_s": rates,
                         "agreement_with_embree": agree}
        figures[f"ratio_vs_embree_1t{suffix}"] = rates["ours_1t"] / rates["embree_1t"]
        figures[f"ratio_vs_embree_all_threads{suffix}"] = rates[f"ours_{threads}t"] / rates["embree_1t"]
        figures[f"speedup_vs_warp_bvh_1t{suffix}"] = rates["ours_1t"] / rates["warp_bvh_1t"]
        figures[f"speedup_vs_warp_bvh_all_threads{suffix}"] = rates[f"ours_{threads}t"] / rates[f"warp_bvh_{threads}t"]
        for k, r in rates.items():
            table.append((name, k, r))
    pool.shutdown()

    sweep = []
    for target in [int(x) for x in args.build_sizes.split(",") if x.strip()]:
        sub = max(1, min(8, int(round(math.log(max(target, 80) / 40, 4)))))
        vs, fs = lumpy_mesh(sub)
        t0 = time.perf_counter()
        KdTree.build(vs, fs, cache=False, progress=False)
        sweep.append({"triangles": len(fs), "seconds": time.perf_counter() - t0})
    if sweep:
        nlogn = np.array([s["triangles"] * math.log2(s["triangles"]) for s in sweep])
        secs = np.array([s["seconds"] for s in sweep])
        k = float(np.sum(nlogn * secs) / np.sum(nlogn * nlogn))  # least squares seconds = k * N log2 N
        for s, pred in zip(sweep, k * nlogn, strict=True):
            s["n_log_n_fit_seconds"] = float(pred)
        figures["build_seconds_per_n_log2_n"] = k
        figures["build_1m_s_extrapolated"] = k * 1e6 * math.log2(1e6)

    st = tree.stats
    out = {
        "benchmark": "kdtree",
        "machine": {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
                    "cpus": os.cpu_count(), "threads": threads, "python": platform.python_version(),
                    "warp": wp.__version__},
        "device": "cpu",
        "scene": {"name": f"lumpy icosphere + terrain (subdivisions {args.subdivisions})", "triangles": len(f)},
        "settings": {"size": [width, height], "repeats": args.repeats},
        "build": {"seconds": build_s, "nodes": st.nodes, "leaves": st.leaves, "empty_leaves": st.empty_leaves,
                  "references": st.references, "depth": st.depth, "sweep": sweep},
        "figures": figures,
    }
    os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
    with open(args.json, "w") as fh:
        json.dump(out, fh, indent=2)

    print(f"kd-tree: {len(f):,} triangles, build {build_s:.2f} s ({st.nodes:,} nodes, "
          f"{st.references / len(f):.2f} refs/triangle, depth {st.depth}); {threads} threads")
    print(f"{'rays':<11} {'tracer':<16} {'Mrays/s':>8}")
    for name, k, r in table:
        print(f"{name:<11} {k:<16} {r:8.2f}")
    for k in ("ratio_vs_embree_1t", "ratio_vs_embree_all_threads", "speedup_vs_warp_bvh_1t",
              "speedup_vs_warp_bvh_all_threads"):
        print(f"{k:<34} incoherent {figures[k]:5.2f}   coherent {figures[k + '_coherent']:5.2f}")
    print(f"agreement with Embree: coherent {figures['coherent']['agreement_with_embree']:.6f}, "
          f"incoherent {figures['incoherent']['agreement_with_embree']:.6f}")
    for s in sweep:
        print(f"build {s['triangles']:>9,} triangles: {s['seconds']:6.2f} s "
              f"(N log N fit {s['n_log_n_fit_seconds']:.2f} s)")
    if sweep:
        print(f"build of 1M triangles, extrapolated from the N log N fit: {figures['build_1m_s_extrapolated']:.1f} s")
    print(f"wrote {args.json}")
    return out


if __name__ == "__main__":
    main()

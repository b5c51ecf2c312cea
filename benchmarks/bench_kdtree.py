"""kd-tree speed against Embree and Warp's own ``wp.Mesh`` BVH, measured in the same run (paper §9).

    python benchmarks/bench_kdtree.py --json FILE [--size 1280x720] [--subdivisions 6] [--repeats 11]
                                      [--build-sizes 10000,40000,160000,640000,1000000] [--charts PREFIX]

Scene: a displaced icosphere on a wavy terrain grid (``--subdivisions 6``: 164k triangles, 7: 655k).
Rays (the same arrays for every tracer):
- coherent: camera primary rays, one per pixel of ``--size``;
- incoherent: from the camera rays' hit points (nudged back 1 mm), uniformly random directions
  (secondary rays as a reflection pass would cast them, without any coherence).
Tracers: ours (:class:`serenity.kernels.kdtree.KdTree`, closest hit; the default call, which
reorders incoherent batches before the launch — ``sort=None``, ``serenity.kernels.kdtree.ray_order``
— with the sort, the gather and the write-back inside the timed call; ``reordered`` per ray set says
whether it did, and ``rays_per_thread`` how many rays each kernel thread traces at once: both sets
are traced in packets, ``serenity.kernels.kdtree.trace_packets_kernel``, the incoherent one in its
sorted order, the camera rays in theirs),
Embree (``embreex``, closest hit, one ``run`` call over all rays) and Warp's BVH
(``wp.mesh_query_ray``, SAH constructor; both take the rays as they come). Ours and Warp's run on
1, 2, ... all threads (through ``serenity.kernels.launch``); Embree on 1 thread, and its calls
split over all threads as Python threads (embreex holds the GIL, so that is shown only as it
measures). Every tracer and thread count runs once per round, in turn, for ``--repeats`` rounds
after one warm-up each (compilation, first touch) outside the timed region; rates are medians over
the rounds. The host's speed drifts by 30-50 % within minutes on the shared CI-class machine, so
the ratios below are **paired**: the median over rounds of the two wall times' ratio within a round
(seconds apart), not a ratio of medians taken minutes apart; each ray set's
``paired_ratios_per_round`` keeps the rounds' values (other tracer's time / ours).

Figures (ratios of this run's own measurements; incoherent rays unless ``_coherent``):
- ``ratio_vs_embree_1t``: ours / Embree, 1 thread each (paired); ``ratio_vs_embree_all_threads``:
  ours on all threads / Embree's best (medians);
- ``speedup_vs_warp_bvh_1t``: ours / Warp's BVH, 1 thread each (paired);
- ``thread_scaling``: ours on 2 threads / ours on 1 (paired), the worse of coherent and incoherent. Wall
  time: on a machine shared with other busy sessions (Linux groups each session's threads and
  shares the CPUs equally between groups: ``sched_autogroup``) a second thread gets no more CPU, so
  this reads ~1 there; ``machine.load_average`` says how busy the machine was.
  ``thread_scaling_cpu_bound``: the same split's Σ thread CPU-s / the busiest thread's CPU-s inside
  the kernel launches — their speed-up on 2 threads when each has a core to itself (imbalance and
  overheads, not the load; the serial Python before and after the launches is not in it); per ray
  set also ``thread_scaling_cpu_bound_one_chunk_per_thread``, the same for one contiguous chunk per
  thread (the split of an unbalanced launch: uneven, sky above and ground below);
  ``thread_cpu_efficiency`` (per ray set): Mrays per CPU-second of the process on 2 threads / on 1
  (1.0: the second thread does its rays at the same CPU cost; below 1: the threads slow each other
  through the shared L3 and memory); ``thread_scaling_projected`` = ``thread_scaling_cpu_bound`` ×
  that, the 2-thread speed-up on an otherwise idle machine (the worse ray set at the top level);
- ``*_cpu`` ratios (``ratio_vs_embree_1t_cpu``, ``speedup_vs_warp_bvh_1t_cpu``, with ``_coherent``):
  the same 1-thread ratios from CPU seconds of the process instead of wall seconds, which a
  time-shared (loaded) machine does not distort; ``mrays_per_cpu_s`` per ray set has the rates;
- ``build_1m_s``: wall seconds of one build of 1 M triangles (no cache), measured;
  ``build_1m_cpu_s`` its CPU seconds (all threads). The sweep over ``--build-sizes`` builds random
  subsets (seeded) of the subdivision-8 scene (2.6 M triangles), with an N log N least-squares fit.
Charts: ``PREFIX_threads.png`` (Mrays/s vs threads) and ``PREFIX_build.png`` (build seconds vs
triangles); PREFIX defaults to the JSON path without ``.json``. Prints progress, a table, and the JSON.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import sys
import threading
import time
from collections import defaultdict
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from serenity.device import cpu_threads, init_warp
from serenity.io.results import machine_info, write_results
from serenity.kernels.kdtree import PACKET_LANES, KdTree, intersect_rays, ray_order
from serenity.kernels.launch import launch
from serenity.scene.procedural import lumpy_mesh

_T0 = time.perf_counter()


def say(msg: str) -> None:
    print(f"[bench_kdtree {time.perf_counter() - _T0:7.1f} s] {msg}", flush=True)


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


def ray_sets(tree, width: int, height: int) -> dict:
    """The benchmark's two ray sets, traced against ``tree`` (any version's ``KdTree``) to place the
    second: ``coherent``, the camera's rays, one per pixel of ``width`` × ``height``; ``incoherent``,
    from their hit points (nudged back 1 mm; a miss keeps the camera's origin) in uniformly random
    directions (seed 0). Each is (origins, directions), (N, 3) float32."""
    oc, dc = camera_rays(width, height)
    hits = tree.intersect(oc, dc, device="cpu")
    rng = np.random.default_rng(0)
    oi = oc.copy()
    oi[hits.hit] = oc[hits.hit] + dc[hits.hit] * (hits.t[hits.hit] - 1e-3)[:, None]
    di = rng.normal(size=oc.shape).astype(np.float32)
    di /= np.linalg.norm(di, axis=1, keepdims=True)
    return {"coherent": (oc, dc), "incoherent": (oi, di)}


def median_time(fn, repeats: int, cpu: dict | None = None, key: str = "") -> float:
    """Median wall seconds of ``fn`` over ``repeats`` runs after a warm-up; with ``cpu``, also
    ``cpu[key]`` = the median CPU seconds of the process (all its threads) per run."""
    fn()  # warm-up: compile, first touch
    times, cpus = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    if cpu is not None:
        cpu[key] = statistics.median(cpus)
    return statistics.median(times)


def thread_cpu_split(wp, fn) -> float:
    """Run ``fn`` once, recording each thread's CPU time inside ``wp.launch``; return Σ / max: the
    speed-up of that split when every thread has a core of its own."""
    per_thread: dict[int, float] = defaultdict(float)
    lock = threading.Lock()
    original = wp.launch

    def timed(*args, **kwargs):
        t0 = time.thread_time()
        out = original(*args, **kwargs)
        dt = time.thread_time() - t0
        with lock:
            per_thread[threading.get_ident()] += dt
        return out

    wp.launch = timed
    try:
        fn()
    finally:
        wp.launch = original
    cpu = list(per_thread.values())
    return sum(cpu) / max(cpu) if cpu and max(cpu) > 0 else 1.0


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


def measure_rates(wp, tree, embree, query_rays, mesh, o, d, thread_counts: list[int], repeats: int):
    """Mrays/s (wall) of ours and Warp's BVH on each thread count, Embree on 1 and on all; Mrays per
    CPU-second of the process for the same runs (one thread: immune to time-sharing); and the
    per-round ratios of each tracer's wall time to ours on the same thread count. Every tracer and
    thread count runs once per round, in turn (after one warm-up each), so a round's runs are
    seconds apart and a ratio within a round is not moved by the host's drift between rounds (it
    drifts by 30-50 % within minutes on the shared CI-class machine)."""
    n = len(o)
    wo, wd = wp.array(o, dtype=wp.vec3, device="cpu"), wp.array(d, dtype=wp.vec3, device="cpu")
    wt, wpr = wp.empty(n, dtype=float, device="cpu"), wp.empty(n, dtype=wp.int32, device="cpu")
    top = max(thread_counts)
    runs = {}  # name -> callable
    for nt in thread_counts:
        runs[f"ours_{nt}t"] = lambda nt=nt: tree.intersect(o, d, device="cpu", threads=nt)
        runs[f"warp_bvh_{nt}t"] = lambda nt=nt: launch(query_rays, n, [mesh.id, wo, wd, wt, wpr], device="cpu",
                                                       threads=nt, balanced=True)
    runs["embree_1t"] = lambda: embree(o, d, 1)
    if top > 1:
        runs[f"embree_{top}t"] = lambda: embree(o, d, top)
    say(f"  {n:,} rays: {', '.join(runs)}, {repeats} rounds")
    for fn in runs.values():
        fn()  # warm-up: compile, first touch
    wall = {k: [] for k in runs}
    cpu = {k: [] for k in runs}
    for _ in range(repeats):
        for k, fn in runs.items():
            c0, t0 = time.process_time(), time.perf_counter()
            fn()
            wall[k].append(time.perf_counter() - t0)
            cpu[k].append(time.process_time() - c0)
    rates = {k: n / statistics.median(v) / 1e6 for k, v in wall.items()}
    cpu_rates = {k: n / statistics.median(v) / 1e6 for k, v in cpu.items() if k != f"embree_{top}t" or top == 1}
    paired = {}  # other's time / ours, per round (> 1: ours is faster)
    for k in runs:
        nt = k.rsplit("_", 1)[1]
        if not k.startswith("ours_") and f"ours_{nt}" in wall:
            paired[f"{k}_over_ours"] = [a / b for a, b in zip(wall[k], wall[f"ours_{nt}"], strict=True)]
    if top > 1:
        paired["ours_1t_over_ours_2t"] = [a / b for a, b in zip(wall["ours_1t"], wall["ours_2t"], strict=True)]
    return rates, cpu_rates, paired


def build_sweep(sizes: list[int], repeats: int) -> list[dict]:
    """Build time (wall and CPU, no cache) of random subsets of the subdivision-8 scene."""
    if not sizes:
        return []
    say("build sweep: making the subdivision-8 scene (2.6 M triangles)")
    v, f = lumpy_mesh(8)
    rng = np.random.default_rng(1)
    out = []
    for n in sizes:
        sub = f[np.sort(rng.choice(len(f), min(n, len(f)), replace=False))]
        walls, cpus = [], []
        for _ in range(max(1, min(3, repeats)) if n <= 200_000 else 1):
            c0, t0 = time.process_time(), time.perf_counter()
            tree = KdTree.build(v, sub, cache=False, progress=False)
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
        st = tree.stats
        out.append({"triangles": len(sub), "seconds": statistics.median(walls), "cpu_seconds": statistics.median(cpus),
                    "nodes": st.nodes, "references": st.references, "depth": st.depth})
        say(f"  build {len(sub):>9,} triangles: {out[-1]['seconds']:6.2f} s wall, {out[-1]['cpu_seconds']:6.2f} CPU-s")
    nlogn = np.array([s["triangles"] * math.log2(s["triangles"]) for s in out])
    secs = np.array([s["seconds"] for s in out])
    k = float(np.sum(nlogn * secs) / np.sum(nlogn * nlogn))  # least squares: seconds = k * N log2 N
    for s, pred in zip(out, k * nlogn, strict=True):
        s["n_log_n_fit_seconds"] = float(pred)
    return out


def save_charts(prefix: str, figures: dict, sweep: list[dict], thread_counts: list[int]) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=False)
    for ax, name in zip(axes, ("coherent", "incoherent"), strict=True):
        r = figures[name]["mrays_per_s"]
        ax.plot(thread_counts, [r[f"ours_{t}t"] for t in thread_counts], "o-", label="ours (kd-tree)")
        ax.plot(thread_counts, [r[f"warp_bvh_{t}t"] for t in thread_counts], "s-", label="Warp wp.Mesh BVH")
        ax.axhline(r["embree_1t"], color="k", ls="--", lw=1, label="Embree, 1 thread")
        ax.set_title(f"{name} rays ({figures[name]['rays']:,})")
        ax.set_xlabel("threads")
        ax.set_xticks(thread_counts)
        ax.set_ylabel("Mrays/s")
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    paths.append(f"{prefix}_threads.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    if sweep:
        fig, ax = plt.subplots(figsize=(5.5, 4))
        n = np.array([s["triangles"] for s in sweep])
        ax.loglog(n, [s["seconds"] for s in sweep], "o-", label="build, wall s")
        ax.loglog(n, [s["cpu_seconds"] for s in sweep], "^:", label="build, CPU s (all threads)")
        ax.loglog(n, [s["n_log_n_fit_seconds"] for s in sweep], "k--", lw=1, label="k·N log N fit (wall)")
        ax.axhline(5.0, color="r", lw=0.8, ls=":", label="5 s")
        ax.set_xlabel("triangles")
        ax.set_ylabel("seconds")
        ax.set_title("SAH kd-tree build (no cache)")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        fig.tight_layout()
        paths.append(f"{prefix}_build.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)
    return paths


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    if argv is None:
        argv = sys.argv[1:]
    ap.add_argument("--json", required=True, help="write the figures here")
    ap.add_argument("--size", default="1280x720", help="camera rays WxH (default 1280x720)")
    ap.add_argument("--subdivisions", type=int, default=6, help="icosphere subdivisions (6: 164k tris, 7: 655k)")
    ap.add_argument("--repeats", type=int, default=11, help="rounds (each runs every tracer once)")
    ap.add_argument("--build-sizes", default="10000,40000,160000,640000,1000000",
                    help="triangle counts of the build sweep ('' = none; 1000000 gives build_1m_s)")
    ap.add_argument("--charts", default=None, help="chart path prefix (default: the JSON path without .json)")
    args = ap.parse_args(argv)
    width, height = (int(x) for x in args.size.lower().split("x"))
    wp = init_warp()
    threads = cpu_threads()
    thread_counts = sorted({1, 2, threads})
    load_before = os.getloadavg()

    say(f"scene: lumpy mesh, subdivisions {args.subdivisions}")
    v, f = lumpy_mesh(args.subdivisions)
    build_times = []
    for _ in range(max(1, min(3, args.repeats))):
        t0 = time.perf_counter()
        tree = KdTree.build(v, f, cache=False, progress=False)
        build_times.append(time.perf_counter() - t0)
    build_s = statistics.median(build_times)
    say(f"built the tree of {len(f):,} triangles: {build_s:.2f} s")

    # rays
    sets = ray_sets(tree, width, height)

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
    scaling, scaling_cpu, scaling_projected = [], [], []
    for name, (o, d) in sets.items():
        say(f"{name} rays")
        n = len(o)
        rates, cpu_rates, paired = measure_rates(wp, tree, embree, query_rays, mesh, o, d, thread_counts,
                                                 args.repeats)
        cpu_bound = thread_cpu_split(wp, lambda o=o, d=d: tree.intersect(o, d, device="cpu", threads=2))
        # the same with one contiguous chunk per thread (an unbalanced launch)
        args_1 = [tree.device_data("cpu"), wp.array(o, dtype=wp.vec3, device="cpu"),
                  wp.array(d, dtype=wp.vec3, device="cpu"), 0.0,
                  wp.array(np.full(n, np.inf, np.float32), dtype=float, device="cpu")]  # unsorted
        outs_1 = [wp.empty(n, dtype=t, device="cpu") for t in (float, wp.int32, float, float)]
        cpu_bound_halves = thread_cpu_split(
            wp, lambda n=n, a=[*args_1, *outs_1]: launch(intersect_rays, n, a, device="cpu", threads=2))
        ours = tree.intersect(o, d, device="cpu")
        res = escene.run(o, d, output=1)
        e_prim = res["primID"]
        e_t = np.where(e_prim >= 0, res["tfar"], np.inf)
        both = (e_prim >= 0) & ours.hit
        close = np.zeros(n, bool)
        close[both] = np.abs(ours.t[both] - e_t[both]) <= 1e-5 * e_t[both]
        agree = float(np.mean(((e_prim == ours.prim) & ((e_prim < 0) | close)) | close))
        suffix = "" if name == "incoherent" else "_coherent"
        embree_best = max(rates["embree_1t"], rates.get(f"embree_{threads}t", 0.0))
        # CPU time: the work per ray on 2 threads against 1 (1.0 = the threads do not slow each other
        # down through the shared caches and memory); times the balance = the 2-thread speed-up
        # when each thread has a core of its own
        efficiency = cpu_rates["ours_2t"] / cpu_rates["ours_1t"]
        data = tree.device_data("cpu")
        reordered = ray_order(data.box_lo, data.box_hi, wp.array(o, dtype=wp.vec3, device="cpu"),
                              wp.array(d, dtype=wp.vec3, device="cpu"), n, None, "cpu").shape[0] > 0
        # the default query traces a reordered batch and a coherent one in packets
        figures[name] = {"rays": n, "reordered": reordered, "rays_per_thread": PACKET_LANES,
                         "hit_fraction": float(ours.hit.mean()),
                         "mrays_per_s": rates,
                         "mrays_per_cpu_s": cpu_rates, "paired_ratios_per_round": paired,
                         "thread_cpu_efficiency": efficiency,
                         "thread_scaling_projected": cpu_bound * efficiency,
                         "agreement_with_embree": agree, "thread_scaling_cpu_bound": cpu_bound,
                         "thread_scaling_cpu_bound_one_chunk_per_thread": cpu_bound_halves}
        figures[f"ratio_vs_embree_1t{suffix}"] = statistics.median(paired["embree_1t_over_ours"])
        figures[f"ratio_vs_embree_1t_cpu{suffix}"] = cpu_rates["ours_1t"] / cpu_rates["embree_1t"]
        figures[f"speedup_vs_warp_bvh_1t_cpu{suffix}"] = cpu_rates["ours_1t"] / cpu_rates["warp_bvh_1t"]
        figures[f"ratio_vs_embree_all_threads{suffix}"] = rates[f"ours_{threads}t"] / embree_best
        figures[f"speedup_vs_warp_bvh_1t{suffix}"] = statistics.median(paired["warp_bvh_1t_over_ours"])
        figures[f"speedup_vs_warp_bvh_all_threads{suffix}"] = rates[f"ours_{threads}t"] / rates[f"warp_bvh_{threads}t"]
        scaling.append(statistics.median(paired["ours_1t_over_ours_2t"]))
        scaling_cpu.append(cpu_bound)
        scaling_projected.append(cpu_bound * efficiency)
        for k, r in rates.items():
            table.append((name, k, r))
    pool.shutdown()
    figures["thread_scaling"] = min(scaling)
    figures["thread_scaling_cpu_bound"] = min(scaling_cpu)
    figures["thread_scaling_projected"] = min(scaling_projected)

    sweep = build_sweep([int(x) for x in args.build_sizes.split(",") if x.strip()], args.repeats)
    one_m = [s for s in sweep if s["triangles"] == 1_000_000]
    if one_m:
        figures["build_1m_s"] = one_m[0]["seconds"]
        figures["build_1m_cpu_s"] = one_m[0]["cpu_seconds"]
    if sweep:
        figures["build_seconds_per_n_log2_n"] = sweep[0]["n_log_n_fit_seconds"] / (
            sweep[0]["triangles"] * math.log2(sweep[0]["triangles"]))

    st = tree.stats
    out = {
        "benchmark": "kdtree",
        "machine": {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
                    "cpus": os.cpu_count(), "threads": threads, "python": platform.python_version(),
                    "warp": wp.__version__,
                    "load_average": {"before": list(load_before), "after": list(os.getloadavg())},
                    **{k: v for k, v in machine_info().items()
                       if k in ("sched_autogroup", "cpu_model", "cpu_family_model", "avx512f", "cache")}},
        "device": "cpu",
        "scene": {"name": f"lumpy icosphere + terrain (subdivisions {args.subdivisions})", "triangles": len(f)},
        "settings": {"size": [width, height], "repeats": args.repeats, "thread_counts": thread_counts},
        "build": {"seconds": build_s, "nodes": st.nodes, "leaves": st.leaves, "empty_leaves": st.empty_leaves,
                  "references": st.references, "depth": st.depth, "sweep": sweep},
        "figures": figures,
    }
    write_results(args.json, out)
    prefix = args.charts or (args.json[:-5] if args.json.endswith(".json") else args.json)
    charts = save_charts(prefix, figures, sweep, thread_counts)

    print(f"\n{len(f):,} triangles; build {build_s:.2f} s ({st.nodes:,} nodes, {st.references:,} refs, "
          f"depth {st.depth}); {threads} threads; load average {load_before[0]:.1f} -> {os.getloadavg()[0]:.1f}")
    print(f"{'rays':<11} {'tracer':<16} {'Mrays/s':>8}")
    for name, k, r in table:
        print(f"{name:<11} {k:<16} {r:8.2f}")
    for k in ("ratio_vs_embree_1t", "ratio_vs_embree_1t_cpu", "ratio_vs_embree_all_threads", "speedup_vs_warp_bvh_1t",
              "speedup_vs_warp_bvh_1t_cpu", "speedup_vs_warp_bvh_all_threads"):
        print(f"{k:<34} incoherent {figures[k]:5.2f}   coherent {figures[k + '_coherent']:5.2f}")
    print(f"thread_scaling (2 threads / 1, worse of the two) {figures['thread_scaling']:.2f}; "
          f"CPU-bound (Σ thread CPU / busiest thread) {figures['thread_scaling_cpu_bound']:.2f}; "
          "one chunk per thread: " + ", ".join(
              f"{k} {figures[k]['thread_scaling_cpu_bound_one_chunk_per_thread']:.2f}" for k in sets))
    print("CPU cost per ray, 1 thread / 2 threads: " + ", ".join(
        f"{k} {figures[k]['thread_cpu_efficiency']:.2f}" for k in sets)
        + f"; projected 2-thread speed-up on an idle machine {figures['thread_scaling_projected']:.2f}")
    print(f"agreement with Embree: coherent {figures['coherent']['agreement_with_embree']:.6f}, "
          f"incoherent {figures['incoherent']['agreement_with_embree']:.6f}")
    if one_m:
        print(f"build of 1M triangles (measured): {figures['build_1m_s']:.2f} s wall, "
              f"{figures['build_1m_cpu_s']:.2f} CPU-s")
    print(f"wrote {args.json}, {', '.join(charts)}")
    return out


if __name__ == "__main__":
    main()

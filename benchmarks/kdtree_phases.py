"""Where one kd-tree query's time goes: each step of ``KdTree.intersect`` timed on its own, for the
benchmark's rays, on 1 thread and on all threads.

    python benchmarks/kdtree_phases.py --json FILE [--size 1280x720] [--subdivisions 6] [--rounds 9]

Rays and scene as in ``bench_kdtree.py`` (coherent camera rays; incoherent random rays from their
hits). The default call is timed as it runs: every Warp launch the query makes through
``serenity.kernels.launch.launch`` is timed by wrapping the kd-tree package's references to it
(``serenity.kernels.kdtree.query``, ``reorder``, ``cpu.sort``; the query itself is not changed),
and so is the counting sort as a whole (``counting_order``: its launches, ``count_keys`` and the
placing passes, plus numpy's prefix sum of the bins). ``other`` is the call's wall time less its
timed parts: the conversion of the numpy inputs, the arrays' allocation, the results' copy back,
Python. Per phase the median over
``--rounds`` calls (after one warm-up call) of its milliseconds per call, and its share of the
call's median. Phases:
- ``sample_key_changes``: whether the batch is coherent (keys of 4096 pairs of consecutive rays);
- ``sort_keys_simd``, ``sort_keys``: each ray's reordering key (16 rays per kernel thread as SIMD
  lanes, the one-ray kernel for the last few); ``counting_order``: the keys' stable order (its
  launches, ``count_keys`` and ``place_keys`` or, on several threads, ``place_low_runs`` and
  ``place_high_runs``, are inside it);
- ``move_in_order``: the rays' origins and directions in that order (one launch per array, 4096
  rays per kernel thread; ``gather_rays`` and ``gather_array`` are read too, for JSON of earlier
  versions of the query);
- ``trace``: the traversal (``trace_packets``, 16-ray packets, for a reordered batch and for a
  coherent one in the caller's order; ``intersect_rays``, one ray per kernel thread, for any other
  batch; ``trace_rays``, for JSON of earlier versions);
- ``scatter_hits``: the four results back at their rays' own indices, as one 16-byte record per ray
  (``scatter_array``, one launch per result array, for JSON of earlier versions).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections import defaultdict
from pathlib import Path

from serenity.device import init_warp
from serenity.io.results import machine_info, write_results
from serenity.kernels.launch import cpu_threads
from serenity.scene.procedural import lumpy_mesh

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_kdtree import ray_sets  # noqa: E402

#: the kernels that are the traversal itself
TRACE_KERNELS = ("trace_rays", "trace_packets", "intersect_rays")
#: the launches made inside counting_order, which is timed as a whole
SORT_PARTS = ("count_keys", "place_keys", "place_low_runs", "place_high_runs")


def phase_name(kernel) -> str:
    key = getattr(kernel, "key", str(kernel))
    for name in TRACE_KERNELS:
        if key.endswith(name):
            return "trace"
    return key


def instrument(modules: list, times: dict) -> None:
    """Wrap each of ``modules``' ``launch`` and ``counting_order`` (where it has them) so that each call
    adds its wall seconds to ``times[phase]`` (the current call's entries)."""

    def timed_launch(launch):
        def run(kernel, *args, **kwargs):
            t = time.perf_counter()
            launch(kernel, *args, **kwargs)
            times[phase_name(kernel)] += time.perf_counter() - t
        return run

    def timed_order(counting_order):
        def run(*args, **kwargs):
            t = time.perf_counter()
            out = counting_order(*args, **kwargs)
            times["counting_order"] += time.perf_counter() - t
            return out
        return run

    for mod in modules:
        if hasattr(mod, "launch"):
            mod.launch = timed_launch(mod.launch)
        if hasattr(mod, "counting_order"):
            mod.counting_order = timed_order(mod.counting_order)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", required=True)
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--subdivisions", type=int, default=6)
    ap.add_argument("--rounds", type=int, default=9)
    args = ap.parse_args(argv)
    init_warp()
    import serenity.kernels.kdtree as kd
    from serenity.kernels.kdtree import query, reorder
    from serenity.kernels.kdtree.cpu import sort

    width, height = (int(x) for x in args.size.lower().split("x"))
    v, f = lumpy_mesh(args.subdivisions)
    tree = kd.KdTree.build(v, f, progress=True)
    sets = ray_sets(tree, width, height)
    current: dict = defaultdict(float)
    instrument([query, reorder, sort], current)
    thread_counts = sorted({1, cpu_threads()})
    results = {}
    for threads in thread_counts:
        for name, (o, d) in sets.items():
            calls = []
            for r in range(args.rounds + 1):  # the first is the warm-up
                current.clear()
                t = time.perf_counter()
                tree.intersect(o, d, device="cpu", threads=threads)
                wall = time.perf_counter() - t
                if r:
                    parts = {k: s for k, s in current.items() if k not in SORT_PARTS}
                    calls.append({"call": wall, **parts, "other": wall - sum(parts.values())})
            call_ms = 1e3 * statistics.median(c["call"] for c in calls)
            phases = {}
            for key in calls[0]:
                if key == "call":
                    continue
                ms = 1e3 * statistics.median(c.get(key, 0.0) for c in calls)
                phases[key] = {"ms": ms, "share": ms / call_ms}
            results[f"{name}_{threads}t"] = {"rays": len(o), "threads": threads, "call_ms": call_ms,
                                             "mrays_per_s": len(o) / call_ms / 1e3, "phases": phases}
            print(f"{name:>10}, {threads} thread(s): {call_ms:6.1f} ms per call", flush=True)
            for key, p in phases.items():
                print(f"{'':>14}{key:<22}{p['ms']:7.2f} ms  {100 * p['share']:5.1f} %", flush=True)
    out = {"benchmark": "kdtree_phases", "triangles": len(f), "size": [width, height], "rounds": args.rounds,
           "timing": "wall ms per call, median over rounds; each phase's median on its own",
           "machine": machine_info(), "results": results}
    write_results(args.json, out)
    return out


if __name__ == "__main__":
    main()

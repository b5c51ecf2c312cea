"""Two-level ray tracing of moving objects (``serenity.kernels.dynamic``) against rebuilding the kd-tree
of the posed scene every frame (the paper's reason for keeping its §9 kd-tree static).

    python benchmarks/bench_dynamic.py [--json benchmarks/results/dynamic_tracing.json] [--frames 7]
                                       [--rebuilds 3] [--quick]

Scene: the courtyard (its static triangles in a ``KdTree``) and moving objects in front of its camera:
spheres of the wanted triangle count (a UV sphere each), turning about their own axes and drifting
every frame. Rays, the same arrays every frame: ``camera`` (the courtyard camera's 320×180 primary
rays) and ``random`` (64k rays from random points in the objects' region, uniform directions).

Per configuration, per frame (medians over ``--frames`` frames after a warm-up frame; ``*_cpu_ms``:
the same calls' CPU seconds of the process, all threads, which a shared machine distorts less):
- ``update_ms``: ``DynamicGeometry.set_transforms`` (the inverse transforms and world boxes on the
  host, the top level's build, their upload; the objects' BVHs are untouched);
- ``extra_ms`` per ray set: the dynamic kernel alone over the kd-tree's hits (``trace_into``, what a
  two-level query adds to the static one), ``extra_any_ms`` the same for any hits (``occlude_into``);
  ``static_ms`` and ``two_level_ms``: the kd-tree's closest-hit query and ``TwoLevelTracer.intersect``
  whole (numpy in and out);
- ``rebuild_ms``: ``KdTree.build`` of the posed scene (the static and the posed dynamic triangles, no
  cache; median of ``--rebuilds`` frames) and ``rebuilt_query_ms`` per ray set: the rebuilt tree's
  closest-hit query — the cost per frame of keeping one kd-tree is rebuild_ms + its query.

Sweeps: dynamic triangles 1k-300k in one object and spread over 10 objects (``triangles``); 1-100
objects of ~1k triangles (``objects``), each with both top levels (``TOP_LEVELS``: ``top_level``
figures: the top level a DynamicGeometry uses by default is the one measured faster); and one
configuration traced static-first (``TwoLevelTracer``) and dynamic-first (the dynamic query, then the
kd-tree with each ray's dynamic hit as its tmax) (``order``). All on the CPU with every thread
(``serenity.kernels.launch``), wall time; the machine is shared, so the figures are indicative.
Writes the JSON (``serenity.io.results.write_results``) and a PNG beside it.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time

import numpy as np

from serenity.device import cpu_threads, init_warp
from serenity.io.results import write_results
from serenity.kernels.dynamic import TOP_LEVELS, DynamicGeometry
from serenity.kernels.kdtree import Hits, KdTree
from serenity.kernels.two_level import TwoLevelTracer
from serenity.scene.procedural import build_scene

_T0 = time.perf_counter()
wp = None  # warp, once main() has initialised it
TRIANGLES = (1_000, 3_000, 10_000, 30_000, 100_000, 300_000)
OBJECTS = (1, 3, 10, 30, 100)
RANDOM_RAYS = 64_000
SIZE = (320, 180)


def say(msg: str) -> None:
    print(f"[bench_dynamic {time.perf_counter() - _T0:7.1f} s] {msg}", flush=True)


def uv_sphere(triangles: int, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """A UV sphere of about ``triangles`` triangles (2·n·(m−1) for n segments and m rings)."""
    rings = max(3, round(math.sqrt(triangles / 4)))
    segments = max(3, round(triangles / (2 * (rings - 1))))
    theta = np.linspace(0, math.pi, rings + 1)[1:-1]
    phi = np.linspace(0, 2 * math.pi, segments, endpoint=False)
    ring = np.stack([np.sin(theta)[:, None] * np.cos(phi), np.repeat(np.cos(theta)[:, None], segments, 1),
                     np.sin(theta)[:, None] * np.sin(phi)], -1).reshape(-1, 3)
    v = np.concatenate([[[0, 1, 0]], ring, [[0, -1, 0]]]) * radius
    j = np.arange(segments)
    faces = [np.stack([np.zeros(segments, int), 1 + (j + 1) % segments, 1 + j], 1)]
    for r in range(rings - 2):
        a, b = 1 + r * segments + j, 1 + r * segments + (j + 1) % segments
        c, d = a + segments, b + segments
        faces += [np.stack([a, b, c], 1), np.stack([b, d, c], 1)]
    last = len(v) - 1
    base = 1 + (rings - 2) * segments
    faces.append(np.stack([np.full(segments, last), base + j, base + (j + 1) % segments], 1))
    return v.astype(np.float32), np.concatenate(faces).astype(np.int32)


class Motion:
    """``count`` objects in front of the camera (centre ``centre``, spread over ``spread`` m), each
    turning about its own axis and drifting on a small circle: :meth:`at` gives frame k's (count,4,4)."""

    def __init__(self, count: int, centre: np.ndarray, spread: float, seed: int = 0):
        rng = np.random.default_rng(seed)
        self.base = centre + rng.uniform(-1, 1, (count, 3)) * (spread, 0.3 * spread, spread)
        self.base[:, 1] = np.maximum(self.base[:, 1], 1.0)
        axes = rng.normal(size=(count, 3))
        self.axes = axes / np.linalg.norm(axes, axis=1, keepdims=True)
        self.phase = rng.uniform(0, 2 * math.pi, count)

    def at(self, frame: int) -> np.ndarray:
        m = np.tile(np.eye(4), (len(self.base), 1, 1))
        for k, (axis, phase) in enumerate(zip(self.axes, self.phase, strict=True)):
            a = 0.15 * frame + phase
            x = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
            m[k, :3, :3] = np.eye(3) + math.sin(a) * x + (1 - math.cos(a)) * (x @ x)  # Rodrigues
            m[k, :3, 3] = self.base[k] + 0.3 * np.array([math.cos(a), 0.0, math.sin(a)])
        return m


def measure(static, tree: KdTree, rays: dict, objects: list, motion: Motion, frames: int, rebuilds: int,
            top_level: str = "bvh", order: bool = False) -> dict:
    """One configuration's per-frame figures (module docstring)."""
    dyn = DynamicGeometry("cpu", top_level=top_level)
    for v, f in objects:
        dyn.add(v, f)
    two = TwoLevelTracer(tree, dyn)
    wrays = {name: [wp.array(a, dtype=wp.vec3, device="cpu") for a in od] for name, od in rays.items()}
    base = {name: tree.intersect(o, d, np.inf, "cpu") for name, (o, d) in wrays.items()}  # the static hits
    base_occ = {name: tree.occluded(o, d, np.inf, "cpu") for name, (o, d) in wrays.items()}
    prim_base = len(static[1])
    rows: dict[str, list] = {"update_ms": []}

    def timed(key: str, fn, *args) -> None:
        c0, t0 = time.process_time(), time.perf_counter()
        fn(*args)
        rows.setdefault(key, []).append(1e3 * (time.perf_counter() - t0))
        rows.setdefault(key.replace("_ms", "_cpu_ms"), []).append(1e3 * (time.process_time() - c0))

    for frame in range(frames + 1):  # frame 0: warm-up (compilation, first touch)
        t0 = time.perf_counter()
        dyn.set_transforms(motion.at(frame))
        update = time.perf_counter() - t0
        if frame:
            rows["update_ms"].append(1e3 * update)
        for name, (o, d) in rays.items():
            wo, wd = wrays[name]
            hits = Hits(*(wp.clone(a) for a in (base[name].t, base[name].prim, base[name].u, base[name].v)))
            occ = wp.clone(base_occ[name])
            if not frame:
                dyn.trace_into(hits, wo, wd, np.inf, 0.0, prim_base)
                dyn.occlude_into(occ, wo, wd, np.inf, 0.0)
                two.intersect(o, d)
                two.occluded(o, d)
                continue
            timed(f"{name}.extra_ms", dyn.trace_into, hits, wo, wd, np.inf, 0.0, prim_base)
            timed(f"{name}.extra_any_ms", dyn.occlude_into, occ, wo, wd, np.inf, 0.0)
            timed(f"{name}.static_ms", tree.intersect, o, d)
            timed(f"{name}.two_level_ms", two.intersect, o, d)
            if order:
                timed(f"{name}.dynamic_first_ms", dynamic_first, tree, dyn, o, d, prim_base)
    out = {k: statistics.median(v) for k, v in rows.items()}
    for name in rays:
        hits = two.intersect(*rays[name])
        out[f"{name}.dynamic_hit_share"] = float(np.mean(hits.prim >= prim_base))
    if rebuilds:
        build, query = [], {name: [] for name in rays}
        for frame in range(1, rebuilds + 1):
            dyn.set_transforms(motion.at(frame))
            pv, pf = dyn.posed_triangles()
            v = np.concatenate([static[0], pv])
            f = np.concatenate([static[1], pf + len(static[0])])
            t0 = time.perf_counter()
            posed = KdTree.build(v, f, cache=False, progress=False)
            build.append(1e3 * (time.perf_counter() - t0))
            for name, (o, d) in rays.items():
                posed.intersect(o, d)  # first touch of the new tree's device arrays: part of a rebuild
                t0 = time.perf_counter()
                posed.intersect(o, d)
                query[name].append(1e3 * (time.perf_counter() - t0))
        out["rebuild_ms"] = statistics.median(build)
        for name in rays:
            out[f"{name}.rebuilt_query_ms"] = statistics.median(query[name])
    out["objects"] = len(objects)
    out["triangles"] = int(sum(len(f) for _, f in objects))
    out["top_level"] = top_level
    return out


def dynamic_first(tree: KdTree, dyn: DynamicGeometry, o, d, prim_base: int):
    """The other order: the dynamic query, then the kd-tree with each ray's dynamic hit as its tmax
    (a per-ray tmax, which the kd-tree reorders with its rays), merged."""
    first = dyn.intersect(o, d)
    rest = tree.intersect(o, d, first.t)
    prim = np.where(rest.prim >= 0, rest.prim, np.where(first.prim >= 0, first.prim + prim_base, -1))
    return np.where(rest.prim >= 0, rest.t, first.t), prim


def chart(results: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    ax = axes[0]
    for layout, style in (("one_object", "-"), ("ten_objects", "--")):
        rows = results["triangles"][layout]
        tris = [r["triangles"] for r in rows]
        ax.plot(tris, [r["update_ms"] for r in rows], style, marker="o", color="C0",
                label=f"top-level update ({layout.replace('_', ' ')})")
        ax.plot(tris, [r["camera.extra_ms"] for r in rows], style, marker="s", color="C1",
                label=f"extra traversal, camera rays ({layout.replace('_', ' ')})")
        ax.plot(tris, [r["random.extra_ms"] for r in rows], style, marker="^", color="C2",
                label=f"extra traversal, 64k random ({layout.replace('_', ' ')})")
        ax.plot(tris, [r["rebuild_ms"] for r in rows], style, marker="x", color="C3",
                label=f"full kd-tree rebuild ({layout.replace('_', ' ')})")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("dynamic triangles")
    ax.set_ylabel("ms per frame")
    ax.set_title("Per-frame cost vs dynamic triangles")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6.5)
    ax = axes[1]
    for top, style in zip(TOP_LEVELS, ("-", ":"), strict=True):
        rows = results["objects"][top]
        n = [r["objects"] for r in rows]
        ax.plot(n, [r["update_ms"] for r in rows], style, marker="o", color="C0", label=f"update ({top})")
        ax.plot(n, [r["camera.extra_ms"] for r in rows], style, marker="s", color="C1",
                label=f"extra traversal, camera ({top})")
        ax.plot(n, [r["random.extra_ms"] for r in rows], style, marker="^", color="C2",
                label=f"extra traversal, random ({top})")
    rows = results["objects"]["bvh"]
    ax.plot([r["objects"] for r in rows], [r["rebuild_ms"] for r in rows], marker="x", color="C3",
            label="full kd-tree rebuild")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("objects (~1k triangles each)")
    ax.set_ylabel("ms per frame")
    ax.set_title("Per-frame cost vs object count")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6.5)
    fig.suptitle(f"Two-level ray tracing vs kd-tree rebuild (courtyard, CPU, {cpu_threads()} threads)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"wrote {path}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default="benchmarks/results/dynamic_tracing.json")
    ap.add_argument("--frames", type=int, default=7, help="timed frames per configuration (median)")
    ap.add_argument("--rebuilds", type=int, default=3, help="timed kd-tree rebuilds per configuration")
    ap.add_argument("--quick", action="store_true", help="fewer sizes and frames: a check that it runs")
    args = ap.parse_args(argv)
    global wp
    wp = init_warp()
    scene = build_scene("courtyard")
    pos, _, _, faces, _ = scene.merged()
    static = (pos, faces)
    tree = KdTree.build(pos, faces, cache=False, progress=False)
    rng = np.random.default_rng(0)
    cam = scene.camera
    centre = np.asarray(cam.position, np.float64) + 12.0 * np.asarray(cam.forward, np.float64)
    o_rand = (centre + rng.uniform(-6, 6, (RANDOM_RAYS, 3)) * (1, 0.25, 1)).astype(np.float32)
    o_rand[:, 1] = np.clip(o_rand[:, 1], 0.1, None)
    d_rand = rng.normal(size=(RANDOM_RAYS, 3)).astype(np.float32)
    d_rand /= np.linalg.norm(d_rand, axis=1, keepdims=True)
    rays = {"camera": cam.primary_rays(*SIZE), "random": (o_rand, d_rand)}
    tri_sizes = TRIANGLES[:3] if args.quick else TRIANGLES
    counts = OBJECTS[:3] if args.quick else OBJECTS
    frames = 2 if args.quick else args.frames
    rebuilds = 1 if args.quick else args.rebuilds
    results: dict = {"triangles": {"one_object": [], "ten_objects": []}, "objects": {t: [] for t in TOP_LEVELS}}
    for tris in tri_sizes:
        for layout, count in (("one_object", 1), ("ten_objects", 10)):
            radius = 1.5 if count == 1 else 0.6
            objects = [uv_sphere(tris // count, radius) for _ in range(count)]
            row = measure(static, tree, rays, objects, Motion(count, centre, 0.0 if count == 1 else 4.0), frames,
                          rebuilds)
            results["triangles"][layout].append(row)
            say(f"{layout} {row['triangles']:7d} triangles: update {row['update_ms']:.2f} ms, extra camera "
                f"{row['camera.extra_ms']:.1f} / random {row['random.extra_ms']:.1f} ms, rebuild "
                f"{row['rebuild_ms']:.0f} ms")
    for count in counts:
        objects = [uv_sphere(1000, 0.4) for _ in range(count)]
        for top in TOP_LEVELS:
            row = measure(static, tree, rays, objects, Motion(count, centre, 5.0, seed=1), frames,
                          rebuilds if top == "bvh" else 0, top_level=top)
            results["objects"][top].append(row)
            say(f"{count:3d} objects, {top:6s}: update {row['update_ms']:.2f} ms, extra camera "
                f"{row['camera.extra_ms']:.1f} / random {row['random.extra_ms']:.1f} ms")
    objects = [uv_sphere(10_000, 0.6) for _ in range(10)]
    results["order"] = measure(static, tree, rays, objects, Motion(10, centre, 4.0), frames, 0, order=True)
    faster = {t: sum(r["camera.extra_ms"] + r["random.extra_ms"] + r["update_ms"] for r in results["objects"][t])
              for t in TOP_LEVELS}
    results["top_level_faster"] = min(faster, key=faster.get)
    results["settings"] = {"scene": "courtyard", "static_triangles": int(len(faces)), "camera_rays": SIZE,
                           "random_rays": RANDOM_RAYS, "frames": frames, "rebuilds": rebuilds,
                           "threads": cpu_threads(), "device": "cpu", "quick": bool(args.quick)}
    write_results(args.json, results)
    chart(results, args.json.removesuffix(".json") + ".png")
    return 0


if __name__ == "__main__":
    sys.exit(main())

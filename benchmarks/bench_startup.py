"""`serenity render` of a big scene as a fresh process, with empty and with warm scene caches: the
seconds, the peak resident memory of the renderer and of its tracer process, and where the time goes.

    python benchmarks/bench_startup.py [--scene scenes/breakfast_room/breakfast_room.toml]
        [--size 640x360] [--runs 3] [--json FILE]

Each run is a fresh process with ``SERENITY_CACHE`` pointing at a folder of its own: a cold run
starts from an empty folder (no kd-tree, no traced probes, no lit volume; Warp's kernel cache stays
warm), a warm run reads the folder its cold run left. ``--runs`` pairs of plain ``serenity render``
runs give the seconds (wall clock from the spawn to the exit, Python's start-up and imports
included) and the peak resident set of the whole tree of processes (``wait4``: the larger of the
renderer and its tracer process; what ``/usr/bin/time -v`` reports) and the last frame's
milliseconds. One more cold and warm pair runs the same command in an instrumented process (this
script's ``--child``): the phases (imports, scene load, the renderer's set-up, the kd-tree, the
probes' rays, the passes, the frames, the outputs), each with its seconds, its CPU seconds (the
renderer process's threads, not its tracer process's: on a shared machine a steadier measure of the
work than the seconds) and the resident memory after it, and each process's own peak (the tracer
process's read from its ``VmHWM`` before it stops).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

DEFAULT_SCENE = "scenes/breakfast_room/breakfast_room.toml"


def _render_args(scene: str, size: str, out: Path) -> list[str]:
    return ["render", scene, "--size", size, "-o", str(out / "x.png"), "--json", str(out / "render.json")]


def _spawn(argv: list[str], cache: Path) -> tuple[float, float, int]:
    """(seconds from the spawn to the exit, peak RSS in MB of the process tree, exit status)."""
    env = {**os.environ, "SERENITY_CACHE": str(cache)}
    with tempfile.TemporaryFile() as log:
        t0 = time.perf_counter()
        proc = subprocess.Popen(argv, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=log)
        _, status, usage = os.wait4(proc.pid, 0)
        seconds = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        log.seek(0)
        err = log.read().decode(errors="replace")
    if proc.returncode != 0:
        raise SystemExit(f"bench_startup: {' '.join(argv)} failed ({proc.returncode}):\n{err[-2000:]}")
    return seconds, usage.ru_maxrss / 1024.0, proc.returncode


def plain_run(scene: str, size: str, cache: Path, out: Path) -> dict:
    seconds, peak, _ = _spawn([sys.executable, "-m", "serenity", *_render_args(scene, size, out)], cache)
    report = json.loads((out / "render.json").read_text())
    return {"seconds": seconds, "peak_rss_mb": peak, "frame_ms": report["frame_ms"]}


def instrumented_run(scene: str, size: str, cache: Path, out: Path) -> dict:
    path = out / "phases.json"
    t0 = time.perf_counter()
    seconds, peak, _ = _spawn([sys.executable, str(Path(__file__).resolve()), "--child", str(path), "--",
                               *_render_args(scene, size, out)], cache)
    data = json.loads(path.read_text())
    data["python_start_s"] = data.pop("entered") - t0  # the interpreter's own start, before this script's first line
    data["seconds"], data["peak_rss_mb"] = seconds, peak
    return data


# ------------------------------------------------------------------------- the instrumented process


def child(path: str, argv: list[str]) -> None:
    """Run ``serenity`` with ``argv``, timing its phases (module docstring) into ``path``."""
    entered = time.perf_counter()
    import functools
    import resource
    import threading

    rss = {"now": 0.0, "peak": 0.0}

    def poll() -> None:
        page = os.sysconf("SC_PAGE_SIZE")
        while True:
            with open("/proc/self/statm") as f:
                now = int(f.read().split()[1]) * page / 2**20
            rss["now"], rss["peak"] = now, max(rss["peak"], now)
            time.sleep(0.01)

    if os.path.exists("/proc/self/statm"):
        threading.Thread(target=poll, daemon=True).start()
    phases = []

    def mark(name: str, t0: float, depth: int, c0: float) -> None:
        phases.append({"phase": name, "start_s": t0 - entered, "seconds": time.perf_counter() - t0,
                       "cpu_s": time.process_time() - c0, "rss_mb": rss["now"], "depth": depth})

    t0, c0 = time.perf_counter(), time.process_time()
    import serenity.cli
    import serenity.commands.render  # noqa: F401 - what `serenity render` imports, timed here
    import serenity.frame
    import serenity.io.exr
    import serenity.io.png
    import serenity.kernels.probegather as pg
    import serenity.kernels.raytrace as rt
    import serenity.kernels.skygather as sg
    import serenity.kernels.tracer_process as tp
    import serenity.raster.scene_gl as scene_gl
    import serenity.scene

    mark("imports", t0, 0, c0)
    depth = [0]

    def timed(owner, attr: str, name: str) -> None:
        fn = getattr(owner, attr)

        @functools.wraps(fn)
        def wrapper(*a, **k):
            t, c = time.perf_counter(), time.process_time()
            depth[0] += 1
            try:
                return fn(*a, **k)
            finally:
                depth[0] -= 1
                mark(name, t, depth[0], c)

        setattr(owner, attr, wrapper)

    timed(serenity.scene, "load", "scene load")
    timed(serenity.frame.Renderer, "__init__", "renderer set-up")
    timed(tp.TracerProcess, "__init__", "tracer process start")
    timed(tp.TracerProcess, "result", "wait for the tracer process")
    timed(rt.RayTracer, "__init__", "ray tracer (kd-tree)")
    timed(scene_gl, "scene_levels", "levels of detail")
    timed(pg.ProbeGather, "_build", "probe rays (trace, surfels, moments)")
    timed(pg.ProbeGather, "_load", "probe cache read")
    timed(pg.ProbeGather, "gather", "probe gathers")
    timed(pg.ProbeGather, "update_surfels", "surfel updates")
    timed(pg.ProbeGather, "update_visibility", "surfel shadow rays")
    timed(sg.GatherMethod, "_update", "sky volume (gather)")
    timed(serenity.frame.Renderer, "render", "frame")
    timed(serenity.frame.Renderer, "close", "close (tracer process stops)")
    timed(serenity.io.png, "write_png", "write PNG")
    timed(serenity.io.exr, "write_exr", "write EXR")
    tracer = {}
    close = tp.TracerProcess.close

    def close_and_note(self):
        tracer["build_s"] = self.build_seconds
        try:  # the child's own high-water mark (its rusage would count the memory it was forked with)
            with open(f"/proc/{self._proc.pid}/status") as f:
                tracer["peak_rss_mb"] = next(int(line.split()[1]) / 1024.0 for line in f if line.startswith("VmHWM"))
        except (OSError, StopIteration):
            pass
        close(self)

    tp.TracerProcess.close = close_and_note
    t0, c0 = time.perf_counter(), time.process_time()
    status = serenity.cli.main(argv)
    mark("serenity render (all)", t0, 0, c0)
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    with open(path, "w") as f:
        json.dump({"entered": entered, "status": status, "phases": phases, "renderer_peak_rss_mb": own,
                   "tracer_peak_rss_mb": tracer.get("peak_rss_mb"), "tracer_build_s": tracer.get("build_s")}, f)


def summarise(phases: list[dict]) -> dict[str, dict]:
    """Seconds and CPU seconds (the process's threads) per phase name, summed over calls, and the calls."""
    out: dict[str, dict] = {}
    for p in phases:
        s = out.setdefault(p["phase"], {"seconds": 0.0, "cpu_s": 0.0, "calls": 0, "depth": p["depth"]})
        s["seconds"] += p["seconds"]
        s["cpu_s"] += p.get("cpu_s", 0.0)
        s["calls"] += 1
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=DEFAULT_SCENE)
    ap.add_argument("--size", default="640x360")
    ap.add_argument("--runs", type=int, default=3, help="cold + warm pairs of plain runs (default %(default)s)")
    ap.add_argument("--json", default=str(ROOT / "benchmarks/results/startup.json"))
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args, rest = ap.parse_known_args()
    if args.child:
        child(args.child, [a for a in rest if a != "--"])
        return
    from serenity.io.results import write_results

    plain = {"cold": [], "warm": []}
    with tempfile.TemporaryDirectory(prefix="serenity-startup-") as tmp:
        for i in range(args.runs):
            cache, out = Path(tmp) / f"cache{i}", Path(tmp) / f"out{i}"
            cache.mkdir()
            out.mkdir()
            for kind in ("cold", "warm"):
                r = plain_run(args.scene, args.size, cache, out)
                plain[kind].append(r)
                print(f"{kind} run {i + 1}: {r['seconds']:.1f} s, peak {r['peak_rss_mb']:.0f} MB, "
                      f"frame {r['frame_ms']:.0f} ms", flush=True)
        cache, out = Path(tmp) / "cache-phases", Path(tmp) / "out-phases"
        cache.mkdir()
        out.mkdir()
        phases = {kind: instrumented_run(args.scene, args.size, cache, out) for kind in ("cold", "warm")}
    summary = {}
    for kind, runs in plain.items():
        summary[kind] = {k: {"median": float(np.median([r[k] for r in runs])), "min": float(min(r[k] for r in runs)),
                             "max": float(max(r[k] for r in runs))} for k in ("seconds", "peak_rss_mb", "frame_ms")}
    for kind, d in phases.items():
        d["by_phase"] = summarise(d["phases"])
        print(f"\n{kind} (instrumented): {d['seconds']:.1f} s; Python start {d['python_start_s']:.2f} s; "
              f"renderer peak {d['renderer_peak_rss_mb']:.0f} MB, tracer process peak {d['tracer_peak_rss_mb']:.0f} MB")
        for name, s in d["by_phase"].items():
            print(f"  {'  ' * s['depth']}{name:40s} {s['seconds']:6.2f} s  cpu {s['cpu_s']:6.2f} s  x{s['calls']}")
    write_results(args.json, {"scene": args.scene, "size": args.size, "quality": "traced-probes", "runs": args.runs,
                              "plain": plain, "summary": summary, "phases": phases,
                              "command": " ".join([Path(sys.executable).name, *sys.argv])})


if __name__ == "__main__":
    main()

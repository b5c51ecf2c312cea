"""Where a frame's CPU time goes, thread by thread: llvmpipe's rasteriser threads, the main thread,
the volume worker, Warp's launch threads and the tracer process.

    python benchmarks/bench_frame_threads.py [--sizes 320x180,640x360] [--frames 60] [--json FILE]

One ``lpv-fast`` renderer per schedule (overlapped, serial) along ``serenity bench``'s camera path
with the sun moving, 6 warm-up frames, then ``--frames`` frames. Before and after them, every
thread's CPU time is read from ``/proc/self/task/*/stat`` (and the tracer process's from its own
``/proc/PID/task``), so each thread's CPU-ms per frame is its difference divided by the frames.
Threads are grouped by what runs on them: llvmpipe names its rasteriser threads (``llvmpipe-N``);
Python's threads are told apart by their native ids (the main thread, the ``serenity-volumes``
worker, the ``serenity-launch`` pool that splits Warp's CPU launches). Reported per group: CPU-ms
per frame and its share of the frame's CPU time, beside the median wall time of a frame.

The point is the bound on what the overlap can buy: a frame's CPU time divided by the cores
is the wall time no schedule can beat, and what the GL passes cost on llvmpipe's threads is what
no overlap can hide. Linux only (``/proc``).
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from serenity.io.results import machine_info, write_results  # noqa: E402

TICK_MS = 1000.0 / os.sysconf("SC_CLK_TCK")
GROUPS = ("llvmpipe rasteriser threads", "main thread", "volume worker", "Warp launch threads",
          "tracer process", "other threads")


def thread_cpu_ms(pid: int | str = "self") -> dict[int, tuple[str, float]]:
    """{thread id: (its name, CPU ms so far)} of process ``pid``."""
    out = {}
    base = f"/proc/{pid}/task"
    for tid in os.listdir(base):
        try:
            with open(f"{base}/{tid}/stat") as f:
                stat = f.read()
        except OSError:  # the thread ended meanwhile
            continue
        name = stat[stat.index("(") + 1:stat.rindex(")")]
        fields = stat[stat.rindex(")") + 2:].split()
        out[int(tid)] = (name, (int(fields[11]) + int(fields[12])) * TICK_MS)  # utime, stime
    return out


def group_of(name: str, tid: int, python_names: dict[int, str]) -> str:
    if name.startswith("llvmpipe"):
        return GROUPS[0]
    py = python_names.get(tid)
    if py == "MainThread":
        return GROUPS[1]
    if py is not None and py.startswith("serenity-volumes"):
        return GROUPS[2]
    if py is not None and py.startswith("serenity-launch"):
        return GROUPS[3]
    return GROUPS[5]


def measure(width: int, height: int, frames: int, overlap: bool) -> dict:
    from serenity.bench import camera_path, sun_path
    from serenity.config import RenderConfig, ScheduleConfig
    from serenity.frame import Renderer
    from serenity.scene import load

    scene = load("courtyard")
    cam0, sun0 = scene.camera, np.asarray(scene.sun.direction, np.float64).copy()
    r = Renderer(scene, width, height, config=RenderConfig.preset("lpv-fast", schedule=ScheduleConfig(overlap=overlap)))

    def step(i: int) -> float:
        t = (i % 48) / 47
        scene.camera, scene.sun.direction = camera_path(cam0, t), sun_path(sun0, t)
        return r.render(read_back=False).wall_ms

    try:
        for i in range(6):
            step(i)
        proc = getattr(r, "_tracer_proc", None)
        child = proc._proc.pid if proc is not None and getattr(proc, "_proc", None) is not None else None
        before, before_child = thread_cpu_ms(), thread_cpu_ms(child) if child else {}
        t0 = time.perf_counter()
        walls = [step(6 + i) for i in range(frames)]
        elapsed = time.perf_counter() - t0
        after, after_child = thread_cpu_ms(), thread_cpu_ms(child) if child else {}
        python_names = {t.native_id: t.name for t in threading.enumerate()}
    finally:
        r.close()
    per_group = dict.fromkeys(GROUPS, 0.0)
    for tid, (name, ms) in after.items():
        per_group[group_of(name, tid, python_names)] += ms - before.get(tid, (name, 0.0))[1]
    for tid, (_, ms) in after_child.items():
        per_group[GROUPS[4]] += ms - before_child.get(tid, ("", 0.0))[1]
    total = sum(per_group.values())
    cpu = {g: v / frames for g, v in per_group.items()}
    return {"overlap": overlap, "frames": frames, "frame_ms_median": float(np.median(walls)),
            "frame_ms_mean": elapsed * 1e3 / frames, "cpu_ms_per_frame": cpu,
            "cpu_ms_per_frame_total": total / frames,
            "share": {g: (v / total if total > 0 else 0.0) for g, v in per_group.items()},
            "cores_busy": (total / frames) / (elapsed * 1e3 / frames), "tick_ms": TICK_MS}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="320x180,640x360")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--json", default=str(ROOT / "benchmarks/results/frame_threads.json"))
    args = ap.parse_args(argv)
    if not os.path.isdir("/proc/self/task"):
        raise SystemExit("bench_frame_threads.py reads /proc/self/task: Linux only")
    out = {"benchmark": "frame_threads", "command": " ".join(["python", *sys.argv]), "machine": machine_info(),
           "quality": "lpv-fast", "sizes": {}}
    for size in args.sizes.split(","):
        w, h = (int(v) for v in size.lower().split("x"))
        res = out["sizes"][size] = {s: measure(w, h, args.frames, s == "overlapped") for s in ("overlapped", "serial")}
        for s, m in res.items():
            parts = ", ".join(f"{g} {m['cpu_ms_per_frame'][g]:.1f} ({100 * m['share'][g]:.0f} %)" for g in GROUPS)
            print(f"{size} {s}: frame {m['frame_ms_mean']:.1f} ms (mean), {m['cpu_ms_per_frame_total']:.1f} CPU-ms "
                  f"({m['cores_busy']:.2f} cores busy): {parts}")
    write_results(args.json, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

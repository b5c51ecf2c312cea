"""Viewer: what a displayed frame costs beyond ``Renderer.render``, and what the
per-frame read-back the viewer avoids would cost.

    python benchmarks/bench_view.py [--json FILE] [--size WxH] [--frames N] [--scene NAME]

Runs ``serenity view SCENE --script`` (a still camera for ``--frames`` frames, panel shown) in a
subprocess under ``xvfb-run`` (or the current ``DISPLAY``) with ``--trace``, twice: as it starts
(the still view accumulating temporal anti-aliasing samples: a jittered frame and one more
fullscreen pass per frame) and with ``--taa 0``; then, in this process on the headless EGL context,
the same scene and size with ``Renderer.render(read_back=True)``.

Keys (medians over the frames after the first two; all milliseconds):
- ``view_render_ms``: ``Frame.wall_ms`` of the viewer's frames (``render(read_back=False)``).
- ``view_loop_ms``: the viewer's full frame period (script input, render, present, panel, swap).
- ``view_overhead_ms``: ``loop - render`` of the same frame; ``view_overhead_ratio``: overhead / loop.
- ``no_taa``: the same three for the run with ``--taa 0`` (``taa_samples`` of each run's last frame).
  It runs first; on a machine shared with other jobs the first viewer process renders slower (warm-up),
  so compare the two runs' overheads, not their render times.
- ``readback_ms``: the ``readback`` stage of ``render(read_back=True)`` (HDR, LDR, AOVs), which the
  viewer does not pay; ``offscreen_render_ms``: that frame's ``wall_ms``.
Timings are wall clock on whatever machine runs it (see ``machine``); on a shared machine they are
noisy, the ratios less so.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def viewer_trace(scene: str, size: str, frames: int, taa: list[str] = ()) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        script = os.path.join(tmp, "still.toml")
        with open(script, "w") as f:
            f.write(f'[[step]]\nframe = {frames}\nexit = true\n')
        xvfb = shutil.which("xvfb-run")
        prefix = [xvfb, "-a", "-s", "-screen 0 1920x1080x24"] if xvfb else []
        if not prefix and not os.environ.get("DISPLAY"):
            sys.exit("bench_view: needs xvfb-run or a DISPLAY")
        trace = os.path.join(tmp, "trace.json")
        env = {**os.environ, "PYTHONPATH": ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")}
        subprocess.run(prefix + [sys.executable, "-m", "serenity", "view", scene, "--size", size, "--script", script,
                                 "--trace", trace, *taa], check=True, env=env, cwd=tmp, stdout=subprocess.DEVNULL)
        with open(trace) as f:
            return json.load(f)


def offscreen(scene_name: str, width: int, height: int, frames: int) -> tuple[list[float], list[float]]:
    from serenity.frame import Renderer
    from serenity.scene import load

    r = Renderer(load(scene_name), width, height)
    walls, reads = [], []
    for _ in range(frames):
        fr = r.render(read_back=True)
        walls.append(fr.wall_ms)
        reads.append(fr.timings["readback"])
    r.close()
    return walls[2:], reads[2:]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default=os.path.join(ROOT, "benchmarks", "results", "view.json"))
    ap.add_argument("--size", default="320x180")
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--scene", default="courtyard")
    args = ap.parse_args()
    from serenity.commands.common import parse_size
    from serenity.io.results import write_results

    w, h = parse_size(args.size)
    runs = {}
    for name, extra in (("no_taa", ["--taa", "0"]), ("taa", [])):
        t = viewer_trace(args.scene, args.size, args.frames, extra)
        fr = t["frames"][2:]
        render = np.array([f["wall_ms"] for f in fr[:-1]])
        loop = np.array([f["loop_ms"] for f in fr[1:]])  # frame i's period is measured at frame i + 1
        runs[name] = {"view_render_ms": float(np.median(render)), "view_loop_ms": float(np.median(loop)),
                      "view_overhead_ms": float(np.median(loop - render)),
                      "view_overhead_ratio": float(np.median((loop - render) / loop)),
                      "taa_samples": t["frames"][-1]["taa_samples"]}
    walls, reads = offscreen(args.scene, w, h, args.frames)
    out = {
        "scene": args.scene, "size": [w, h], "frames": args.frames, **runs["taa"], "no_taa": runs["no_taa"],
        "readback_ms": float(np.median(reads)), "offscreen_render_ms": float(np.median(walls)),
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                    "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None},
    }
    print(json.dumps(out, indent=1))
    write_results(args.json, out)


if __name__ == "__main__":
    main()

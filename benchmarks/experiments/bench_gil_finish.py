"""Does a Python thread issuing Warp launches keep going while the main thread waits for GL?

    python benchmarks/experiments/bench_gil_finish.py [--json FILE]

A worker thread runs small Warp CPU launches (each followed by a little numpy) in a loop while the
main thread draws a fragment-bound fullscreen pass and waits for it, either through moderngl's
``ctx.finish()`` (which holds the GIL while llvmpipe renders) or through
``serenity.raster.context.finish`` (glFinish through ctypes, which releases it). Reported: the
worker's launches per second in each case and alone, and the pass's milliseconds. This is why the
frame's volume worker (``ScheduleConfig.overlap_volumes``) can overlap the GL passes at all.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from serenity.io.results import write_results  # noqa: E402
from serenity.kernels.launch import init_warp  # noqa: E402
from serenity.raster.context import (  # noqa: E402
    compile_program,
    expand_includes,
    finish,
    fullscreen_vao,
    get_context,
)

PASS = """#include "fullscreen.glsl"
#if defined FRAGMENT_SHADER
out vec4 o_colour;
void main() {
    float s = 0.0;
    for (int i = 0; i < 400; ++i) s += sin(gl_FragCoord.x * 0.01 + float(i));
    o_colour = vec4(s);
}
#endif
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--passes", type=int, default=40)
    ap.add_argument("--json", default=str(ROOT / "benchmarks/experiments/results/gil_finish.json"))
    args = ap.parse_args()
    wp = init_warp()

    @wp.kernel
    def busy(a: wp.array(dtype=float)):
        i = wp.tid()
        s = float(0.0)
        for j in range(200):
            s += wp.sin(float(i + j))
        a[i] = s

    ctx = get_context()
    prog = compile_program(ctx, expand_includes(PASS), "bench_gil_finish")
    vao = fullscreen_vao(ctx, prog)
    fbo = ctx.framebuffer([ctx.texture((320, 180), 4, dtype="f4")])
    a = wp.zeros(2000, dtype=float, device="cpu")
    wp.launch(busy, dim=2000, inputs=[a], device="cpu")

    def worker(stop, out):
        n = 0
        while not stop.is_set():
            wp.launch(busy, dim=2000, inputs=[a], device="cpu")
            float(np.sum(a.numpy()))
            n += 1
        out.append(n)

    def run(wait) -> dict:
        stop, out = threading.Event(), []
        t = threading.Thread(target=worker, args=(stop, out))
        t.start()
        t0 = time.perf_counter()
        for _ in range(args.passes):
            fbo.use()
            vao.render(vertices=3)
            wait()
        dt = time.perf_counter() - t0
        stop.set()
        t.join()
        return {"pass_ms": dt * 1e3 / args.passes, "worker_launches_per_s": out[0] / dt}

    results: dict = {"moderngl_finish": [], "ctypes_finish": []}
    for _ in range(2):  # in turns: the machine's drift falls on both
        results["moderngl_finish"].append(run(ctx.finish))
        results["ctypes_finish"].append(run(lambda: finish(ctx)))
    stop, out = threading.Event(), []
    t = threading.Thread(target=worker, args=(stop, out))
    t.start()
    time.sleep(0.5)
    stop.set()
    t.join()
    results["worker_alone_launches_per_s"] = out[0] / 0.5
    for k in ("moderngl_finish", "ctypes_finish"):
        runs = (f"pass {r['pass_ms']:.1f} ms, worker {r['worker_launches_per_s']:.0f}/s" for r in results[k])
        print(k, ", ".join(runs))
    print(f"worker alone: {results['worker_alone_launches_per_s']:.0f}/s")
    write_results(args.json, results)


if __name__ == "__main__":
    main()

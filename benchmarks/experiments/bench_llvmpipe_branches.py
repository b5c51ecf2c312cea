"""What a branch saves on llvmpipe: the cost of a full-screen fragment shader whose expensive part sits
behind a condition that no pixel, half the pixels or every pixel takes.

    python benchmarks/experiments/bench_llvmpipe_branches.py [--size 640x360] [--reps 15] [--json FILE]

The deferred passes are written for this rasteriser (``docs/architecture.md``, GL passes): it shades a
block of pixels as SIMD lanes under an execution mask, so which code a block skips decides what a pass
costs. Each body does 12 steps of one kind of work; each is timed (median of ``--reps`` draws of a
full-screen triangle into an RGBA32F target, ``finish()`` before and after; the shader is
``benchmarks/glsl/llvmpipe_branches.glsl``) as

- ``always``: no condition;
- ``if_none``: inside ``if`` on a uniform no pixel satisfies;
- ``if_half``: inside ``if`` on the pixel's x (the right half of the screen takes it);
- ``return_all``: after an early ``return`` that every pixel takes (a uniform condition);
- ``loop_none``: inside a loop whose run-time trip count is 0 for every pixel;

and ``none`` is the shader without the body. Bodies: ``taps_unrolled`` (12 texture taps in a loop of
compile-time length, which the compiler unrolls), ``taps_dynamic`` (the same loop with a run-time
trip count, ``12 + u_zero``: not unrolled), ``alu_unrolled`` (12 steps of arithmetic, unrolled).
Writes the milliseconds per (body, placement) and, per body, the fraction of ``always`` that each
placement costs above ``none``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)

from serenity.io.results import write_results  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
SHADER = os.path.join(HERE, "glsl", "llvmpipe_branches.glsl")

#: body name -> BODY in the shader (12 steps of one kind of work)
BODIES = {"taps_unrolled": 0, "taps_dynamic": 1, "alu_unrolled": 2}
#: placement name -> PLACEMENT in the shader
PLACEMENTS = {"none": 0, "always": 1, "if_none": 2, "if_half": 3, "return_all": 4, "loop_none": 5}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", default="640x360")
    ap.add_argument("--reps", type=int, default=15)
    ap.add_argument("--json", default=os.path.join(HERE, "results", "llvmpipe_branches.json"))
    args = ap.parse_args(argv)
    w, h = (int(x) for x in args.size.lower().split("x"))

    import moderngl

    from serenity.raster.context import compile_program, get_context

    ctx = get_context()
    tex = ctx.texture((64, 64), 4, data=np.random.default_rng(0).random((64, 64, 4), np.float32).tobytes(),
                      dtype="f4")
    tex.use(0)
    target = ctx.texture((w, h), 4, dtype="f4")
    fbo = ctx.framebuffer([target])
    fbo.use()
    with open(SHADER) as fh:
        text = fh.read()
    programs = {}
    for body_name, body in BODIES.items():
        for placement, pl in PLACEMENTS.items():
            prog = compile_program(ctx, text, os.path.basename(SHADER), {"BODY": body, "PLACEMENT": pl})
            for name, value in (("u_tex", 0), ("u_flag", 0.0), ("u_zero", 0)):
                if name in prog:
                    prog[name].value = value
            programs[body_name, placement] = ctx.vertex_array(prog, [])
    times = {k: [] for k in programs}
    for _ in range(args.reps):  # the variants interleaved, so a load change hits them alike
        for k, vao in programs.items():
            ctx.finish()
            t0 = time.perf_counter()
            vao.render(moderngl.TRIANGLES, vertices=3)
            ctx.finish()
            times[k].append((time.perf_counter() - t0) * 1e3)
    out = {"benchmark": "llvmpipe_branches", "renderer": ctx.info["GL_RENDERER"], "size": [w, h], "reps": args.reps,
           "machine": platform.machine(), "cpus": os.cpu_count(), "ms": {}, "fraction_of_always": {}}
    for body_name in BODIES:
        ms = {p: float(np.median(times[body_name, p])) for p in PLACEMENTS}
        out["ms"][body_name] = ms
        span = ms["always"] - ms["none"]
        out["fraction_of_always"][body_name] = {p: (ms[p] - ms["none"]) / span if span > 0 else float("nan")
                                               for p in PLACEMENTS if p not in ("none", "always")}
        print(f"{body_name:14s} " + "  ".join(f"{p} {v:.2f}" for p, v in ms.items()) + " ms")
    write_results(args.json, out)
    print(json.dumps(out["fraction_of_always"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

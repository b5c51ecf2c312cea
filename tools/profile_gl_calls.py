"""Where the main thread sits inside moderngl calls, by call and caller: the time the frame holds
the GIL in GL (moderngl holds it through every call, and llvmpipe makes a draw that reads what an
earlier draw rendered wait for that draw inside the call), which the volume worker's Python cannot
use. The bench's camera path and moving sun; per call site, calls and ms per frame over frames 4..N.

    python tools/profile_gl_calls.py [WxH] [frames] [--quality Q] [--serial] [--json FILE]

With ``PYTHONPATH`` set to another checkout it profiles that revision (the script needs only
``Renderer``, ``RenderConfig.preset`` and ``serenity.bench``'s paths).
"""

from __future__ import annotations

import argparse
import collections
import copy
import sys
import time

import moderngl

from serenity.bench import camera_path, sun_path
from serenity.config import QUALITY_PRESETS, RenderConfig, ScheduleConfig
from serenity.frame import Renderer
from serenity.scene import load

CALLS = {moderngl.VertexArray: ("render",), moderngl.Texture: ("write", "read", "use", "build_mipmaps"),
         moderngl.Texture3D: ("write", "read"), moderngl.Framebuffer: ("clear", "use", "read"),
         moderngl.Buffer: ("write", "read", "orphan"), moderngl.Context: ("finish", "copy_framebuffer")}


def instrument(acc: dict) -> None:
    """Wrap the moderngl methods in ``CALLS`` to add each call's wall time to ``acc[(call, caller)]``."""
    for cls, names in CALLS.items():
        for name in names:
            orig = getattr(cls, name)

            def timed(self, *a, _orig=orig, _key=f"{cls.__name__}.{name}", **k):
                caller = sys._getframe(1).f_code
                t = time.perf_counter()
                try:
                    return _orig(self, *a, **k)
                finally:
                    rec = acc[(_key, f"{caller.co_filename.rsplit('/', 1)[-1]}:{caller.co_name}")]
                    rec[0] += 1
                    rec[1] += time.perf_counter() - t

            setattr(cls, name, timed)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("size", nargs="?", default="320x180")
    ap.add_argument("frames", nargs="?", type=int, default=23)
    ap.add_argument("--quality", choices=QUALITY_PRESETS, default="lpv-fast")
    ap.add_argument("--scene", default="courtyard")
    ap.add_argument("--serial", action="store_true", help="the serial schedule (default: overlapped)")
    ap.add_argument("--json")
    args = ap.parse_args()
    w, h = (int(x) for x in args.size.split("x"))
    acc: dict = collections.defaultdict(lambda: [0, 0.0])
    instrument(acc)
    scene = copy.deepcopy(load(args.scene))
    base_cam, base_sun = scene.camera, scene.sun.direction.copy()
    config = RenderConfig.preset(args.quality, schedule=ScheduleConfig(overlap=not args.serial))
    renderer = Renderer(scene, w, h, config=config)
    warm = 3
    for i in range(args.frames):
        if i == warm:
            acc.clear()
        t = i / max(1, args.frames - 1)
        scene.camera = camera_path(base_cam, t)
        scene.sun.direction = sun_path(base_sun, t)
        renderer.render(read_back=False)
    renderer.close()
    n = max(1, args.frames - warm)
    rows = sorted(({"call": c, "caller": k, "calls_per_frame": v[0] / n, "ms_per_frame": v[1] / n * 1e3}
                   for (c, k), v in acc.items()), key=lambda r: -r["ms_per_frame"])
    total = sum(r["ms_per_frame"] for r in rows)
    for r in rows[:20]:
        print(f"{r['call'] + ' <- ' + r['caller']:72s} {r['calls_per_frame']:5.1f}/frame {r['ms_per_frame']:7.3f} ms")
    print(f"{'every moderngl call':72s} {'':11s} {total:7.3f} ms per frame")
    if args.json:
        from serenity.io.results import machine_info, write_results

        write_results(args.json, {"benchmark": "gl_calls", "command": "python tools/profile_gl_calls.py "
                                  + " ".join(sys.argv[1:]), "size": [w, h], "quality": args.quality,
                                  "schedule": "serial" if args.serial else "overlapped", "frames": n,
                                  "ms_per_frame_total": total, "calls": rows, "machine": machine_info()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The frontier: our whole frame against Mitsuba 3 + Intel Open Image Denoise at equal error.

    python benchmarks/bench_frontier.py                      # courtyard + cornell (320x180 + 640x360), breakfast room
    python benchmarks/bench_frontier.py --quick              # smoke run: courtyard 160x90, few spp
    python benchmarks/bench_frontier.py --scenes cornell --sizes 320x180
    python benchmarks/bench_frontier.py --references-only    # render and cache the references first
    python benchmarks/bench_frontier.py --peers mitsuba      # without the Cycles peer

For each scene and size, all in one process on one machine:

- the reference: Mitsuba 3 ``path`` at ``--ref-spp`` (1024) spp, unlimited depth
  (``serenity.eval.reference.render_reference``, cached: only the first run pays for it); for a
  scene in ``REFERENCES`` (the breakfast room, lit almost only by bounced light), a reference that
  states its noise floor (``reference_for_error``: two halves, doubled up to ``max_spp`` until the
  floor is at most a quarter of the errors named), and each of our configs records whether its
  own error is at least four times that floor; with each of our images, where its error sits
  (``serenity.eval.regions``: FLIP, relMSE and the luminance ratio of up- and down-facing, vertical
  and edge pixels) and the largest ratio ours ÷ reference over the reference's dark regions (leaks);
- ours: for each of our quality configs (:func:`our_configs`), the median wall time of
  ``renderer.render(read_back=False)`` (the interactive frame: nothing read back, GL finished) over
  ``--frames`` frames with the static camera and sun after ``--warmup`` frames, and as many again
  after the peer's sweep (the load of a shared machine drifts); the FLIP and relMSE of one more
  frame, read back, before the sweep;
- the peer: Mitsuba 3 ``path`` at each of ``--spp`` (1 … 64), rendered progressively (each count
  adds a chunk of samples to the one before; its time is the sum of the chunks' ``mi.render`` wall
  times, the scene loaded beforehand, one warm-up render), raw and denoised by OIDN at each of
  ``--oidn`` qualities (time = render + the OIDN call), with albedo and normal guides from our
  noise-free AOVs (a 2×-supersampled G-buffer box-filtered down: ``guides_from_aovs``);
- ours with a moving camera (``moving_camera``): after the warm-up, the camera is moved to
  ``MOTION_FRAMES`` steps to the left of the case's pose and pans back to it, ``MOTION_STEP`` of
  its distance to its target per frame; the median wall time of the moving frames, and the errors
  of the last one, taken at the case's pose (so against the same reference, and the peers' curves
  stand as they are: a path tracer renders each frame afresh). What the temporal parts (the
  indirect light's history, the shadow tiles, anti-aliasing) give or cost under motion shows here;
- the equal-FLIP speed-up (``serenity.eval.frontier.equal_error_speedup``): the time the fastest
  peer curve needs to reach our FLIP (log-log interpolation between its spp points) ÷ our frame
  time, or "dominated" when its 1-spp image is already at least as good as ours; the same at equal
  relMSE. ``serenity.eval.frontier.combine`` takes the fastest of the curves: the denoised ones
  and the raw one (which at times reaches a noisy scene's error sooner: the Cornell box's 1-spp
  image can be as good as ours by FLIP); "denoised_only" in the JSON leaves the raw curves out;
- the second peer, Blender Cycles (``serenity.eval.cycles``, ``--peers``; by default wherever its
  interpreter exists, ``make cycles``): each spp a fresh render of a scene built and synced once
  (persistent data, one warm-up render per curve reported apart), raw ("cycles") and denoised by
  Cycles' own OIDN with its albedo and normal passes, FAST and ACCURATE prefilter
  ("cycles+oidn-fast", "cycles+oidn-accurate"; the time includes the denoiser). Its curves sit
  beside Mitsuba's in each case's "peer", and the speed-ups take the fastest curve of both peers.

Metrics as in ``serenity.eval.metrics``: FLIP on the tone-mapped images (our exposure, Reinhard,
sRGB), relMSE (ε = 1e-2) on linear HDR, all pixels ("rel_mse") and without the worst 0.1% of the
pixels ("rel_mse_trimmed", the one charted and compared: see ``TRIM``). Writes ``results/frontier.json`` and
``results/frontier.png`` (``--quick``: ``serenity_out/frontier_quick/``).
"""

from __future__ import annotations

import argparse
import copy
import os
import platform
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
BREAKFAST_ROOM = os.path.join(os.path.dirname(HERE), "scenes", "breakfast_room", "breakfast_room.toml")
SCENES = ("courtyard", "cornell", BREAKFAST_ROOM)
SIZES = ("320x180", "640x360")
SCENE_SIZES = {"breakfast_room": ("320x180",)}
"""Default sizes of a scene where they are not ``SIZES`` (the breakfast room's reference needs 4096 spp)."""
REFERENCES = {"breakfast_room": {"spp": 256, "max_spp": 4096, "flip": 0.08, "rel_mse": 0.2}}
"""Scenes whose reference is a ``reference_for_error`` (first spp, max_spp, and the errors its floor
must be a quarter of: the goals the scene is held to); other scenes: ``--ref-spp`` spp, no floor."""
MOTION_FRAMES = 12
MOTION_STEP = 0.01
"""The moving camera: frames of the pan, and each frame's step as a fraction of the camera's distance
to its target (the courtyard 0.25 m, the Cornell box 8 mm, the breakfast room 3 cm)."""
SPP = (1, 2, 4, 8, 16, 32, 64)
REF_SPP = 1024
OIDN_QUALITIES = ("balanced", "high")
PEERS = ("mitsuba", "cycles")
RAW_CURVES = ("raw", "cycles")
"""The peers' curves without a denoiser (left out of "denoised_only")."""
QUICK = dict(scenes=("courtyard",), sizes=("160x90",), spp=(1, 4, 16), ref_spp=64, frames=3, warmup=2,
             motion_frames=4)
GUIDE_SUPERSAMPLE = 2
TRIM = 1e-3
"""Fraction of the worst pixels left out of "rel_mse_trimmed" (as in bench_baseline): OIDN spreads a little
light onto the few pixels whose reference is exactly black, and those alone decide the all-pixel relMSE."""
SPEEDUP_METRICS = ("flip", "rel_mse_trimmed")
TIMING_REPEATS_BELOW_S = 1.0
"""Peer renders (and OIDN calls) faster than this are timed 3 times, median taken."""


def our_configs() -> dict:
    """Our quality settings, name → RenderConfig: the single place the charted points come from (the
    quality presets, cheapest first), as an application renders them: waiting for GL only before the
    CPU stages (``sync_stages="cpu"``), not after every GL pass as a per-stage profile must."""
    from serenity.config import QUALITY_PRESETS, RenderConfig, ScheduleConfig

    return {name: RenderConfig.preset(name, schedule=ScheduleConfig(sync_stages="cpu"))
            for name in reversed(QUALITY_PRESETS)}


def parse_size(text: str) -> tuple[int, int]:
    from serenity.errors import SerenityError

    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise SerenityError(f"--sizes: {text!r} is not WIDTHxHEIGHT (e.g. 320x180)") from None
    if not (16 <= w <= 4096 and 16 <= h <= 4096):
        raise SerenityError(f"--sizes: {text!r} must be within 16..4096 pixels per side")
    return w, h


def csv(text: str) -> list[str]:
    return [x.strip() for x in text.split(",") if x.strip()]


def timed_frames(renderer, frames) -> list[float]:
    """Wall ms of each of ``frames`` renders as an interactive caller makes them: nothing read back to
    the host (the image stays in the GL texture it is displayed from), the GL queue finished."""
    walls = []
    for _ in range(frames):
        t0 = time.perf_counter()
        renderer.render(read_back=False)
        renderer.ctx.finish()
        walls.append((time.perf_counter() - t0) * 1e3)
    return walls


def guides(scene, width, height, config):
    """OIDN guides (albedo, normal) at width×height from one frame of ours at GUIDE_SUPERSAMPLE× the size."""
    from serenity.eval.denoise import guides_from_aovs
    from serenity.frame import Renderer

    s = GUIDE_SUPERSAMPLE
    renderer = Renderer(scene, s * width, s * height, config=config)
    try:
        frame = renderer.render(read_back=("aovs",))
    finally:
        renderer.close()
    return guides_from_aovs(frame.aovs, supersample=s)


def moving_camera(renderer, scene, frames: int = MOTION_FRAMES, step: float = MOTION_STEP):
    """(wall ms of each moving frame, the last frame's HDR): the camera moved ``frames`` steps to the
    left of its pose, then panned back to it one step a frame (``step`` × its distance to its
    target); the pose restored after. The last frame, at the pose, is read back and not timed."""
    from serenity.eval.stability import pan_camera

    base = scene.camera
    dist = float(np.linalg.norm(np.asarray(base.target) - np.asarray(base.position)))
    walls = []
    try:
        for k in range(-frames, 0):
            scene.camera = pan_camera(base, step * dist * k)
            walls += timed_frames(renderer, 1)
        scene.camera = base
        hdr = renderer.render(read_back=("hdr",)).hdr
    finally:
        scene.camera = base
    return walls[1:], hdr  # the first moving frame follows a jump (a cut), not a step


def case_reference(scene, width, height, args, info: dict):
    """(reference image, its description for the JSON) of one case (``REFERENCES``, else ``--ref-spp``)."""
    from serenity.eval.reference import reference_for_error, render_reference

    spec = REFERENCES.get(scene.name)
    if spec is None:
        ref = render_reference(scene, width, height, spp=args.ref_spp, component="full", seed=0,
                               progress=not args.no_progress, info=info)
        return ref, {"spp": args.ref_spp, "cached": bool(info.get("cached"))}
    r = reference_for_error(scene, width, height, flip=spec["flip"], rel_mse=spec["rel_mse"], spp=spec["spp"],
                            max_spp=spec["max_spp"], seed=0, progress=not args.no_progress)
    return r.image, {"spp": r.spp, "cached": bool(r.cached), "floor": r.floor, "converged": bool(r.converged),
                     "floor_for": {"flip": spec["flip"], "rel_mse": spec["rel_mse"]},
                     **({"message": r.message} if getattr(r, "message", None) else {})}


def run_case(scene, width, height, args, bar) -> dict:
    """Everything measured for one scene and size (one entry of the JSON's "cases")."""
    from serenity.eval.frontier import combine, equal_error_speedup
    from serenity.eval.metrics import compare, rel_mse
    from serenity.frame import Renderer

    name = scene.name
    configs = our_configs()
    exposure = next(iter(configs.values())).exposure
    tag = f"{name} {width}x{height}"

    bar.set_description(f"{tag}: reference")
    info: dict = {}
    t0 = time.perf_counter()
    ref, ref_info = case_reference(scene, width, height, args, info)
    ref_s = time.perf_counter() - t0
    bar.update(1)
    floor = ref_info.get("floor")

    def metrics(img):
        m = compare(img, ref, exposure=exposure)
        out = {"flip": m["flip"], "rel_mse": m["rel_mse"], "rel_mse_trimmed": rel_mse(img, ref, trim=TRIM)}
        if floor is not None:  # the error is at least four times the reference's own noise
            out["above_floor"] = {k: bool(out[k] >= 4 * floor[k]) for k in ("flip", "rel_mse")}
        return out

    def where(frame) -> dict:
        """Where the error sits (the region report: up- and down-facing, vertical, edges, sky) and the
        largest light ratio over the reference's dark regions (leaks)."""
        from serenity.eval.regions import leak_ratio, region_report

        rep = region_report(frame.hdr, ref, frame.aovs["normal"], frame.aovs["depth"], exposure=exposure)
        keep = ("fraction", "flip", "rel_mse", "flip_share", "rel_mse_share", "luminance_ratio")
        return {"regions": {name: {k: v[k] for k in keep} for name, v in rep["regions"].items()},
                "luminance_ratio": rep["all"]["luminance_ratio"], "leak": leak_ratio(frame.hdr, ref)}

    # ours: timed before and again after the peer's sweep (this machine's load drifts over minutes);
    # the image is one more frame, read back, before it
    ours, renderers = [], {}
    for cname, cfg in configs.items():
        bar.set_description(f"{tag}: ours ({cname})")
        renderers[cname] = r = Renderer(scene, width, height, config=cfg)
        for _ in range(args.warmup):
            r.render()
        walls = timed_frames(r, args.frames)
        frame = r.render(read_back=("hdr", "aovs"))
        entry = {"name": cname, "wall_ms_before": walls, **metrics(frame.hdr), **where(frame)}
        if args.motion_frames:
            bar.set_description(f"{tag}: ours ({cname}), moving camera")
            moving_walls, hdr = moving_camera(r, scene, args.motion_frames)
            entry["moving"] = {"wall_ms": moving_walls, "ms": float(np.median(moving_walls)), **metrics(hdr)}
        ours.append(entry)
        bar.update(1)

    curves: dict[str, list[dict]] = {}
    if "mitsuba" in args.peers:
        curves.update(mitsuba_curves(scene, width, height, args, bar, metrics, configs, tag))
    cycles_run = None
    if "cycles" in args.peers:
        from serenity.eval.cycles import CyclesPeer

        bar.set_description(f"{tag}: Cycles {args.spp[0]}-{args.spp[-1]} spp")
        cpeer = CyclesPeer(scene, width, height)
        for curve, pts in cpeer.curves(args.spp, repeat_below_s=TIMING_REPEATS_BELOW_S).items():
            curves[curve] = [{"spp": spp, "ms": s * 1e3, **metrics(img)} for spp, img, s in pts]
        cycles_run = cpeer.last_run
        bar.update(1)

    bar.set_description(f"{tag}: ours again")
    for o in ours:
        o["wall_ms_after"] = timed_frames(renderers[o["name"]], args.frames)
        renderers.pop(o["name"]).close()
        o["ms"] = float(np.median(o["wall_ms_before"] + o["wall_ms_after"]))

    denoised = [q for q in curves if q not in RAW_CURVES]

    def speedups_of(point) -> dict:
        out = {}
        for metric in SPEEDUP_METRICS:
            per_config = {}
            for o in ours:
                if (p := point(o)) is None:
                    continue
                per_curve = {q: equal_error_speedup([(c["ms"], c[metric]) for c in pts], p["ms"], p[metric])
                             for q, pts in curves.items()}
                # the headline: the peers' fastest way to our error, raw or denoised (raw only ever makes
                # it faster); "denoised_only" keeps the denoised curves alone
                per_config[o["name"]] = {**combine(per_curve),
                                         "denoised_only": combine({q: per_curve[q] for q in denoised}),
                                         "per_curve": per_curve}
            out[metric] = per_config
        return out

    case = {"scene": name, "size": [width, height], "reference": {**ref_info, "seconds": ref_s},
            "ours": ours, "peer": curves, "equal_error": speedups_of(lambda o: o)}
    if args.motion_frames:
        case["equal_error_moving"] = speedups_of(lambda o: o.get("moving"))
    if cycles_run is not None:
        case["cycles"] = cycles_run
    return case


def mitsuba_curves(scene, width, height, args, bar, metrics, configs, tag) -> dict[str, list[dict]]:
    """Mitsuba's curves, raw and + OIDN at each quality, for one case (points: spp, ms, errors)."""
    from serenity.eval.denoise import denoise
    from serenity.eval.frontier import PathTracerPeer, timed

    bar.set_description(f"{tag}: guides")
    albedo, normal = guides(scene, width, height, next(iter(configs.values())))
    for q in args.oidn:  # OIDN's first call per size and quality builds its filter: not timed
        denoise(np.ones((height, width, 3), np.float32), albedo, normal, quality=q)

    peer = PathTracerPeer(scene, width, height)
    curves: dict[str, list[dict]] = {"raw": [], **{q: [] for q in args.oidn}}
    bar.set_description(f"{tag}: Mitsuba {args.spp[0]} spp")
    for k, (spp, img, render_s) in enumerate(peer.progressive(args.spp, TIMING_REPEATS_BELOW_S)):
        curves["raw"].append({"spp": spp, "ms": render_s * 1e3, "render_ms": render_s * 1e3, **metrics(img)})
        for q in args.oidn:
            out, oidn_s = timed(lambda q=q, img=img: denoise(img, albedo, normal, quality=q), TIMING_REPEATS_BELOW_S)
            curves[q].append({"spp": spp, "ms": (render_s + oidn_s) * 1e3, "render_ms": render_s * 1e3,
                              "oidn_ms": oidn_s * 1e3, **metrics(out)})
        bar.update(1)
        if k + 1 < len(args.spp):
            bar.set_description(f"{tag}: Mitsuba {args.spp[k + 1]} spp")
    return curves


def cycles_info(args) -> dict:
    """The Cycles peer's settings, for the JSON (each case's "cycles" adds its run: version, threads, warm-ups)."""
    from serenity.eval.cycles import CURVES, MAX_BOUNCES, interpreter

    return {"renderer": "Blender Cycles (bpy), CPU, all threads, persistent data, box filter, no adaptive sampling, "
                        f"no clamping, {MAX_BOUNCES} bounces",
            "interpreter": str(interpreter()), "curves": dict(CURVES), "spp": args.spp,
            "denoiser": "Cycles' own Open Image Denoise, albedo + normal passes of Cycles, prefilter FAST or ACCURATE",
            "time": "each spp a fresh render of the synced scene (one warm-up render per curve first, reported in "
                    "each case's cycles.warmup_seconds): the wall time around bpy.ops.render.render, denoiser "
                    f"included; renders under {TIMING_REPEATS_BELOW_S:g} s timed 3 times, median"}


def headline(case: dict, metric: str = "flip") -> tuple[str, dict]:
    """(config name, result) of our config with the best equal-``metric`` standing (:func:`strongest`)."""
    from serenity.eval.frontier import strongest

    return strongest(case["equal_error"][metric])


def summarise(cases: list[dict], goal: float) -> list[dict]:
    """Per case, the headline config's standing by each metric; with a moving camera too
    ("moving": the same config's result with the camera panning)."""
    from serenity.eval.frontier import describe, goal_met

    def entry(name, r):
        return {"config": name, "status": r["status"], "speedup": r["speedup"], "bound": r["bound"],
                "peer_ms": r["peer_ms"], "curve": r["curve"],
                "peer": "cycles" if r["curve"].startswith("cycles") else "mitsuba", "reads": describe(r),
                "goal_met": goal_met(r, goal)}

    out = []
    for c in cases:
        row = {"scene": c["scene"], "size": f"{c['size'][0]}x{c['size'][1]}"}
        for metric in SPEEDUP_METRICS:
            name, r = headline(c, metric)
            row[metric] = entry(name, r)
            if "equal_error_moving" in c:
                row[metric]["moving"] = entry(name, c["equal_error_moving"][metric][name])
        out.append(row)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true",
                   help="smoke run: courtyard at 160x90, 1/4/16 spp, a 64-spp reference, 3 frames")
    p.add_argument("--scenes", type=csv, help="comma-separated built-in names or scene files (default: courtyard, "
                                              "cornell and scenes/breakfast_room/breakfast_room.toml)")
    p.add_argument("--sizes", type=csv, help=f"comma-separated WxH (default: {','.join(SIZES)}; the breakfast room "
                                             f"{','.join(SCENE_SIZES['breakfast_room'])})")
    p.add_argument("--spp", type=lambda t: [int(x) for x in csv(t)], help="peer spp list (default 1,2,4,...,64)")
    p.add_argument("--ref-spp", type=int, help=f"reference spp (default {REF_SPP})")
    p.add_argument("--peers", type=csv,
                   help=f"comma-separated among {','.join(PEERS)} (default: both where Cycles' interpreter exists, "
                        "else mitsuba)")
    p.add_argument("--oidn", type=csv, default=list(OIDN_QUALITIES),
                   help=f"OIDN qualities of the denoised curves (default {','.join(OIDN_QUALITIES)})")
    p.add_argument("--frames", type=int, help="our timed frames (default 5)")
    p.add_argument("--warmup", type=int, help="our untimed frames first (default 3)")
    p.add_argument("--motion-frames", type=int,
                   help=f"frames of the moving camera's pan, 0 = none (default {MOTION_FRAMES})")
    p.add_argument("--json", help="output JSON (default results/frontier.json; --quick: under serenity_out/)")
    p.add_argument("--png", help="output chart (default results/frontier.png; --quick: under serenity_out/)")
    p.add_argument("--references-only", action="store_true",
                   help="only render (and cache) the references of the selected scenes and sizes, then exit")
    p.add_argument("--no-progress", action="store_true")
    args = p.parse_args(argv)

    from tqdm import tqdm

    from serenity.errors import SerenityError
    from serenity.eval.denoise import QUALITIES
    from serenity.eval.frontier import GOAL_SPEEDUP, save_frontier_chart
    from serenity.io.results import write_results

    # the smoke run is not a result: it goes beside the renders, not into benchmarks/results
    out_dir = os.path.join("serenity_out", "frontier_quick") if args.quick else os.path.join(HERE, "results")
    args.json = args.json or os.path.join(out_dir, "frontier.json")
    args.png = args.png or os.path.join(out_dir, "frontier.png")
    try:
        defaults = QUICK if args.quick else dict(scenes=SCENES, sizes=None, spp=SPP, ref_spp=REF_SPP, frames=5,
                                                 warmup=3, motion_frames=MOTION_FRAMES)
        for key, value in defaults.items():
            if getattr(args, key) is None:
                setattr(args, key, list(value) if isinstance(value, tuple) else value)
        if args.motion_frames < 0:
            raise SerenityError(f"--motion-frames must be >= 0, got {args.motion_frames}")

        def sizes_of(scene_name: str) -> list[tuple[int, int]]:
            return [parse_size(x) for x in (args.sizes or SCENE_SIZES.get(scene_name, SIZES))]

        sizes_of("")  # a bad --sizes fails here
        if sorted(set(args.spp)) != list(args.spp) or args.spp[0] < 1:
            raise SerenityError(f"--spp must be rising positive counts, got {args.spp}")
        bad = [q for q in args.oidn if q not in QUALITIES]
        if bad or not args.oidn:
            raise SerenityError(f"--oidn: qualities must be among {', '.join(QUALITIES)}, got {args.oidn}")
        if args.frames < 1 or args.warmup < 0 or args.ref_spp < 1:
            raise SerenityError("--frames must be >= 1, --warmup >= 0 and --ref-spp >= 1")
        from serenity.eval import cycles

        if args.peers is None:
            args.peers = list(PEERS) if cycles.available() else ["mitsuba"]
            if "cycles" not in args.peers and not args.references_only:
                print(f"{cycles.unavailable_reason()}; measuring Mitsuba alone", file=sys.stderr)
        elif not args.peers or any(x not in PEERS for x in args.peers):
            raise SerenityError(f"--peers: must be among {', '.join(PEERS)}, got {args.peers}")
        elif "cycles" in args.peers and not args.references_only:
            cycles.require()

        from serenity.scene import load

        scenes = {name: load(name) for name in args.scenes}  # a bad name or file fails here, before any work
        t_start = time.perf_counter()
        if args.references_only:
            for scene in scenes.values():
                for w, h in sizes_of(scene.name):
                    t0 = time.perf_counter()
                    info: dict = {}
                    _, ref_info = case_reference(scene, w, h, args, info)
                    floor = f", noise floor {ref_info['floor']}" if "floor" in ref_info else ""
                    print(f"{scene.name} {w}x{h}: reference {ref_info['spp']} spp{floor} "
                          f"{'cached' if ref_info.get('cached') else 'rendered'} in {time.perf_counter() - t0:.0f} s")
            return 0
        n_cfg = len(our_configs())
        # reference, ours, each Mitsuba spp, the Cycles run
        steps = 1 + n_cfg + ("mitsuba" in args.peers) * len(args.spp) + ("cycles" in args.peers)
        total = sum(len(sizes_of(scene.name)) for scene in scenes.values()) * steps
        cases = []
        with tqdm(total=total, unit="step", disable=args.no_progress) as bar:
            for scene in scenes.values():
                for w, h in sizes_of(scene.name):
                    cases.append(run_case(copy.deepcopy(scene), w, h, args, bar))
        elapsed = time.perf_counter() - t_start
    except SerenityError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2

    import mitsuba
    import pyoidn

    from serenity.config import PRESETS
    from serenity.eval.frontier import describe

    summary = summarise(cases, GOAL_SPEEDUP)
    out = {
        "benchmark": "frontier",
        "quick": bool(args.quick),
        "command": "python benchmarks/bench_frontier.py " + " ".join(sys.argv[1:] if argv is None else argv),
        "seconds": elapsed,
        "machine": {"platform": platform.platform(), "processor": platform.processor(), "cpus": os.cpu_count(),
                    "python": sys.version.split()[0]},
        "peer": {"renderer": f"Mitsuba {mitsuba.__version__} scalar_rgb path (unlimited depth)",
                 "denoiser": f"Intel Open Image Denoise via pyoidn {getattr(pyoidn.version, '__version__', '')}"
                             .strip(),
                 "oidn_qualities": args.oidn, "spp": args.spp,
                 "time": "progressive: sum of the wall times of the mi.render chunks up to this spp (scene loaded "
                         "beforehand, one warm-up render) + the OIDN call; "
                         f"calls under {TIMING_REPEATS_BELOW_S:g} s timed 3 times, median",
                 "guides": f"albedo + normal from our G-buffer at {GUIDE_SUPERSAMPLE}x the size, box-filtered down; "
                           "albedo 1 on the sky and where we trace rays; cleanAux"},
        "peers": args.peers,
        **({"cycles": cycles_info(args)} if "cycles" in args.peers else {}),
        "ours": {"configs": list(our_configs()), "presets": {k: PRESETS[k] for k in our_configs()},
                 "sync_stages": "cpu", "frames": args.frames, "warmup": args.warmup,
                 "time": "median wall time of Renderer.render(read_back=False) + GL finish, static camera and "
                         "sun, after the warm-up: frames frames before the peer's sweep and frames after it",
                 "moving": {"frames": args.motion_frames, "step": MOTION_STEP,
                            "what": "the camera panned back to the case's pose, each frame a step of 'step' times "
                                    "its distance to its target; ms: median wall time of the moving frames after "
                                    "the first; errors: the last frame, at the case's pose"}},
        "reference": {"renderer": "Mitsuba path, unlimited depth (serenity.eval.reference.render_reference)",
                      "spp": args.ref_spp,
                      "with_floor": {k: v for k, v in REFERENCES.items()},
                      "floor": "reference_for_error: two half-spp renders; floor = FLIP and relMSE of one "
                               "against the other (conservative: about 4x the reference's own relMSE)"},
        "metrics": {"flip": "mean FLIP (LDR) after exposure + Reinhard + sRGB, all pixels",
                    "rel_mse": "mean (x-ref)^2/(ref^2+1e-2), linear HDR, all pixels",
                    "rel_mse_trimmed": f"the same without the {TRIM:.1%} of pixels with the largest error (charted: "
                                       "a few pixels whose reference is black outweigh all others)"},
        "speedup": "peer time to reach our error (the fastest curve, raw or denoised, log-log interpolation "
                   "between spp) / our frame time; 'dominated' when its 1-spp image is already as good (bound = "
                   "upper bound); 'not_reached' when 64 spp is not (bound = lower bound); 'denoised_only': the "
                   "same over the denoised curves alone",
        "goal_speedup": GOAL_SPEEDUP,
        "summary": summary,
        "cases": cases,
    }
    write_results(args.json, out)
    panels = []
    for c, s in zip(cases, summary, strict=True):
        panels.append({"title": f"{c['scene']} {c['size'][0]}×{c['size'][1]}",
                       "peer": c["peer"],
                       "ours": c["ours"], "headline": s["flip"]["config"],
                       "speedup": {m: c["equal_error"][m][s["flip"]["config"]] for m in SPEEDUP_METRICS}})
    save_frontier_chart(panels, args.png, GOAL_SPEEDUP,
                        metrics=(("flip", "FLIP"), ("rel_mse_trimmed", "relMSE, worst 0.1% of pixels left out")))
    for s in summary:
        print(f"{s['scene']} {s['size']}: equal-FLIP {describe(s['flip'])} ({s['flip']['config']}; the "
              f"peers' fastest curve: {s['flip']['curve']}), "
              f"equal-relMSE (trimmed) {describe(s['rel_mse_trimmed'])}; goal >= {GOAL_SPEEDUP:g}x "
              f"{'met' if s['flip']['goal_met'] else 'not met'}")
    print(f"{elapsed:.0f} s; wrote {args.json} and {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``serenity bench``: a frame benchmark in the manner of the paper's Table 1 (§10).

Renders N frames along a camera path (a slow orbit-and-dolly around the camera's target) with the
sun moving (a few minutes of the day per frame), the overlapped and the serial schedule taking
turns frame by frame (``run_schedules``), and reports per stage the median milliseconds, the total,
FPS, the serial total and the overlap gain. Writes JSON and a timeline chart of one overlapped
frame (paper Fig. 21): one lane for the main thread (GL passes and volume kernels), one for the CPU ray-tracing worker.
It times the default preset unless told otherwise; ``quality="lpv-fast"`` (``--quality lpv-fast``)
has every technique of the paper's Table 1 on (the default has neither SSAO nor the LPV).

Also tracked, for the "frame to frame" contract: the process's resident memory after each frame
(it must stay flat: no per-frame allocation growth) and that no frame contains NaN.
"""

from __future__ import annotations

import copy
import math
import os
import time

import numpy as np
from tqdm import tqdm

from serenity.config import DEFAULT_QUALITY, RenderConfig, ScheduleConfig
from serenity.device import resolve_device
from serenity.frame import LPV_UPDATE_STAGES, MAIN_LANE, SKY_UPDATE_STAGES, STAGES, Renderer
from serenity.io.results import machine_info, write_results
from serenity.optional import pyplot
from serenity.scene import load
from serenity.scene.model import Camera, direction_from_angles

#: the paper's Table 1 (ms), printed beside ours: stage → (paper's name, ms)
PAPER_TABLE1 = {
    "lpv update": ("Light Propagation Volumes Update (3 cascades)", 5.0),
    "direct lighting": ("Direct Lighting (Phong + CSM + PCSS)", 6.5),
    "sky lighting": ("Sky Lighting", 2.4),
    "lpv lighting": ("Light Propagation Volumes Rendering (diffuse + glossy)", 6.8),
    "ssao": ("Screen Space Ambient Occlusion", 6.0),
    "cpu ray tracing": ("CPU Ray Tracing", 36.0),
    "rt direct lighting": ("RT: Direct Lighting (Phong + OSM + PCSS)", 0.8),
    "rt sky lighting": ("RT: Sky Lighting", 0.6),
    "rt lpv lighting": ("RT: Light Propagation Volumes Rendering", 1.0),
    "frame": ("Total Frame Time (without sky lighting update)", 42.6),
}


def rss_mb() -> float:
    """Resident set size of this process now, MiB (Linux /proc; 0 where unavailable)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError):
        return 0.0


def camera_path(base: Camera, t: float) -> Camera:
    """The base camera orbited by up to ±12° around its target and dollied towards it by up to 10 %,
    t ∈ [0, 1]. (Only towards it: a scene's camera usually stands near a wall, and the earlier ±10 %
    put the courtyard's camera inside its south wall for a few frames of the path.)"""
    offset = base.position - base.target
    ang = math.radians(12.0) * math.sin(2 * math.pi * t)
    c, s = math.cos(ang), math.sin(ang)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    pos = base.target + (rot @ offset) * (1.0 - 0.05 * (1.0 - math.cos(4 * math.pi * t)))
    return Camera(position=pos, target=base.target, up=base.up, fov_y_deg=base.fov_y_deg, near=base.near,
                  far=base.far)


def sun_path(base_dir: np.ndarray, t: float, degrees: float = 20.0) -> np.ndarray:
    """The sun swept ``degrees`` of azimuth and half that of elevation over the run."""
    el = math.degrees(math.asin(np.clip(base_dir[1], -1, 1)))
    az = math.degrees(math.atan2(base_dir[0], base_dir[2])) % 360.0
    return direction_from_angles(max(-5.0, el - degrees / 2 * t), az + degrees * t)


def run_schedules(scene, width, height, frames, device=None, schedules=(True, False), progress=True,
                  quality: str = DEFAULT_QUALITY):
    """Render the path once per schedule (overlap True / False), the schedules' renderers taking
    turns frame by frame, each at the same camera and sun, in an order that alternates from frame
    to frame. Interleaved, a drift of the machine's speed over the run (another job, the clock)
    weighs on both alike; run one after the other, it showed as an overlap gain or loss of a few
    per cent either way between runs of the same code. Returns {overlap: (records, the Frame of the
    middle of the run)}."""
    scenes = {o: copy.deepcopy(scene) for o in schedules}
    base_cam, base_sun = scene.camera, np.asarray(scene.sun.direction, np.float64).copy()
    records = {o: [] for o in schedules}
    sample = {o: None for o in schedules}
    label = " + ".join("overlapped" if o else "serial" for o in schedules)
    renderers: dict = {}
    try:
        for o in schedules:
            renderers[o] = Renderer(scenes[o], width, height, device=device,
                                    config=RenderConfig.preset(quality, schedule=ScheduleConfig(overlap=o)))
        for i in tqdm(range(frames), desc=f"bench {scene.name} ({label})", disable=not progress, unit="frame"):
            t = i / max(1, frames - 1)
            order = schedules if i % 2 == 0 else tuple(reversed(schedules))
            for o in order:
                sc = scenes[o]
                sc.camera = camera_path(base_cam, t)
                sc.sun.direction = sun_path(base_sun, t)
                # nothing read back, as in an interactive view; the tone-mapping pass counts the
                # non-finite pixels
                frame = renderers[o].render(read_back=False)
                # the sky update's share of the main thread's time (with the volume worker only its upload)
                sky_main = sum(t1 - t0 for lane, name, t0, t1 in frame.events
                               if lane == MAIN_LANE and name in SKY_UPDATE_STAGES)
                records[o].append({"timings": frame.timings, "wall_ms": frame.wall_ms, "cpu_ms": frame.cpu_ms,
                                   "sky_main_ms": sky_main,
                                   "rss_mb": rss_mb(), "nan": frame.nonfinite_pixels > 0, "rays": frame.rays})
                if i == frames // 2 or sample[o] is None:
                    sample[o] = frame
    finally:
        for r in renderers.values():
            r.close()
    return {o: (records[o], sample[o]) for o in schedules}


def summarise(records: list[dict], skip_first: int = 1) -> dict:
    """Median ms per stage over the frames after the first ``skip_first`` (uploads, builds), in
    ``STAGES`` order, plus the paper's "LPV update" (the sum of ``LPV_UPDATE_STAGES``) and the frame
    without the sky volume's update (``SKY_UPDATE_STAGES``), which the paper's Table 1 leaves out."""
    recs = records[skip_first:] or records
    names = [k for k in STAGES if any(k in r["timings"] for r in recs)]
    stages = {k: float(np.median([r["timings"].get(k, 0.0) for r in recs])) for k in names}
    wall = float(np.median([r["wall_ms"] for r in recs]))
    # the frame less the time the main thread spent on the sky update: with the volume worker that
    # is only the upload (the update runs beside the GL passes and costs the frame only by contention)
    no_sky = float(np.median([r["wall_ms"] - r.get("sky_main_ms", sum(r["timings"].get(k, 0.0)
                                                                      for k in SKY_UPDATE_STAGES))
                              for r in recs]))
    lpv = float(np.median([sum(r["timings"].get(k, 0.0) for k in LPV_UPDATE_STAGES) for r in recs]))
    cpu = float(np.median([r.get("cpu_ms", 0.0) for r in recs]))
    cores = os.cpu_count() or 1
    sky = float(np.median([sum(r["timings"].get(k, 0.0) for k in SKY_UPDATE_STAGES) for r in recs]))
    return {"stages_ms": stages, "frame_ms": wall, "fps": 1e3 / wall if wall > 0 else 0.0,
            "frame_without_sky_update_ms": no_sky, "lpv_update_ms": lpv, "sky_update_ms": sky,
            "sum_of_stages_ms": float(np.median([sum(r["timings"].values()) for r in recs])),
            # CPU time of a frame on all cores (this process + the tracer process); spread perfectly
            # over the machine's cores it still takes cpu_ms / cores: no schedule can beat that
            "cpu_ms": cpu, "cores_busy": cpu / wall if wall > 0 else 0.0, "cpu_bound_ms": cpu / cores}


def timeline_chart(frame, path: str, title: str) -> None:
    """One frame's stages over time (paper Fig. 21), one row per stage (named on the axis, so no
    label can overlap another), coloured by lane: the main thread (GL passes and volume kernels)
    and the ray-tracing worker, whose bar lies under the main thread's GL stages it overlapped."""
    plt = pyplot("the timeline chart")
    events = sorted(frame.events, key=lambda e: e[2])
    rows: list[str] = []
    for _, name, *_ in events:
        if name not in rows:
            rows.append(name)
    lanes = list(dict.fromkeys(lane for lane, *_ in events))
    colours = dict(zip(lanes, ("tab:blue", "tab:orange", "tab:green"), strict=False))
    fig, ax = plt.subplots(figsize=(11, 1.0 + 0.27 * len(rows)))
    for lane, name, t0, t1 in events:
        ax.barh(rows.index(name), t1 - t0, left=t0, height=0.7, color=colours[lane], edgecolor="black",
                linewidth=0.3)
    ax.set_yticks(range(len(rows)), rows, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("ms from the frame's start")
    ax.set_title(title, fontsize=10)
    ax.grid(axis="x", alpha=0.3)
    ax.legend([plt.Rectangle((0, 0), 1, 1, color=colours[lane]) for lane in lanes], lanes, fontsize=8,
              loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def format_table(over: dict, serial: dict) -> str:
    rows = [("stage", "ms (overlapped)", "ms (serial)", "paper ms")]
    for k, v in over["stages_ms"].items():
        paper = PAPER_TABLE1.get(k, ("", None))[1]
        rows.append((k, f"{v:.2f}", f"{serial['stages_ms'].get(k, float('nan')):.2f}",
                     "" if paper is None else f"{paper:.1f}"))
    rows.append(("LPV update (the parts above)", f"{over['lpv_update_ms']:.2f}", f"{serial['lpv_update_ms']:.2f}",
                 f"{PAPER_TABLE1['lpv update'][1]:.1f}"))
    rows.append(("sum of stages", f"{over['sum_of_stages_ms']:.2f}", f"{serial['sum_of_stages_ms']:.2f}", "65.1"))
    rows.append(("frame without sky update", f"{over['frame_without_sky_update_ms']:.2f}",
                 f"{serial['frame_without_sky_update_ms']:.2f}", "42.6 / 68"))
    rows.append(("frame (wall)", f"{over['frame_ms']:.2f}", f"{serial['frame_ms']:.2f}", "42.6 / 68"))
    rows.append(("FPS", f"{over['fps']:.1f}", f"{serial['fps']:.1f}", "23 / 14"))
    w = [max(len(r[i]) for r in rows) for i in range(4)]
    return "\n".join("  ".join(c.ljust(w[i]) if i == 0 else c.rjust(w[i]) for i, c in enumerate(r)) for r in rows)


def bench(scene_name: str, width: int, height: int, frames: int, device=None, json_path=None,
          chart_path=None, quality: str = DEFAULT_QUALITY) -> dict:
    scene = load(scene_name)
    device = resolve_device(device)
    t0 = time.perf_counter()
    runs = run_schedules(scene, width, height, frames, device, (True, False), quality=quality)
    (over_recs, sample), (serial_recs, _) = runs[True], runs[False]
    over, serial = summarise(over_recs), summarise(serial_recs)
    rss = [r["rss_mb"] for r in over_recs]
    result = {
        "scene": scene.name, "size": [width, height], "frames": frames, "device": device, "quality": quality,
        "machine": machine_info(),
        "overlapped": over, "serial": serial,
        "overlap_ratio": over["frame_ms"] / serial["frame_ms"] if serial["frame_ms"] else None,
        "rss_mb": {"frame_20": rss[min(19, len(rss) - 1)], "last": rss[-1], "max": max(rss)},
        "nan_frames": int(sum(r["nan"] for r in over_recs + serial_recs)),
        "rays_median": float(np.median([r["rays"] for r in over_recs])),
        "paper_table1_ms": {k: v[1] for k, v in PAPER_TABLE1.items()},
        "bench_seconds": time.perf_counter() - t0,
    }
    print(format_table(over, serial))
    print(f"overlap gain: frame {over['frame_ms']:.1f} ms overlapped vs {serial['frame_ms']:.1f} ms serial "
          f"(ratio {result['overlap_ratio']:.2f}; paper 42.6 / 68 = 0.63)")
    print(f"CPU per frame (all threads, both processes): {over['cpu_ms']:.1f} ms overlapped, "
          f"{serial['cpu_ms']:.1f} ms serial, on {os.cpu_count()} cores: no schedule beats "
          f"{over['cpu_bound_ms']:.1f} ms; the overlapped frame keeps {over['cores_busy']:.2f} cores busy")
    print(f"memory: RSS {result['rss_mb']['frame_20']:.0f} MiB at frame {min(20, len(rss))}, "
          f"{result['rss_mb']['last']:.0f} MiB at frame {len(rss)}; NaN frames: {result['nan_frames']}")
    if json_path:
        write_results(json_path, result)
    if chart_path:
        os.makedirs(os.path.dirname(os.path.abspath(chart_path)), exist_ok=True)
        timeline_chart(sample, chart_path, f"{scene.name} {width}x{height}, {device}: one overlapped frame "
                                           f"({sample.wall_ms:.0f} ms wall, {sample.total_ms:.0f} ms of stages)")
        print(f"wrote {chart_path}")
    return result

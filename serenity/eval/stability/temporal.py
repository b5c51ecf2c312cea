"""Temporal stability of every quality preset: a slowly sinking sun and a slowly panning camera on the
courtyard, the frame-to-frame steps of the display luminance, which part of the light and which
amortisation switch they come from, and the docs' tables of them.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from serenity.colour import luminance, reinhard
from serenity.config import RenderConfig
from serenity.frame import Renderer
from serenity.scene import load
from serenity.scene.model import Camera, direction_from_angles

TEMPORAL_PRESETS = ("traced-probes", "lpv", "lpv-fast", "paper")
"""The quality presets the temporal-stability measurements cover."""
MEAN_STEP_BOUND = 0.01
"""Goal for the worst frame-to-frame step of the mean display luminance (relative)."""
P99_STEP_BOUND = 0.03
"""Goal for the worst frame-to-frame 99th-percentile pixel step of the display luminance (relative)."""
DISPLAY_FLOOR = 0.01
"""Display luminance (of 1) under which a pixel's step is taken relative to this instead of to the
pixel's own luminance (a step of a nearly black pixel is not a visible pop)."""
SUN_STEP_DEG = 0.05
"""The sun sweep's step: degrees of elevation per frame (the azimuth is kept)."""
CAMERA_STEP_M = 0.05
"""The camera pan's step: metres per frame along the camera's right vector."""


def display_luminance(hdr: np.ndarray, exposure: float) -> np.ndarray:
    """(H, W) the luminance of the renderer's tone map before the sRGB encoding (Reinhard,
    ``serenity.colour.reinhard``), in [0, 1): what the frame-to-frame steps are measured on."""
    return luminance(reinhard(np.asarray(hdr, np.float32), exposure))


def frame_step(prev: np.ndarray, cur: np.ndarray, mask: np.ndarray | None = None) -> tuple[float, float]:
    """(mean-luminance step, 99th-percentile pixel step) from display luminance ``prev`` to ``cur``
    ((H, W) each), over the pixels of ``mask`` (all when None):

        mean step = |mean(cur) − mean(prev)| / mean(prev)
        pixel step = |cur − prev| / max(prev, DISPLAY_FLOOR), and its 99th percentile over the pixels."""
    prev, cur = np.asarray(prev, np.float64), np.asarray(cur, np.float64)
    if mask is not None:
        prev, cur = prev[mask], cur[mask]
    if prev.size == 0:
        return 0.0, 0.0
    m = float(prev.mean())
    pixel = np.abs(cur - prev) / np.maximum(prev, DISPLAY_FLOOR)
    return abs(float(cur.mean()) - m) / max(m, DISPLAY_FLOOR), float(np.percentile(pixel, 99))


def preset_config(quality: str, overrides: dict | None = None) -> RenderConfig:
    """``RenderConfig.preset(quality)`` with ``overrides``: RenderConfig fields by name, or a
    sub-config's field as "sub.field" (e.g. ``{"lpv.temporal_blend": 1.0, "shadow.stagger": False}``)."""
    cfg = RenderConfig.preset(quality)
    for key, value in (overrides or {}).items():
        if "." in key:
            sub, name = key.split(".", 1)
            cfg = dataclasses.replace(cfg, **{sub: dataclasses.replace(getattr(cfg, sub), **{name: value})})
        else:
            cfg = dataclasses.replace(cfg, **{key: value})
    return cfg


def _component_p99(hdr_prev: np.ndarray, part_prev: np.ndarray, part_cur: np.ndarray, mask=None) -> float:
    """99th percentile over pixels of |Δ part| / the pixel's HDR luminance: how much of a pixel's
    step one part of its light makes (linear, before the tone map)."""
    lum = luminance(hdr_prev)
    d = np.abs(luminance(part_cur) - luminance(part_prev)) / np.maximum(lum, 1e-6 * max(float(lum.max()), 1e-12))
    if mask is not None:
        d = d[mask]
    return float(np.percentile(d, 99)) if d.size else 0.0


def _summary(mean: list[float], p99: list[float], parts: dict[str, list[float]], **extra) -> dict:
    mean_a, p99_a = np.array(mean), np.array(p99)
    out = {"mean_step": mean_a.tolist(), "p99_step": p99_a.tolist(),
           "worst_mean_step": float(mean_a.max(initial=0.0)), "worst_p99_step": float(p99_a.max(initial=0.0)),
           "worst_frame": int(np.argmax(p99_a)) + 1 if p99_a.size else 0,
           "parts_p99": {k: np.array(v).tolist() for k, v in parts.items()},
           "worst_parts_p99": {k: float(np.max(v, initial=0.0)) for k, v in parts.items()}}
    out.update(extra)
    return out


def sun_sweep(quality: str, frames: int = 40, size=(160, 90), step_deg: float = SUN_STEP_DEG, start_frame: int = 0,
              warmup: int = 0, scene_name: str = "courtyard", overrides: dict | None = None, device=None) -> dict:
    """The camera still, the sun's elevation sinking ``step_deg`` per frame from the scene's (its
    azimuth kept), rendered as an application renders it (one ``Renderer``, frame after frame). Frame k
    has the sun at elevation e0 − k·step_deg; the renderer starts at k = ``start_frame`` − ``warmup``
    and the ``frames`` steps from k = ``start_frame`` on are measured (``frame_step`` on the display
    luminance). Returns per step the mean-luminance step and the 99th-percentile pixel step, their worst
    and the step (1-based from ``start_frame``) of the worst pixel step; ``parts_p99``: per step, the
    99th percentile of the step of the direct sun light ("direct") and of everything else ("indirect":
    the sky volume's and the LPV's light, reflections and refractions), each over the pixel's HDR
    luminance; ``finite``: no NaN or infinite pixel."""
    scene = load(scene_name)
    el0, az = float(scene.sun.elevation_deg), float(scene.sun.azimuth_deg)
    cfg = preset_config(quality, overrides)
    r = Renderer(scene, *size, device=device, config=cfg)
    mean, p99, parts = [], [], {"direct": [], "indirect": []}
    prev = None
    finite = True
    try:
        for k in range(start_frame - warmup, start_frame + frames + 1):
            scene.sun.direction = direction_from_angles(el0 - step_deg * k, az)
            f = r.render(read_back=("hdr", "aovs"))
            finite &= bool(np.all(np.isfinite(f.hdr)))
            cur = (f.hdr, f.aovs["direct"], display_luminance(f.hdr, cfg.exposure))
            if prev is not None and k > start_frame:
                m, p = frame_step(prev[2], cur[2])
                mean.append(m)
                p99.append(p)
                parts["direct"].append(_component_p99(prev[0], prev[1], cur[1]))
                parts["indirect"].append(_component_p99(prev[0], prev[0] - prev[1], cur[0] - cur[1]))
            prev = cur
    finally:
        r.close()
    return _summary(mean, p99, parts, finite=finite, quality=quality, frames=frames, size=list(size),
                    step_deg=step_deg, start_frame=start_frame, start_elevation_deg=el0 - step_deg * start_frame)


def pan_camera(base: Camera, offset_m: float) -> Camera:
    """``base`` and its target moved ``offset_m`` metres along its right vector (a truck: the view
    direction kept)."""
    right = np.cross(base.forward, base.up)
    d = float(offset_m) * right / np.linalg.norm(right)
    return Camera(position=np.asarray(base.position) + d, target=np.asarray(base.target) + d, up=base.up,
                  fov_y_deg=base.fov_y_deg, near=base.near, far=base.far)


def reprojected(prev_lum, prev_position, prev_normal, prev_view_proj, position, normal, covered,
                tolerance_m: float = 0.05, smooth: float = 0.05):
    """Frame k−1's display luminance at the points frame k shows: each covered pixel's world point
    (``position`` (H, W, 3), ``normal``) projected with frame k−1's ``prev_view_proj`` and ``prev_lum``
    interpolated bilinearly there. Returns (values (H, W), mask): the mask keeps the pixels whose 4 taps
    lie in the image and show the same surface — the taps' normals (``prev_normal``) within 2.6° of the
    point's and their points (``prev_position``) within ``tolerance_m`` of its plane (elsewhere the point
    was hidden in frame k−1 or sits on an edge: a disocclusion) — and whose taps differ by at most
    ``smooth`` of their mean: across a sharp edge (of a shadow, a texture) a point-sampled pixel steps
    by itself as the edge crosses its centre, whatever the renderer does."""
    h, w = prev_lum.shape
    p = np.asarray(position, np.float64).reshape(-1, 3)
    n = np.asarray(normal, np.float64).reshape(-1, 3)
    clip = np.concatenate([p, np.ones((len(p), 1))], 1) @ np.asarray(prev_view_proj, np.float64).T
    wc = np.where(clip[:, 3] > 1e-9, clip[:, 3], 1e-9)
    x = (clip[:, 0] / wc * 0.5 + 0.5) * w - 0.5
    y = (1.0 - (clip[:, 1] / wc * 0.5 + 0.5)) * h - 0.5
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    ok = covered.reshape(-1) & (x0 >= 0) & (y0 >= 0) & (x0 < w - 1) & (y0 < h - 1) & (clip[:, 3] > 1e-9)
    x0, y0 = np.clip(x0, 0, w - 2), np.clip(y0, 0, h - 2)
    fx, fy = x - x0, y - y0
    val = np.zeros(len(p))
    lo, hi = np.full(len(p), np.inf), np.full(len(p), -np.inf)
    for dy, dx, wt in ((0, 0, (1 - fx) * (1 - fy)), (0, 1, fx * (1 - fy)), (1, 0, (1 - fx) * fy), (1, 1, fx * fy)):
        rr, cc = y0 + dy, x0 + dx
        ok &= np.sum(prev_normal[rr, cc] * n, axis=1) > 0.999
        ok &= np.abs(np.sum((prev_position[rr, cc] - p) * n, axis=1)) <= tolerance_m
        tap = prev_lum[rr, cc]
        val += wt * tap
        lo, hi = np.minimum(lo, tap), np.maximum(hi, tap)
    ok &= hi - lo <= smooth * np.maximum(val, DISPLAY_FLOOR)
    return val.reshape(h, w), ok.reshape(h, w)


def camera_pan(quality: str, frames: int = 40, size=(160, 90), step_m: float = CAMERA_STEP_M, start_frame: int = 0,
               warmup: int = 0, scene_name: str = "courtyard", overrides: dict | None = None, device=None,
               tolerance_m: float = 0.05) -> dict:
    """The sun still, the camera (and its target) moved ``step_m`` per frame along its right vector
    (``pan_camera``; frame k at k·step_m, started and measured as in ``sun_sweep``). A diffuse point's
    radiance does not depend on the camera, so frame k is compared with frame k−1 reprojected
    (``reprojected``: bilinear; left out the pixels whose reprojected surface disagrees — disocclusions
    and edges — or whose neighbourhood in frame k−1 has a sharp edge, and the pixels either frame
    ray-traced, mirrors and glass, whose radiance moves with the camera). The steps are
    ``frame_step``'s over the pixels kept, ``matched`` the fewest kept in a step (a fraction of the
    image); ``parts_p99`` as in ``sun_sweep``, over the same pixels."""
    scene = load(scene_name)
    base = scene.camera
    cfg = preset_config(quality, overrides)
    r = Renderer(scene, *size, device=device, config=cfg)
    w, h = size
    mean, p99, parts, matched = [], [], {"direct": [], "indirect": []}, []
    prev = None
    finite = True
    try:
        for k in range(start_frame - warmup, start_frame + frames + 1):
            scene.camera = cam = pan_camera(base, step_m * k)
            f = r.render(read_back=("hdr", "aovs"))
            finite &= bool(np.all(np.isfinite(f.hdr)))
            covered = np.isfinite(f.aovs["depth"][..., 0])
            traced = f.aovs["rt_mask"][..., 0] > 0 if "rt_mask" in f.aovs else np.zeros_like(covered)
            vp = cam.projection_matrix(w / h) @ cam.view_matrix()
            lum = display_luminance(f.hdr, cfg.exposure)
            cur = {"lum": lum, "hdr": f.hdr, "direct": f.aovs["direct"], "position": f.aovs["position"],
                   "normal": f.aovs["normal"], "vp": vp, "traced": traced}
            if prev is not None and k > start_frame:
                ok = covered & ~traced
                geo = (prev["position"], prev["normal"], prev["vp"], f.aovs["position"], f.aovs["normal"], ok,
                       tolerance_m)
                before, keep = reprojected(prev["lum"], *geo)
                back, _ = reprojected(prev["traced"].astype(np.float64), *geo, smooth=np.inf)
                keep &= back == 0.0  # no tap ray-traced in frame k−1 either
                m, p = frame_step(before, lum, keep)
                mean.append(m)
                p99.append(p)
                matched.append(float(keep.mean()))
                parts_prev = {}
                for name, img in (("hdr", prev["hdr"]), ("direct", prev["direct"])):
                    chans = [reprojected(img[..., c], *geo, smooth=np.inf)[0] for c in range(3)]
                    parts_prev[name] = np.stack(chans, axis=-1)
                parts["direct"].append(_component_p99(parts_prev["hdr"], parts_prev["direct"], f.aovs["direct"], keep))
                parts["indirect"].append(_component_p99(parts_prev["hdr"], parts_prev["hdr"] - parts_prev["direct"],
                                                        f.hdr - f.aovs["direct"], keep))
            prev = cur
    finally:
        r.close()
    return _summary(mean, p99, parts, finite=finite, quality=quality, frames=frames, size=list(size), step_m=step_m,
                    start_frame=start_frame, matched=float(min(matched, default=0.0)))


TEMPORAL_SWITCHES = (
    ("shadow tiles all redrawn every frame", {"shadow.stagger": False}),
    ("LPV cascades all updated every frame", {"lpv.stagger": False}),
    ("LPV light switched at once", {"lpv.temporal_blend": 1.0}),
    ("indirect light without its history", {"indirect.history": 1.0}),
    ("sky volume all re-lit every frame", {"sky.transfer_layers": 0, "sky.layers_per_frame": 1 << 10}),
    ("no LPV", {"lpv.enabled": False}),
)
"""The switches the temporal-stability breakdown turns, one at a time: (what it does, overrides for
``preset_config``). A switch that does not change a preset's settings is not run for it."""


def switch_applies(quality: str, overrides: dict) -> bool:
    """Whether ``overrides`` change what preset ``quality`` renders: its settings change (False also
    where a field does not exist), not only those of a part it leaves off (an LPV it does not use,
    the history of indirect light it computes at full resolution)."""
    base = RenderConfig.preset(quality)
    for key in overrides:
        if key.startswith("lpv.") and not base.lpv.enabled:
            return False
        if key == "indirect.history" and base.indirect.scale == 1:
            return False
        if key.startswith("sky") and base.sky.method != "layers" and base.sky.transfer_layers == 0:
            return False  # every probe is re-lit every frame already
    try:
        return preset_config(quality, overrides) != base
    except (TypeError, AttributeError):
        return False


def _pct(x: float) -> str:
    return f"{100.0 * float(x):.2f} %"


def temporal_stability_markdown(now: dict, baseline: dict | None = None) -> str:
    """The temporal-stability table of ``docs/stability.md`` from ``benchmarks/results/
    temporal_stability.json`` (``now``) and, beside it, the same measurement of the renderer without
    its temporal mitigations (``temporal_stability_baseline.json``, its commit recorded there): per
    preset, the worst mean-luminance step and the worst 99th-percentile pixel step of the sun sweep and
    of the camera pan."""
    goal = f"goal ≤ {_pct(now['bounds']['mean_step'])} / ≤ {_pct(now['bounds']['p99_step'])}"
    header = ["preset", "sun sweep: worst mean step", "sun sweep: worst p99 pixel step",
              "camera pan: worst mean step", "camera pan: worst p99 pixel step"]
    rows = []
    for q, r in now["presets"].items():
        b = (baseline or {}).get("presets", {}).get(q)
        cells = [f"`{q}`"]
        for case in ("sun", "camera"):
            for key in ("worst_mean_step", "worst_p99_step"):
                text = _pct(r[case][key])
                if b is not None and case in b:
                    text = f"{_pct(b[case][key])} → **{text}**"
                cells.append(text)
        rows.append(cells)
    lines = ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    lines += ["| " + " | ".join(c) + " |" for c in rows]
    note = (f"{now['size'][0]}×{now['size'][1]}, {now['scene']}, {now['frames']} frame-to-frame steps each "
            f"({goal}); " + ("the renderer without its temporal mitigations → **with them**." if baseline
                                else "with the temporal mitigations."))
    return "\n".join(lines) + "\n\n" + note


def temporal_breakdown_markdown(now: dict, baseline: dict | None = None) -> str:
    """Where the sun sweep's pixel steps come from, per preset: the worst 99th-percentile pixel step as
    measured, of the direct sun light and of the rest alone (``parts``), and with each switch of
    ``TEMPORAL_SWITCHES`` that applies turned; without the temporal mitigations → with them where
    both have it."""
    header = ["preset", "what", "worst p99 pixel step"]
    rows = []
    for q, r in now["presets"].items():
        b = (baseline or {}).get("presets", {}).get(q)
        bb = {row["switch"]: row for row in (baseline or {}).get("breakdown", {}).get(q, [])}

        def cell(value, before):
            return _pct(value) if before is None else f"{_pct(before)} → **{_pct(value)}**"

        rows.append([f"`{q}`", "as it renders", cell(r["sun"]["worst_p99_step"], b and b["sun"]["worst_p99_step"])])
        for part, label in (("direct", "the direct sun light's step alone"), ("indirect", "the rest's step alone")):
            rows.append([f"`{q}`", label, cell(r["sun"]["worst_parts_p99"][part],
                                                b and b["sun"]["worst_parts_p99"][part])])
        for row in now.get("breakdown", {}).get(q, []):
            before = bb.get(row["switch"])
            rows.append([f"`{q}`", row["switch"], cell(row["worst_p99_step"], before and before["worst_p99_step"])])
    lines = ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    lines += ["| " + " | ".join(c) + " |" for c in rows]
    return "\n".join(lines) + ("\n\nThe parts are each part's step over the pixel's HDR luminance (before the tone "
                               "map); the switches are turned one at a time.")

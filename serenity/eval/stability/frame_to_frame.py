"""Frame to frame on a small scene: the sun moving against a converged render of every frame, and the
camera on ``serenity bench``'s path, where a diffuse point's exact radiance does not change.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from serenity.bench import camera_path
from serenity.config import LPVConfig, RenderConfig, SkyConfig, SSAOConfig
from serenity.eval.stability.harness import Case
from serenity.frame import Renderer
from serenity.scene import load
from serenity.scene.model import direction_from_angles


def _luma(img):
    return img @ np.array([0.2126, 0.7152, 0.0722], np.float32)


def sun_motion_sequence(frames: int = 60, step_deg: float = 0.05, size=(64, 36), scene_name: str = "thin-wall",
                        rebuild_angle_deg: float = 0.5, start_elevation: float = 12.0, device=None,
                        probes: tuple[int, int, int] | None = None, rays: int = 256, gi: dict | None = None,
                        sky_map_size: int = 256) -> dict:
    """Camera still, the sun sinking ``step_deg`` per frame from ``start_elevation``: the renderer as a
    real-time app runs it (one sky layer per frame, the sky map rebaked every ``rebuild_angle_deg``)
    beside a converged one (every layer and the sky map redone each frame). Per frame k:
    change c_k = mean|I_k − I_{k−1}|/mean I (luminance), the converged change r_k likewise, and lag
    e_k = mean|I_k − R_k|/mean R_k. Returns the arrays, the largest step excess max(c_k − r_k)
    ("pop"), the largest lag, the mean ms per frame of both, the first/last images and the
    per-pixel error of the worst-lag frame. ``probes`` / ``rays``: the sky volume's resolution (None:
    its default), rays per probe and sky map size; ``gi``: further RenderConfig fields (e.g.
    ``lpv=LPVConfig(enabled=False)``)."""
    runs = {}
    for label, layers, angle in (("ours", 1, rebuild_angle_deg), ("converged", 1 << 10, 0.0)):
        scene = load(scene_name)
        az = float(scene.sun.azimuth_deg)
        cfg = RenderConfig(**(gi or {}), sky=SkyConfig(rebuild_angle_deg=angle, resolution=probes, rays_per_probe=rays,
                                                      sky_map_size=sky_map_size, layers_per_frame=layers))
        if label == "converged":  # nothing carried over from the last frame either
            cfg = dataclasses.replace(cfg, indirect=dataclasses.replace(cfg.indirect, history=1.0),
                                      lpv=dataclasses.replace(cfg.lpv, temporal_blend=1.0))
        r = Renderer(scene, *size, device=device, config=cfg)
        imgs, ms = [], []
        for k in range(frames + 1):
            scene.sun.direction = direction_from_angles(start_elevation - step_deg * k, az)
            t0 = time.perf_counter()
            f = r.render()
            if k:
                ms.append((time.perf_counter() - t0) * 1e3)
            imgs.append(_luma(f.hdr))
        r.close()
        runs[label] = (np.array(imgs), float(np.mean(ms)))
    ours, ref = runs["ours"][0], runs["converged"][0]
    mean = np.maximum(ref.mean(axis=(1, 2)), 1e-9)
    c = np.abs(np.diff(ours, axis=0)).mean(axis=(1, 2)) / mean[1:]
    rr = np.abs(np.diff(ref, axis=0)).mean(axis=(1, 2)) / mean[1:]
    lag = np.abs(ours - ref).mean(axis=(1, 2)) / mean
    worst = int(np.argmax(lag))
    return {"change": c, "reference_change": rr, "lag": lag, "pop": float(np.max(c - rr)),
            "max_lag": float(lag.max()), "ms": runs["ours"][1], "ms_converged": runs["converged"][1],
            "finite": bool(np.all(np.isfinite(ours))), "min": float(ours.min()),
            "images": {"exact": ref[worst], "ours": ours[worst], "error": np.abs(ours[worst] - ref[worst])}}


def sun_motion_case(frames: int = 60, size=(96, 54), device=None) -> Case:
    """Frame-to-frame with the sun moving 0.05°/frame: the largest per-frame change beyond the converged
    reference's own change, with the default sky-map cache (rebaked every 0.5°) vs rebaked every 0.1°.
    Images: the frame lagging most behind the converged render (of each run; the error map: 0.1°)."""
    a = sun_motion_sequence(frames, 0.05, size, rebuild_angle_deg=0.5, device=device)
    b = sun_motion_sequence(frames, 0.05, size, rebuild_angle_deg=0.1, device=device)
    return Case(f"sun moving 0.05 deg/frame, {frames} frames (thin-wall)", "frame to frame",
                "max per-frame change beyond the converged render's (of mean luminance)",
                "sky map rebaked every 0.1 deg (vs 0.5)", a["pop"], b["pop"], a["ms"], b["ms"], exact=0.0,
                images={"exact": a["images"]["exact"], "without": a["images"]["ours"], "with": b["images"]["ours"],
                        "error": b["images"]["error"]},
                extra={"max_lag_default": a["max_lag"], "max_lag_0.1deg": b["max_lag"],
                       "ms_converged_every_frame": a["ms_converged"]})


def camera_path_sequence(frames: int = 60, size=(96, 54), scene_name: str = "thin-wall", gi: bool | dict = True,
                         device=None, tolerance: float = 0.01) -> dict:
    """Sun still, the camera along ``serenity bench``'s path (orbit ±12°, dolly ±10 %). Every surface of
    the scene is diffuse, so the exact outgoing radiance of a world point does not change with the
    camera: for each pixel of frame k whose surface point reappears in frame k−1 (reprojected to the
    the previous frame's luminance interpolated bilinearly there, all 4 taps on the same surface: same
    normal, within ``tolerance`` m of its plane), the change |I_k − I_{k−1}| over the mean. ``gi=False``
    renders direct light only (no LPV, sky volume, SSAO) — the floor the nearest-pixel reprojection
    itself leaves; a dict gives RenderConfig fields (e.g. {"lpv": LPVConfig(enabled=False)}). Returns per-frame flicker,
    its max and mean, ms per frame, and the fewest points matched in a frame (``matched``). The
    interpolation itself errs across shadow edges, so points whose 4 taps differ by more than 5 % are
    left out; the direct-only run measures what error remains from the reprojection."""
    scene = load(scene_name)
    base = scene.camera
    if isinstance(gi, dict):
        cfg = RenderConfig(**gi)
    else:
        cfg = RenderConfig() if gi else RenderConfig(lpv=LPVConfig(enabled=False), sky=SkyConfig(enabled=False),
                                                     ssao=SSAOConfig(enabled=False))
    r = Renderer(scene, *size, device=device, config=cfg)
    w, h = size
    prev, flicker, ms, matched = None, [], [], []
    worst = (0.0, None)
    for k in range(frames + 1):
        scene.camera = camera_path(base, k / frames)
        t0 = time.perf_counter()
        f = r.render()
        if k:
            ms.append((time.perf_counter() - t0) * 1e3)
        lum, pos = _luma(f.hdr), f.aovs["position"]
        covered = np.isfinite(f.aovs["depth"][..., 0])
        cam = scene.camera
        vp = cam.projection_matrix(w / h) @ cam.view_matrix()
        if prev is not None:
            plum, ppos, pcov, pvp, pnrm = prev
            p, n = pos[covered], f.aovs["normal"][covered]
            c = np.concatenate([p, np.ones((len(p), 1))], 1) @ pvp.T
            ndc = c[:, :3] / c[:, 3:4]
            x = (ndc[:, 0] * 0.5 + 0.5) * w - 0.5
            y = (1 - (ndc[:, 1] * 0.5 + 0.5)) * h - 0.5
            x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
            ok = (x0 >= 0) & (x0 < w - 1) & (y0 >= 0) & (y0 < h - 1)
            x0, y0 = np.clip(x0, 0, w - 2), np.clip(y0, 0, h - 2)
            fx, fy = x - x0, y - y0
            val_prev = np.zeros(len(p))
            t_lo, t_hi = np.full(len(p), np.inf), np.full(len(p), -np.inf)
            for dy, dx, wt in ((0, 0, (1 - fx) * (1 - fy)), (0, 1, fx * (1 - fy)), (1, 0, (1 - fx) * fy),
                               (1, 1, fx * fy)):
                rr, cc = y0 + dy, x0 + dx
                # the same surface at all 4 taps: covered, same normal, within ``tolerance`` of its plane
                ok &= pcov[rr, cc] & (np.sum(pnrm[rr, cc] * n, axis=1) > 0.999)
                ok &= np.abs(np.sum((ppos[rr, cc] - p) * n, axis=1)) < tolerance
                val_prev += wt * plum[rr, cc]
                t_lo, t_hi = np.minimum(t_lo, plum[rr, cc]), np.maximum(t_hi, plum[rr, cc])
            ok &= t_hi - t_lo <= 0.05 * np.maximum(val_prev, 1e-9)  # smooth there: not across a shadow edge
            d = np.abs(lum[covered][ok] - val_prev[ok])
            val = float(d.mean() / max(lum[covered][ok].mean(), 1e-9)) if ok.any() else 0.0
            flicker.append(val)
            matched.append(int(ok.sum()))
            if val >= worst[0]:
                img = np.full((h, w), np.nan)
                sub = np.full(int(covered.sum()), np.nan)
                sub[ok] = d
                img[covered] = sub
                worst = (val, img)
        prev = (lum, pos, covered, vp, f.aovs["normal"])
    r.close()
    return {"flicker": np.array(flicker), "max": float(np.max(flicker)), "mean": float(np.mean(flicker)),
            "ms": float(np.mean(ms)), "worst_image": worst[1], "last": lum, "matched": int(np.min(matched))}


def camera_path_case(frames: int = 60, size=(96, 54), device=None) -> Case:
    """Frame-to-frame with the camera on the bench path (diffuse scene: exact change 0). No switch to
    compare: the column "without" is direct light only (the reprojection floor), "with" the full
    renderer (LPV, sky volume, SSAO)."""
    a = camera_path_sequence(frames, size, gi=False, device=device)
    b = camera_path_sequence(frames, size, gi=True, device=device)

    c = camera_path_sequence(frames, size, gi={"lpv": LPVConfig(enabled=False)}, device=device)
    return Case(f"camera on the bench path, {frames} frames (thin-wall)", "frame to frame",
                "max over frames of mean abs(change) of reprojected diffuse points (of mean luminance)",
                "none to switch: direct only (floor) vs full GI", a["max"], b["max"], a["ms"], b["ms"], exact=0.0,
                images={"exact": np.where(np.isnan(b["worst_image"]), np.nan, 0.0), "without": a["last"],
                        "with": b["last"], "error": b["worst_image"]},
                extra={"mean_direct_only": a["mean"], "mean_full": b["mean"], "fewest_points_matched": b["matched"],
                       "max_without_lpv": c["max"], "mean_without_lpv": c["mean"]})

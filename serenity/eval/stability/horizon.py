"""The sky and the sun near and below the horizon: a sunset on a west-facing wall, its radiance step
by step against the exact ρ/π·(E_sun + E_sky).
"""

from __future__ import annotations

import math
import time

import numpy as np

from serenity.config import IndirectConfig, LPVConfig, RenderConfig, SkyConfig, SSAOConfig
from serenity.eval.stability.harness import Case, brute_sky_irradiance
from serenity.frame import Renderer
from serenity.kernels.atmosphere import bake_sky_map, horizontal_irradiance, scene_sun_irradiance
from serenity.scene.model import Camera, Sky, Sun, direction_from_angles
from serenity.scene.procedural import SceneBuilder


def horizon_scene(elevation: float):
    """A 4 × 3 m grey block (albedo 0.5) on a grey plane under the atmosphere, the sun ``elevation``°
    in the west (azimuth 270°); the camera looks at the block's sunlit west face."""
    b = SceneBuilder()
    b.material("ground", albedo=(0.5, 0.5, 0.5))
    b.material("block", albedo=(0.5, 0.5, 0.5))
    b.rect("ground", (0.0, 0.0, 0.0), (30.0, 0.0, 0.0), (0.0, 0.0, -30.0))
    b.box("block", (0.0, 0.0, -2.0), (3.0, 4.0, 2.0), skip=("-y",))
    cam = Camera(position=(-8.0, 2.0, 3.0), target=(0.0, 1.5, 0.0), fov_y_deg=50.0, near=0.1, far=200.0)
    return b.scene("horizon", cam, Sun(direction_from_angles(elevation, 270.0)), Sky())


def horizon_sweep(elevations, size=(48, 27), device=None, rebuild_angle_deg: float = 0.5,
                  probes: tuple[int, int, int] | None = None, rays: int = 256) -> dict:
    """Render ``horizon_scene`` at each elevation (one renderer, the sky volume rebuilt every step so the image is
    converged for that sun; no LPV/SSAO, no history of the indirect light) and compare the mean radiance (red)
    of the west wall's pixels with the exact ρ/π·(E_sun·max(0, n·s) + E_sky(n)) — E_sun the model's sun
    (:func:`~serenity.kernels.atmosphere.scene_sun_irradiance`), E_sky(n) the brute-force cosine integral of a
    sky map baked for this step's sun (the renderer's cached map is rebaked only when the sun moved more than
    ``rebuild_angle_deg``) and the volume's ground model. Returns per-step rows, whether every image was finite,
    the smallest radiance, and the largest step excess (|Δours| − |Δexact|) over the larger exact value of the
    two steps. ``probes`` / ``rays``: the sky volume's resolution (None: its default) and rays per probe."""
    scene = horizon_scene(float(elevations[0]))
    cfg = RenderConfig(lpv=LPVConfig(enabled=False), ssao=SSAOConfig(enabled=False),
                       sky=SkyConfig(rebuild_angle_deg=rebuild_angle_deg, resolution=probes, rays_per_probe=rays,
                                     layers_per_frame=1 << 10),
                       indirect=IndirectConfig(history=1.0))  # each step converged: no light carried over from the last
    r = Renderer(scene, *size, device=device, config=cfg)
    n_wall = np.array([-1.0, 0.0, 0.0])
    rows, finite, lo, ours, exact, images = [], True, np.inf, [], [], []
    ms = []
    for el in elevations:
        scene.sun.direction = direction_from_angles(float(el), 270.0)
        t0 = time.perf_counter()
        f = r.render()
        ms.append((time.perf_counter() - t0) * 1e3)
        finite &= bool(np.all(np.isfinite(f.hdr)))
        lo = min(lo, float(f.hdr.min()))
        wall = np.isfinite(f.aovs["depth"][..., 0]) & (f.aovs["normal"][..., 0] < -0.99)
        sky = bake_sky_map(scene.sun.direction, size=64, device=device)  # this step's sky, not the cached one
        ground = r.sky_volume.config.ground_albedo / math.pi * horizontal_irradiance(sky)
        e_sky = brute_sky_irradiance(sky, ground, n_wall[None], n_dirs=8192)[0]
        e_sun = scene_sun_irradiance(scene) * max(0.0, float(n_wall @ scene.sun.direction))
        ex = 0.5 / math.pi * (e_sun + e_sky)
        ours.append(float(f.hdr[wall][:, 0].mean()))
        exact.append(float(ex[0]))
        images.append(f.hdr[..., 0])
    r.close()
    ours, exact = np.array(ours), np.array(exact)
    big = np.maximum(exact[1:], exact[:-1])
    excess = (np.abs(np.diff(ours)) - np.abs(np.diff(exact))) / big
    for k, el in enumerate(elevations):
        rows.append({"elevation": float(el), "ours": float(ours[k]), "exact": float(exact[k]),
                     "step_excess": float(excess[k - 1]) if k else 0.0})
    return {"steps": rows, "finite": finite, "min_radiance": lo, "max_excess_step": float(excess.max()),
            "max_rel_error": float(np.max(np.abs(ours - exact) / np.maximum(exact, 1e-6))),
            "ms": float(np.median(ms[1:] or ms)), "images": images}


def horizon_case(size=(48, 27), device=None) -> Case:
    """Sunset on a west-facing wall, sun from +1° to −1.5° in 0.25° steps: the largest step of the
    wall's mean radiance beyond the exact step (of the larger exact value), the default sky-map cache
    (rebaked past 0.5°) vs rebaked past 0.1°. Images: the wall's red radiance per step (a strip:
    exact, default, 0.1°)."""
    els = np.arange(1.0, -1.51, -0.25)
    a = horizon_sweep(els, size, device, rebuild_angle_deg=0.5)
    b = horizon_sweep(els, size, device, rebuild_angle_deg=0.1)
    ex = np.array([[r["exact"] for r in a["steps"]]])
    wa = np.array([[r["ours"] for r in a["steps"]]])
    wb = np.array([[r["ours"] for r in b["steps"]]])
    return Case("sunset: sun +1 to -1.5 deg (west wall)", "sky & sun at the horizon",
                "max radiance step beyond the exact step (of the exact value)", "sky map rebaked every 0.1 deg",
                a["max_excess_step"], b["max_excess_step"], a["ms"], b["ms"], exact=0.0,
                images={"exact": ex, "without": wa, "with": wb, "error": np.abs(wa - ex) / ex.max()},
                extra={"elevations": els.tolist(), "max_rel_error_default": a["max_rel_error"],
                       "max_rel_error_0.1deg": b["max_rel_error"], "finite": a["finite"] and b["finite"],
                       "min_radiance": min(a["min_radiance"], b["min_radiance"])})

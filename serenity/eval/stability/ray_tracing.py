"""Where the ray tracing fails: refraction through two interfaces of a glass slab and through nested
glass of one index (Snell's law exactly), and whether geometry seen only in a mirror is shadowed
(exact sun-disc visibility at the reflected hits).
"""

from __future__ import annotations

import math

import numpy as np

from serenity.config import LPVConfig, RayTracingConfig, RenderConfig, ScheduleConfig, SkyConfig, SSAOConfig
from serenity.eval.exact import exact_sun_visibility
from serenity.eval.stability.harness import Case, timed
from serenity.frame import Renderer
from serenity.kernels.atmosphere import scene_sun_irradiance
from serenity.kernels.raytrace import RayTracer
from serenity.raster.interop import read_texture
from serenity.scene import load
from serenity.scene.model import Camera, Sun
from serenity.scene.procedural import SceneBuilder

GLASS_SLAB = (np.array([-2.6, 0.0, -0.25]), np.array([-1.0, 1.2, 0.25]))
"""The ``glass`` scene's slab (m) and its index of refraction is the glass material's (1.5)."""


def _refract(d, n, eta):
    """Snell refraction of unit rows d at unit normals n facing against d, eta = n1/n2."""
    c = -np.sum(d * n, axis=1, keepdims=True)
    k = 1 - eta * eta * (1 - c * c)
    return eta * d + (eta * c - np.sqrt(np.maximum(k, 0))) * n


def glass_slab_rays(count: int = 64, seed: int = 0):
    """Rays from in front of the glass slab through its +z face, out of its −z face and onto the floor
    (exact path by Snell's law, checked to cross the two big faces and reach the floor before the
    boxes behind): (origins, directions, exact floor hits)."""
    rng = np.random.default_rng(seed)
    lo, hi = GLASS_SLAB
    ior = 1.5
    o, d, hit = [], [], []
    while len(o) < count:
        entry = np.array([rng.uniform(lo[0] + 0.3, hi[0] - 0.3), rng.uniform(0.5, 1.0), hi[2]])
        src = entry + np.array([rng.uniform(-0.8, 0.8), rng.uniform(0.3, 1.0), 1.5])
        di = (entry - src) / np.linalg.norm(entry - src)
        dt = _refract(di[None], np.array([[0.0, 0.0, 1.0]]), 1 / ior)[0]
        exit_ = entry + dt * ((lo[2] - hi[2]) / dt[2])
        if not (lo[0] < exit_[0] < hi[0] and lo[1] < exit_[1] < hi[1]):
            continue
        do = _refract(dt[None], np.array([[0.0, 0.0, 1.0]]), ior)[0]
        floor = exit_ + do * (-exit_[1] / do[1])
        if floor[2] < -1.85 or abs(floor[0]) > 9:
            continue
        o.append(src)
        d.append(di)
        hit.append(floor)
    return np.array(o), np.array(d), np.array(hit)


def glass_slab_case(count: int = 64, device=None) -> Case:
    """Refraction through the ``glass`` scene's slab (two interfaces): distance of the reported hit
    from the exact floor hit, the paper's single refraction (transmissions 0: the slab's own back
    face) vs bending through up to 4 interfaces. Images: hit distance errors per ray (1 row)."""
    tracer = RayTracer(load("glass"), device=device)
    o, d, exact = glass_slab_rays(count)
    out = {}
    for k in (0, 4):
        g, ms = timed(tracer.trace, o, d, transmissions=k)
        g, ms = timed(tracer.trace, o, d, transmissions=k)
        err = np.linalg.norm(g["position"][:, :3] - exact, axis=1)
        err = np.where(g["position"][:, 3] > 0, err, np.inf)
        out[k] = (err, ms)
    a, b = out[0], out[4]
    return Case("glass slab refraction (2 interfaces)", "ray tracing", "max distance of hit from exact floor hit (m)",
                "transmissions = 4 (vs the paper's 1)", float(a[0].max()), float(b[0].max()), a[1], b[1], exact=0.0,
                images={"exact": np.zeros((1, count)), "without": a[0][None], "with": b[0][None],
                        "error": b[0][None]})


def mirror_shadow_case(size=(160, 90), device=None, sun_shadows: str = "traced") -> Case:
    """Off-screen geometry seen in the ``mirror-box`` mirror (behind the camera, outside the main view's
    shadow cascades): is it shadowed? For the reflection rays, the exact sun-disc visibility at their
    hits (the kd-tree) vs the answer the RT direct-lighting pass uses (its direct term over the
    unshadowed one): the tracer's shadow ray by default, ``sun_shadows="osm"`` (``RayTracingConfig``)
    the overlapped shadow maps. Error: fraction of hits whose shadow state (exact visibility < 0.5)
    differs; "without" lights every hit as unshadowed."""
    scene = load("mirror-box")
    cfg = RenderConfig(lpv=LPVConfig(enabled=False), sky=SkyConfig(enabled=False), ssao=SSAOConfig(enabled=False),
                       schedule=ScheduleConfig(overlap=False), rt=RayTracingConfig(sun_shadows=sun_shadows))
    r = Renderer(scene, *size, device=device, config=cfg)
    r.render()
    f, ms = timed(r.render)
    w, h = size
    rcb = r.raycast_pass.read()
    sel = rcb.reflection_rays()
    g = r.tracer.trace(rcb.origins[sel], rcb.reflect_dirs[sel], rcb.cone_width[sel], rcb.cone_spread[sel])
    pix = rcb.pixels[sel]
    texel = np.arange(len(pix))  # packed RT G-buffer: the k-th reflection ray is texel k (rt_gbuffer doc)
    hit = g["position"][:, 3] > 0
    p, n = g["position"][hit, :3].astype(np.float64), g["normal"][hit, :3].astype(np.float64)
    alb = g["albedo"][hit, :3].astype(np.float64)
    sun = scene.sun.direction
    cos = n @ sun
    lit_side = cos > 0.2
    p, n, alb, cos = p[lit_side], n[lit_side], alb[lit_side], cos[lit_side]
    pix, texel = pix[hit][lit_side], texel[hit][lit_side]
    vis = exact_sun_visibility(r.tracer.tree, p, n, sun, scene.sun.angular_diameter_deg, n=64)
    direct = read_texture(r.rt_deferred.direct, 3)[::-1].reshape(-1, 3)  # GL row order: texel k = (k mod W, k div W)

    e = scene_sun_irradiance(scene)
    ours = direct[texel, 1] / np.maximum(alb[:, 1] / math.pi * e[1] * cos, 1e-9)
    r.close()
    shadowed = vis < 0.5
    err_with = float(np.mean((ours < 0.5) != shadowed))
    err_without = float(np.mean(shadowed))
    img = np.full(h * w, np.nan)
    ex_img = np.full(h * w, np.nan)
    img[pix] = np.clip(ours, 0, 1.5)
    ex_img[pix] = vis
    shadows = "overlapped shadow maps" if sun_shadows == "osm" else "traced sun shadow rays"
    return Case("mirror: off-screen geometry in shadow", "ray tracing",
                "fraction of reflected hits with the wrong shadow state", f"{shadows} (vs unshadowed)",
                err_without, err_with, 0.0, f.timings.get("shadow maps (OSM)", 0.0), exact=0.0,
                images={"exact": ex_img.reshape(h, w), "without": np.where(np.isnan(img), np.nan, 1.0).reshape(h, w),
                        "with": img.reshape(h, w), "error": np.abs(img - ex_img).reshape(h, w)},
                extra={"reflected_hits": int(len(vis)), "exact_shadowed_fraction": err_without})


def nested_glass_error(count: int = 32, transmissions: int = 4, seed: int = 1, device=None):
    """A glass block (x ∈ [−1, 1], y ∈ [0, 2], z ∈ [−0.5, 0.5]) holding a smaller block of the same
    glass (x ∈ [−0.5, 0.5], y ∈ [0.5, 1.5], z ∈ [−0.25, 0.25]) in front of a wall at z = −3. Exact:
    the inner faces separate glass from the same glass, so rays bend only at the outer faces and
    leave parallel to where they came from. Returns the distances (m) of the traced wall hits from
    the exact ones (inf where the ray did not reach the wall)."""
    b = SceneBuilder()
    b.material("glass", albedo=(0.95,) * 3, transparency=0.95, ior=1.5)
    b.material("wall", albedo=(0.5,) * 3)
    b.box("glass", (-1.0, 0.0, -0.5), (1.0, 2.0, 0.5))
    b.box("glass", (-0.5, 0.5, -0.25), (0.5, 1.5, 0.25))
    b.rect("wall", (0.0, 1.0, -3.0), (6.0, 0.0, 0.0), (0.0, 4.0, 0.0))
    scene = b.scene("nested-glass", Camera((0.0, 1.0, 4.0), (0.0, 1.0, 0.0)), Sun((0.3, 1.0, 0.2)))
    tracer = RayTracer(scene, device=device, cache=False)
    rng = np.random.default_rng(seed)
    entry = np.stack([rng.uniform(-0.3, 0.3, count), rng.uniform(0.8, 1.2, count), np.full(count, 0.5)], 1)
    src = entry + np.stack([rng.uniform(-0.6, 0.6, count), rng.uniform(-0.3, 0.3, count), np.full(count, 2.0)], 1)
    d = (entry - src) / np.linalg.norm(entry - src, axis=1, keepdims=True)
    z = np.array([[0.0, 0.0, 1.0]])
    dt = _refract(d, np.repeat(z, count, 0), 1 / 1.5)
    exit_ = entry + dt * ((-0.5 - 0.5) / dt[:, 2:3])
    do = _refract(dt, np.repeat(z, count, 0), 1.5)
    exact = exit_ + do * ((-3.0 - exit_[:, 2:3]) / do[:, 2:3])
    g = tracer.trace(src, d, transmissions=transmissions)
    err = np.linalg.norm(g["position"][:, :3] - exact, axis=1)
    on_wall = (g["position"][:, 3] > 0) & (np.abs(g["position"][:, 2] + 3.0) < 1e-3)
    return np.where(on_wall, err, np.inf)

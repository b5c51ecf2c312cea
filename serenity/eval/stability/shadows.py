"""Where the sun shadows fail (cascaded shadow maps + PCSS): acne under a grazing sun, peter-panning,
the leak at the foot of a wall seen edge-on, seams between cascades, the penumbra's width; each
against the exact sun-disc visibility traced through the scene's kd-tree.
"""

from __future__ import annotations

import math
import time

import numpy as np

from serenity.config import LPVConfig, RenderConfig, ShadowConfig, SkyConfig, SSAOConfig
from serenity.eval.exact import exact_sun_visibility
from serenity.eval.stability.harness import UP, Case
from serenity.frame import Renderer
from serenity.kernels.kdtree import KdTree
from serenity.raster.shadow import fit_shadow_cascades
from serenity.scene.model import Camera, Sky, Sun, direction_from_angles
from serenity.scene.procedural import SceneBuilder


def shadow_scene(elevation: float, azimuth: float = 90.0, wall: bool = False, box: bool = False,
                 raised: bool = False):
    """A 40 × 40 m grey plane (albedo 0.5) under a sun of 1000 W/m² (black sky), optionally a 2 m
    high, 0.2 m thick wall along z at x ∈ [−0.1, 0.1], z ∈ [−19, 15] and a 2 m cube at the origin
    (x, z ∈ [−1, 1]). The camera looks down −z from (−3, 1.7, 18). ``raised``: a 1 m square 1 m
    under the plane's centre, hidden by it, so the plane is not the scene's bottom plane, which the
    shadow maps leave out (``raster/scene_gl.bottom_plane_triangles``), but a caster like any other."""
    b = SceneBuilder()
    b.material("plane", albedo=(0.5, 0.5, 0.5))
    b.material("block", albedo=(0.5, 0.5, 0.5))
    b.rect("plane", (0.0, 0.0, 0.0), (20.0, 0.0, 0.0), (0.0, 0.0, -20.0))
    if raised:
        b.rect("block", (0.0, -1.0, 0.0), (0.5, 0.0, 0.0), (0.0, 0.0, -0.5))
    if wall:
        b.box("block", (-0.1, 0.0, -19.0), (0.1, 2.0, 15.0), skip=("-y",))
    if box:
        b.box("block", (-1.0, 0.0, -1.0), (1.0, 2.0, 1.0), skip=("-y",))
    cam = Camera(position=(-3.0, 1.7, 18.0), target=(-3.0, 0.3, 0.0), fov_y_deg=50.0, near=0.1, far=100.0)
    sun = Sun(direction_from_angles(elevation, azimuth), irradiance=(1000.0,) * 3)
    return b.scene("shadow-test", cam, sun, Sky(radiance=(0.0, 0.0, 0.0), model="constant"))


def render_sun_visibility(scene, width: int, height: int, shadow, sky: bool = False):
    """Render ``scene`` (direct light only: no LPV, SSAO, sky lighting) and return (visibility
    (H, W) = direct / unshadowed direct on the ground (NaN elsewhere), positions (H, W, 3), the
    ground mask, ms of the frame)."""
    cfg = RenderConfig(lpv=LPVConfig(enabled=False), sky=SkyConfig(enabled=sky), ssao=SSAOConfig(enabled=False),
                       shadow=shadow)
    r = Renderer(scene, width, height, config=cfg)
    r.render()
    t0 = time.perf_counter()
    f = r.render()
    ms = (time.perf_counter() - t0) * 1e3
    r.close()
    pos, nrm = f.aovs["position"], f.aovs["normal"]
    ground = np.isfinite(f.aovs["depth"][..., 0]) & (nrm[..., 1] > 0.99) & (pos[..., 1] < 1e-3)
    unshadowed = 0.5 / math.pi * 1000.0 * max(float(scene.sun.direction[1]), 0.0)
    vis = np.where(ground, f.aovs["direct"][..., 1] / unshadowed, np.nan)
    return vis, pos, ground, ms


def exact_ground_visibility(scene, points, n: int = 256):
    """Exact sun-disc visibility (P,) at ground points (normal +y), traced with the scene's kd-tree."""
    pos, _, _, faces, _ = scene.merged()
    tree = KdTree.build(pos, faces, cache=False)
    return exact_sun_visibility(tree, np.asarray(points, np.float64), np.tile(UP, (len(points), 1)),
                                scene.sun.direction, scene.sun.angular_diameter_deg, n=n)


def shadow_acne_case(elevation: float = 2.0, size=(160, 90)) -> Case:
    """Shadow acne on an open plane under a grazing sun (exact visibility 1 everywhere): fraction of
    ground pixels darker than 0.99 of the unshadowed light, without the constant depth bias (and
    normal offset) vs the defaults; both compare the map with the receiver's plane. Images:
    visibility. The plane is raised over a hidden square (``shadow_scene``):
    as the scene's bottom plane it would be left out of the shadow maps and could not acne at all,
    while any surface above it can (a roof, a terrace, a table)."""
    scene = shadow_scene(elevation, raised=True)
    a = render_sun_visibility(scene, *size, ShadowConfig(bias=0.0, normal_offset=0.0))
    b = render_sun_visibility(scene, *size, ShadowConfig())
    err = [float(np.mean(v[g] < 0.99)) for v, _, g, _ in (a, b)]
    ex = np.where(a[2], 1.0, np.nan)
    return Case(f"shadow acne (sun {elevation} deg, open plane)", "shadows", "fraction of lit ground shadowed",
                "constant depth bias on the receiver's plane", err[0], err[1], a[3], b[3], exact=0.0,
                images={"exact": ex, "without": a[0], "with": b[0], "error": np.abs(b[0] - ex)})


def peter_panning(elevation: float, shadow, size=(160, 90), band: float = 0.25):
    """A 2 m cube on the plane, sun ``elevation``° from the east, the camera looking at the cube's
    shadow side from above: (fraction of ground pixels within ``band`` m of the cube's base on its
    shadow side, in the exact umbra, that come out more than half lit; visibility image; exact
    image; ms)."""
    scene = shadow_scene(elevation, azimuth=90.0, box=True)
    scene.camera = Camera(position=(-3.5, 3.0, 3.0), target=(-1.3, 0.0, 0.0), fov_y_deg=50.0, near=0.05, far=100.0)
    vis, pos, ground, ms = render_sun_visibility(scene, *size, shadow)
    near = ground & (pos[..., 0] < -1.0) & (pos[..., 0] > -1.0 - band) & (np.abs(pos[..., 2]) < 0.8)
    ex_img = np.full(vis.shape, np.nan)
    ex = exact_ground_visibility(scene, pos[near], n=64)
    ex_img[near] = ex
    umbra = ex < 0.01
    return float(np.mean(vis[near][umbra] > 0.5)), vis, ex_img, ms


def peter_panning_case(elevation: float = 10.0, size=(160, 90)) -> Case:
    """Peter-panning: the bias that cures acne detaches shadows from their casters. Fraction of the
    exact umbra within 25 cm of a cube's base rendered more than half lit: no bias vs default bias."""
    a = peter_panning(elevation, ShadowConfig(bias=0.0, normal_offset=0.0), size)
    b = peter_panning(elevation, ShadowConfig(), size)
    return Case(f"peter-panning (sun {elevation} deg, cube contact)", "shadows",
                "fraction of contact umbra rendered lit", "constant depth bias (its cause)", a[0], b[0],
                a[3], b[3], exact=0.0,
                images={"exact": b[2], "without": a[1], "with": b[1], "error": np.abs(b[1] - b[2])})


def contact_leak(shadow, size=(320, 180), band: float = 0.15):
    """The Cornell box's leak in the open: a one-sided 3 m wall (a single quad at x = 0, facing −x)
    on the plane, the sun (70° up, azimuth 170°: 3.4° off the wall's plane) behind it, so the wall
    shadows a 19 cm strip at its foot on the camera's side while nothing is drawn beyond it. The
    shadow maps see the wall almost edge-on; a PCSS/PCF footprint at its foot reaches the texels past
    its edge, which are open. Returns (fraction of ground pixels within ``band`` m of the wall, in
    the exact umbra, that come out more than 5 % lit; visibility image; exact image; ms). A leak
    touches only the pixels whose sample falls within a texel of the foot (the Cornell box's
    worst pixel is one, 0.08 mm inside the wall), so the fraction is small but each is a bright
    pixel on a black one.)"""
    b = SceneBuilder()
    b.material("plane", albedo=(0.5, 0.5, 0.5))
    b.material("block", albedo=(0.5, 0.5, 0.5))
    b.rect("plane", (0.0, 0.0, 0.0), (20.0, 0.0, 0.0), (0.0, 0.0, -20.0))
    b.rect("block", (0.0, 1.5, 0.0), (0.0, 0.0, 10.0), (0.0, 1.5, 0.0))
    cam = Camera(position=(-3.0, 1.5, 5.0), target=(0.0, 0.0, 0.0), fov_y_deg=50.0, near=0.05, far=100.0)
    sun = Sun(direction_from_angles(70.0, 170.0), irradiance=(1000.0,) * 3)
    scene = b.scene("contact-test", cam, sun, Sky(radiance=(0.0, 0.0, 0.0), model="constant"))
    vis, pos, ground, ms = render_sun_visibility(scene, *size, shadow)
    near = ground & (pos[..., 0] < 0.0) & (pos[..., 0] > -band) & (np.abs(pos[..., 2]) < 5.0)
    ex_img = np.full(vis.shape, np.nan)
    ex = exact_ground_visibility(scene, pos[near], n=64)
    ex_img[near] = ex
    umbra = ex < 0.01
    return float(np.mean(vis[near][umbra] > 0.05)), vis, ex_img, ms


def contact_leak_case(size=(320, 180)) -> Case:
    """Contact leak: a floor at the foot of a wall nearly parallel to the sun, lit through the
    shadow map's texel edge (``contact_leak``): without vs with the screen-space contact shadow
    (``ShadowConfig.contact_steps``)."""
    a = contact_leak(ShadowConfig(contact_steps=0), size)
    b = contact_leak(ShadowConfig(), size)
    return Case("contact leak (wall 3.4 deg off the sun, open behind)", "shadows",
                "fraction of contact umbra rendered lit", "screen-space contact shadow", a[0], b[0], a[3], b[3],
                exact=0.0, images={"exact": b[2], "without": a[1], "with": b[1], "error": np.abs(b[1] - b[2])})


def cascade_seams(shadow, size=(320, 180), elevation: float = 30.0):
    """A long 2 m wall along the view direction, sun from the east at ``elevation``°: its shadow's
    edge (x = −2/tan(elevation) − 0.1) runs through every cascade split. Returns (max over splits of
    |mean visibility in the 0.5 m of depth past the split − before it| along the edge band, minus
    the exact's; mean |vis − exact| near the edge; visibility image; exact image; ms)."""
    scene = shadow_scene(elevation, azimuth=90.0, wall=True)
    vis, pos, ground, ms = render_sun_visibility(scene, *size, shadow)
    x_edge = -0.1 - 2.0 / math.tan(math.radians(elevation))
    near = ground & (np.abs(pos[..., 0] - x_edge) < 0.4) & (pos[..., 2] > -18) & (pos[..., 2] < 14)
    ex_img = np.full(vis.shape, np.nan)
    ex = exact_ground_visibility(scene, pos[near], n=64)
    ex_img[near] = ex
    cam = scene.camera
    depth = (pos[near] - cam.position) @ cam.forward
    cascades = fit_shadow_cascades(cam, size[0] / size[1], scene.sun.direction, scene.bounds, shadow.cascades,
                                   shadow.size_for(*size), shadow.split_lambda, shadow.max_distance)
    jumps = []
    v = vis[near]
    for c in cascades[:-1]:
        d = c.far
        lo, hi = (depth > d - 0.5) & (depth < d), (depth >= d) & (depth < d + 0.5)
        if lo.sum() < 4 or hi.sum() < 4:
            continue
        jumps.append(abs(v[hi].mean() - v[lo].mean()) - abs(ex[hi].mean() - ex[lo].mean()))
    return max(jumps) if jumps else 0.0, float(np.mean(np.abs(v - ex))), vis, ex_img, ms, len(jumps)


def cascade_seam_case(size=(320, 180)) -> Case:
    """Cascade seams: the step in the shadow term across each CSM split along a shadow edge that
    runs through all of them, without the cross-fade band (cascade_blend 0) vs the default 0.1."""
    a = cascade_seams(ShadowConfig(cascade_blend=0.0), size)
    b = cascade_seams(ShadowConfig(), size)
    return Case("CSM cascade seams (shadow edge across splits)", "shadows",
                "max step of mean visibility across a split, beyond the exact step", "cascade cross-fade band",
                a[0], b[0], a[4], b[4], exact=0.0,
                images={"exact": b[3], "without": a[2], "with": b[2], "error": np.abs(b[2] - b[3])},
                extra={"mean_abs_error_near_edge_without": a[1], "mean_abs_error_near_edge_with": b[1],
                       "splits_measured": b[5]})


def penumbra(elevation: float, shadow, size=(256, 256)):
    """The shadow of a 2 m cube's top edge under the 0.53° sun at ``elevation``° from the east, seen
    from straight above: (mean |vis − exact| over ground pixels within max(0.3 m, 1.5 exact
    penumbra widths) of the edge, rendered
    10–90 % width / exact width, visibility image, exact image, ms)."""
    scene = shadow_scene(elevation, azimuth=90.0, box=True)
    x_edge = -1.0 - 2.0 / math.tan(math.radians(elevation))
    width_exact = 2.0 * math.radians(scene.sun.angular_diameter_deg) / math.sin(math.radians(elevation)) ** 2
    band = max(0.3, 1.5 * width_exact)
    scene.camera = Camera(position=(x_edge, 1.3 * band / 0.3, 0.0), target=(x_edge, 0.0, 0.0), up=(0.0, 0.0, -1.0),
                          fov_y_deg=30.0, near=0.05, far=60.0)
    vis, pos, ground, ms = render_sun_visibility(scene, *size, shadow)
    near = ground & (np.abs(pos[..., 0] - x_edge) < band) & (np.abs(pos[..., 2]) < 0.1 * band / 0.3)
    ex = exact_ground_visibility(scene, pos[near], n=256)
    ex_img = np.full(vis.shape, np.nan)
    ex_img[near] = ex
    x, v = pos[near][:, 0], vis[near]

    def width(val):
        inside = (val > 0.1) & (val < 0.9)
        return float(np.ptp(x[inside])) if inside.sum() > 1 else 0.0

    return float(np.mean(np.abs(v - ex))), width(v) / max(width(ex), 1e-9), vis, ex_img, ms


def penumbra_case(elevation: float = 10.0, size=(256, 256)) -> Case:
    """PCSS penumbra vs the exact sun-disc visibility at a cube's shadow edge: hard shadows vs PCSS."""
    a = penumbra(elevation, ShadowConfig(filter="hard"), size)
    b = penumbra(elevation, ShadowConfig(filter="pcss"), size)
    return Case(f"penumbra width (sun {elevation} deg)", "shadows", "mean abs(vis - exact) across the penumbra",
                "PCSS (vs hard)", a[0], b[0], a[4], b[4], exact=0.0,
                images={"exact": b[3], "without": a[2], "with": b[2], "error": np.abs(b[2] - b[3])},
                extra={"width_ratio_hard": a[1], "width_ratio_pcss": b[1]})

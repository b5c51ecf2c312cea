"""Ray-casting buffer: rays only where needed, correct reflection/refraction, TIR flagged."""

import math

import numpy as np

from serenity.raster.gbuffer import GBufferPass
from serenity.raster.raycast import TRACE_REFLECTION, TRACE_REFRACTION, RayCastPass
from serenity.raster.scene_gl import SceneGL
from serenity.scene.model import Camera, Material

from .scenes import plane_scene


def _render(scene, w=64, h=48):
    from serenity.raster.context import get_context

    ctx = get_context()
    sgl = SceneGL(ctx, scene)
    gb = GBufferPass(ctx, sgl)
    gb.resize(w, h)
    rc = RayCastPass(ctx, sgl)
    rc.resize(w, h)
    cam = scene.camera
    vp = cam.projection_matrix(w / h) @ cam.view_matrix()
    rc.render(vp, cam, gb.render(vp, cam.position))
    return rc.read(), rc


def test_no_rays_for_opaque_scene(gl_ctx):
    buf, rc = _render(plane_scene())
    assert buf.count == 0 and not rc.any_traced_material


def test_mirror_plane_reflects_view_rays(gl_ctx):
    scene = plane_scene()
    scene.materials[0] = Material("mirror", albedo=(0.9, 0.9, 0.9), reflectivity=0.9)
    buf, _ = _render(scene)
    covered = buf.count
    assert covered > 0.3 * 64 * 48
    v = buf.origins - scene.camera.position
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    expected = v * np.array([1.0, -1.0, 1.0])  # mirror about y = 0
    assert np.allclose(buf.reflect_dirs, expected, atol=2e-3)
    assert np.all(buf.flags == TRACE_REFLECTION)
    assert np.allclose(buf.origins[:, 1], 0.0, atol=1e-4)
    # ray cone: width = distance x pixel spread
    d = np.linalg.norm(buf.origins - scene.camera.position, axis=1)
    spread = math.atan(2 * math.tan(math.radians(scene.camera.fov_y_deg) / 2) / 48)
    assert np.allclose(buf.cone_width, d * spread, rtol=1e-3)


def test_glass_refracts_by_snell_and_flags_tir(gl_ctx):
    scene = plane_scene()
    scene.materials[0] = Material("glass", albedo=(1, 1, 1), transparency=1.0, ior=1.5)
    buf, _ = _render(scene)
    assert np.all(buf.flags & TRACE_REFRACTION)
    v = buf.origins - scene.camera.position
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    sin_i = np.linalg.norm(v[:, [0, 2]], axis=1)
    sin_t = np.linalg.norm(buf.refract_dirs[:, [0, 2]], axis=1)
    assert np.allclose(sin_t, sin_i / 1.5, atol=2e-3)
    assert np.all(buf.refract_dirs[:, 1] < 0)
    # seen from below (inside the denser medium) at a grazing angle: total internal reflection
    scene.camera = Camera(position=(0.0, -0.5, 12.0), target=(0.0, 0.0, -5.0))
    buf, _ = _render(scene)
    assert buf.count > 0
    tir = (buf.flags & 4) > 0
    assert tir.any()
    assert np.allclose(buf.refract_dirs[tir], 0.0)


def test_both_ways_find_the_same_rays(gl_ctx):
    """The fullscreen pass over the G-buffer and the paper's second rasterisation of the reflective
    and refractive ranges give the same pixels, origins, directions and flags (a mirror floor, glass
    seen from above and from below, where glass shows total internal reflection)."""
    from serenity.raster.context import get_context

    scene = plane_scene()
    above = scene.camera
    below = Camera(position=(0.0, -0.5, 12.0), target=(0.0, 0.0, -5.0))  # the back seen: TIR at a grazing angle
    cases = [(Material("mirror", albedo=(0.9, 0.9, 0.9), reflectivity=0.9), above),
             (Material("glass", albedo=(1, 1, 1), transparency=1.0, ior=1.5), above),
             (Material("glass", albedo=(1, 1, 1), transparency=1.0, ior=1.5), below)]
    for material, cam in cases:
        scene.materials[0] = material
        scene.camera = cam
        ctx = get_context()
        sgl = SceneGL(ctx, scene)
        gb = GBufferPass(ctx, sgl)
        gb.resize(64, 48)
        rc = RayCastPass(ctx, sgl)
        rc.resize(64, 48)
        vp = cam.projection_matrix(64 / 48) @ cam.view_matrix()
        g = gb.render(vp, cam.position)
        out = {}
        for method in ("gbuffer", "geometry"):
            rc.render(vp, cam, g, method=method)
            assert rc.last_method == method
            out[method] = rc.read()
        a, b = out["gbuffer"], out["geometry"]
        assert a.count > 100 and np.array_equal(a.pixels, b.pixels)
        assert np.allclose(a.origins, b.origins, atol=1e-4)
        assert np.allclose(a.reflect_dirs, b.reflect_dirs, atol=2e-3)
        assert np.allclose(a.refract_dirs, b.refract_dirs, atol=2e-3)
        assert np.array_equal(a.flags, b.flags) and np.array_equal(a.material, b.material)
        if cam is below:
            assert ((a.flags & 4) > 0).any()  # total internal reflection: the back of the glass was seen

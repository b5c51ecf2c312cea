"""Per-object frustum culling: the G-buffer, shadow maps and RSM are the same with and without it,
and it skips what lies outside the frustum it is drawn with."""

from pathlib import Path

import numpy as np
import pytest

from serenity.raster.culling import boxes_in_frustum
from serenity.raster.gbuffer import GBufferPass
from serenity.raster.interop import read_depth, read_texture
from serenity.raster.rsm import RSMPass
from serenity.raster.scene_gl import SceneGL
from serenity.raster.shadow import Cascade, ShadowPass, fit_shadow_cascades, look_at, ortho
from serenity.scene.loaders import load
from serenity.scene.mesh_io import load_mesh_file, scene_from_meshes
from serenity.scene.model import Camera, Sun
from serenity.scene.procedural import courtyard_scene
from tests.data.materials_gltf import write_materials_gltf

from .scenes import box, plane_scene

W, H = 96, 54
BREAKFAST = Path(__file__).resolve().parents[2] / "scenes" / "breakfast_room" / "breakfast_room.toml"


def _view_proj(camera):
    return camera.projection_matrix(W / H) @ camera.view_matrix()


def _gbuffer(gpass, camera, cull):
    gpass.cull = cull
    g = gpass.render(_view_proj(camera), camera.position)
    return [read_texture(t) for t in (g.albedo, g.normal, g.position, g.material)] + [read_depth(g.depth)]


def _shadow(spass, camera, scene, bounds, cull):
    spass.cull = cull
    spass.invalidate()
    cascades = fit_shadow_cascades(camera, W / H, scene.sun.direction, bounds, spass.count, spass.size, 0.75, 200.0)
    maps = spass.render(cascades)
    return read_depth(maps.depth)


def test_box_against_frustum_planes():
    cam = Camera(position=(0.0, 0.0, 0.0), target=(0.0, 0.0, -1.0), fov_y_deg=60.0, near=0.1, far=100.0)
    vp = _view_proj(cam)
    lo = np.array([[-1, -1, -6], [-1, -1, 4], [50, -1, -6], [-1, -1, -200], [-1, -1, -0.5], [-1, -1, -0.09]], float)
    hi = lo + 2.0
    hi[4] = (1, 1, 0.5)        # straddles the camera's plane: near plane crosses it
    hi[5] = (1, 1, -0.0901)    # wholly between the eye and the near plane
    assert boxes_in_frustum(vp, lo, hi).tolist() == [True, False, False, False, True, False]


@pytest.mark.parametrize("which", ["courtyard", "breakfast_room"])
def test_culling_leaves_every_pass_unchanged(gl_ctx, which):
    scene = courtyard_scene() if which == "courtyard" else load(BREAKFAST)
    sgl = SceneGL(gl_ctx, scene)
    gpass, spass, rpass = GBufferPass(gl_ctx, sgl), ShadowPass(gl_ctx, sgl, 128, 4), RSMPass(gl_ctx, sgl, 64)
    gpass.resize(W, H)
    cam = scene.camera
    # the scene's own view, and one looking from its centre along a wall (most objects behind it)
    centre = sgl.bounds.mean(axis=0)
    turned = Camera(position=centre, target=centre + np.array([1.0, -0.2, 0.1]), fov_y_deg=50.0,
                    near=cam.near, far=cam.far)
    culled = 0
    try:
        for c in (cam, turned):
            on = _gbuffer(gpass, c, True)
            drawn, total = gpass.last_draws
            off = _gbuffer(gpass, c, False)
            assert gpass.last_draws == (total, total)
            culled += total - drawn
            for a, b in zip(on, off, strict=True):
                np.testing.assert_array_equal(a, b)
            on = _shadow(spass, c, scene, sgl.bounds, True)
            drawn, total = spass.last_draws
            np.testing.assert_array_equal(on, _shadow(spass, c, scene, sgl.bounds, False))
            culled += total - drawn
        rpass.render(scene.sun.direction, scene.sun.irradiance, sgl.bounds)
        on = [read_texture(t) for t in rpass.targets]
        rpass.cull = False
        rpass.render(scene.sun.direction, scene.sun.irradiance, sgl.bounds)
        for a, t in zip(on, rpass.targets, strict=True):
            np.testing.assert_array_equal(a, read_texture(t))
    finally:
        sgl.release()
    assert culled > 0  # the comparison covered ranges that were culled


def test_camera_facing_away_skips_the_draw_and_a_caster_behind_it_still_shadows(gl_ctx):
    scene = plane_scene(with_box=True)
    scene.sun = Sun((0.0, 0.5, 0.75 ** 0.5), irradiance=(1000.0,) * 3)  # 30 degrees up, towards +z
    ground = np.array([0.0, 0.0, 10.8])
    centre = ground + scene.sun.direction * (3.0 / scene.sun.direction[1])  # the box shading ``ground``
    scene.meshes.append(box("behind", centre, (2.0, 2.0, 2.0), 1))
    # the camera looks down at ``ground``, away from the box that shades it (behind and above it)
    cam = Camera(position=(0.0, 1.5, 12.5), target=ground, fov_y_deg=50.0)
    sgl = SceneGL(gl_ctx, scene)
    behind = next(i for i, r in enumerate(sgl.ranges) if r.lo[2] > 12.5)
    lo, hi = np.array([r.lo for r in sgl.ranges]), np.array([r.hi for r in sgl.ranges])
    gpass, spass = GBufferPass(gl_ctx, sgl), ShadowPass(gl_ctx, sgl, 256, 1)
    gpass.resize(W, H)
    try:
        on = _gbuffer(gpass, cam, True)
        seen = boxes_in_frustum(_view_proj(cam), lo, hi)
        assert seen.any() and not seen[behind]
        assert gpass.last_draws == (int(seen.sum()), len(sgl.ranges))  # the box behind is not drawn
        for x, y in zip(on, _gbuffer(gpass, cam, False), strict=True):
            np.testing.assert_array_equal(x, y)
        on = _shadow(spass, cam, scene, sgl.bounds, True)
        assert spass.last_draws[0] == spass.last_draws[1]  # every caster, the one behind included
        np.testing.assert_array_equal(on, _shadow(spass, cam, scene, sgl.bounds, False))
        # the map holds the box in front of the ground point its shadow falls on
        c = fit_shadow_cascades(cam, W / H, scene.sun.direction, sgl.bounds, 1, 256, 0.75, 200.0)[0]
        p = c.view_proj @ np.append(ground, 1.0)
        col, row = ((p[:2] * 0.5 + 0.5) * 256).astype(int)
        assert on[255 - row, col] < p[2] * 0.5 + 0.5 - 0.01
    finally:
        sgl.release()


def test_cutouts_are_culled_like_the_rest(gl_ctx, tmp_path):
    meshes, mats = load_mesh_file(write_materials_gltf(tmp_path))
    scene = scene_from_meshes("m", [m for m in meshes if m.name in {"wall", "fence"}], mats)  # fence at z = 0
    sgl = SceneGL(gl_ctx, scene)
    assert len(sgl.ranges) == 2 and len(sgl.masked_caster_ranges) == 1
    gpass, spass = GBufferPass(gl_ctx, sgl), ShadowPass(gl_ctx, sgl, 128, 1)
    gpass.resize(W, H)
    front = look_at(np.array([0.0, 0.0, 10.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]))
    try:
        # from z = 3 the camera sees both; from between the fence and the wall, only the wall
        for z, drawn in ((3.0, 2), (-0.5, 1)):
            cam = Camera(position=(0.0, 0.0, z), target=(0.0, 0.0, -1.0), fov_y_deg=60.0, near=0.1, far=20.0)
            on = _gbuffer(gpass, cam, True)
            assert gpass.last_draws == (drawn, 2)
            for a, b in zip(on, _gbuffer(gpass, cam, False), strict=True):
                np.testing.assert_array_equal(a, b)
        # a light box around the whole fence, and one beside it that holds only the wall's edge
        for left, drawn in ((-3.0, 2), (1.2, 1)):
            vp = ortho(left, 3.0, -3.0, 3.0, 1.0, 20.0) @ front
            maps = []
            for cull in (True, False):
                spass.cull = cull
                spass.invalidate()
                maps.append(read_depth(spass.render([Cascade(vp, 100.0, 6.0 / 128, 19.0)]).depth))
                assert spass.last_draws == ((drawn if cull else 2), 2)
            np.testing.assert_array_equal(*maps)
    finally:
        sgl.release()

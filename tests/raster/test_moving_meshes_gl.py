"""Meshes that move (``SceneGL.update_meshes``): after the move the G-buffer and the shadow maps are
those of a scene built at the new pose, bit for bit — nothing stale — and a moving mesh keeps its
own triangles (no levels of detail)."""

import dataclasses

import numpy as np

from serenity.raster.gbuffer import GBufferPass
from serenity.raster.interop import read_depth, read_texture
from serenity.raster.scene_gl import SceneGL
from serenity.raster.shadow import ShadowPass, fit_shadow_cascades
from serenity.scene.animation import Animation, Track, axis_angle_quaternion, pose_scene
from serenity.scene.model import Camera, Sun
from tests.scene.test_lod import _sphere

from .scenes import box, plane_scene

W, H = 96, 54


def _scene():
    scene = plane_scene(with_box=True)
    scene.sun = Sun((0.3, 0.8, 0.52), irradiance=(1000.0,) * 3)
    scene.camera = Camera(position=(0.0, 6.0, 9.0), target=(0.0, 0.5, 0.0), fov_y_deg=50.0)
    scene.meshes.append(box("cart", (3.0, 0.75, 2.0), (1.5, 1.5, 1.5), 1))
    turn = [axis_angle_quaternion((0, 1, 0), 0.0), axis_angle_quaternion((0, 1, 0), 60.0)]
    scene.animation = Animation([Track("cart", [0.0, 1.0], translation=[[0, 0, 0], [-5.0, 0.0, -1.0]],
                                       rotation=turn)])
    return scene


def _draw(ctx, sgl, scene):
    g, s = GBufferPass(ctx, sgl), ShadowPass(ctx, sgl, 256, 2)
    g.resize(W, H)
    cam = scene.camera
    gb = g.render(cam.projection_matrix(W / H) @ cam.view_matrix(), cam.position)
    out = [read_texture(t) for t in (gb.albedo, gb.normal, gb.position)] + [read_depth(gb.depth)]
    cascades = fit_shadow_cascades(cam, W / H, scene.sun.direction, sgl.bounds, 2, 256, 0.75, 200.0)
    out.append(read_depth(s.render(cascades).depth))
    return out, (g, s)


def test_moved_meshes_draw_as_a_scene_built_at_their_pose(gl_ctx):
    scene = _scene()
    moving = SceneGL(gl_ctx, scene)
    try:
        first, passes = _draw(gl_ctx, moving, scene)
        later = pose_scene(scene, 1.0)
        moving.update_meshes(later)
        g, s = passes
        s.invalidate()  # what the renderer does when a mesh moved
        cam = scene.camera
        gb = g.render(cam.projection_matrix(W / H) @ cam.view_matrix(), cam.position)
        after = [read_texture(t) for t in (gb.albedo, gb.normal, gb.position)] + [read_depth(gb.depth)]
        cascades = fit_shadow_cascades(cam, W / H, scene.sun.direction, moving.bounds, 2, 256, 0.75, 200.0)
        after.append(read_depth(s.render(cascades).depth))
        fresh_sgl = SceneGL(gl_ctx, later)
        try:
            fresh, _ = _draw(gl_ctx, fresh_sgl, later)
        finally:
            fresh_sgl.release()
        for a, b in zip(after, fresh, strict=True):
            np.testing.assert_array_equal(a, b)
        assert not np.array_equal(first[3], after[3]) and not np.array_equal(first[4], after[4])  # it moved
    finally:
        moving.release()


def test_moving_meshes_have_no_levels_of_detail(gl_ctx):
    scene = _scene()
    ball = dataclasses.replace(_sphere(radius=0.5, subdivisions=5, offset=(-3.0, 0.5, 0.0)), name="ball")
    scene.meshes.append(ball)  # 20480 triangles: levels of detail while it stands still
    still = SceneGL(gl_ctx, scene)
    scene.animation = Animation([Track("ball", [0.0], translation=[[0.0, 0.0, 0.0]])])
    moving = SceneGL(gl_ctx, scene)
    try:
        index = len(scene.meshes) - 1
        assert any(r.mesh == index for r in still.lod_ranges)
        assert moving.animated == [index] and all(r.mesh != index for r in moving.lod_ranges)
    finally:
        still.release()
        moving.release()

"""Levels of detail in the rasterised passes: a dense mesh far away is drawn coarser, near it is drawn
whole, and the coarser draw covers the same pixels to within the error bound."""

import numpy as np

from serenity.raster.gbuffer import GBufferPass
from serenity.raster.interop import read_texture
from serenity.raster.scene_gl import SceneGL
from serenity.scene.model import Camera, Material, Scene, Sky, Sun
from tests.scene.test_lod import _sphere

W, H = 160, 90


def _scene(distance: float) -> Scene:
    ball = _sphere(radius=1.0, subdivisions=6, seam=True, offset=(0.0, 0.0, -distance))  # 81920 triangles
    return Scene("ball", [ball], [Material("ball", albedo=(0.5, 0.5, 0.5))],
                 Camera(position=(0.0, 0.0, 0.0), target=(0.0, 0.0, -1.0), fov_y_deg=50.0, near=0.1, far=500.0),
                 Sun((0.0, 1.0, 0.0), irradiance=(1000.0,) * 3), Sky(radiance=(0.0, 0.0, 0.0), model="constant"))


def _coverage(gl_ctx, sgl, gpass, scene, lod_pixel_error):
    gpass.lod_pixel_error = lod_pixel_error
    cam = scene.camera
    g = gpass.render(cam.projection_matrix(W / H) @ cam.view_matrix(), cam.position)
    return read_texture(g.position)[..., 3] > 0, gpass.last_draws


def test_far_meshes_draw_coarser_levels_that_cover_the_same_pixels(gl_ctx):
    for distance, coarse in ((1.2, False), (60.0, True)):
        scene = _scene(distance)
        sgl = SceneGL(gl_ctx, scene)
        gpass = GBufferPass(gl_ctx, sgl)
        gpass.resize(W, H)
        try:
            cam = scene.camera
            vp = cam.projection_matrix(W / H) @ cam.view_matrix()
            levels = sgl.levels(vp, W, H, 1.0)
            last = sgl.lod_error.shape[1] - 1
            assert last == 3 and (levels[0] == last) == coarse
            # the projected error of the level drawn is within the bound, the next one's is not
            px = sgl.lod_error[0] * H / (2 * np.tan(np.radians(25.0)) * (distance - 1.0))
            assert px[levels[0]] <= 1.0 and (levels[0] == last or px[levels[0] + 1] > 1.0)
            whole, _ = _coverage(gl_ctx, sgl, gpass, scene, 0.0)
            drawn, _ = _coverage(gl_ctx, sgl, gpass, scene, 1.0)
            # within a pixel of the silhouette: covered pixels differ only along it
            changed = np.count_nonzero(whole != drawn)
            edge = np.count_nonzero(whole[1:] != whole[:-1]) + np.count_nonzero(whole[:, 1:] != whole[:, :-1])
            assert whole.any() and changed <= edge
        finally:
            sgl.release()


def test_the_full_meshes_stay_drawable(gl_ctx):
    scene = _scene(60.0)
    sgl = SceneGL(gl_ctx, scene)
    try:
        cam = scene.camera
        assert sgl.levels(cam.projection_matrix(W / H) @ cam.view_matrix(), W, H, 0.0) is None
        # the eye inside a mesh's box: its own triangles
        inside = Camera(position=(0.0, 0.0, -60.0), target=(0.0, 0.0, -61.0), fov_y_deg=50.0)
        assert sgl.levels(inside.projection_matrix(W / H) @ inside.view_matrix(), W, H, 1.0)[0] == 0
    finally:
        sgl.release()

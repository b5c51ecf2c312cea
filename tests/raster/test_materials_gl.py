"""Cut-outs, normal maps and texture transforms in the GL passes: the G-buffer, the shadow maps and
the RSM, on the small glTF of ``tests/data/materials_gltf.py``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from serenity.raster.gbuffer import GBufferPass
from serenity.raster.interop import read_texture
from serenity.raster.rsm import RSMPass
from serenity.raster.scene_gl import SceneGL
from serenity.raster.shadow import Cascade, ShadowPass, look_at, ortho
from serenity.scene.mesh_io import load_mesh_file, scene_from_meshes
from serenity.scene.model import Camera
from tests.data.materials_gltf import write_materials_gltf


@pytest.fixture(scope="module")
def loaded(tmp_path_factory):
    return load_mesh_file(write_materials_gltf(tmp_path_factory.mktemp("materials")))


def _scene(loaded, names, camera_z):
    meshes, mats = loaded
    s = scene_from_meshes("m", [m for m in meshes if m.name in names], mats)
    s.camera = Camera(position=(0.0, 0.0, camera_z), target=(0.0, 0.0, -1.0), fov_y_deg=40.0, near=0.1, far=20.0)
    return s


def _gbuffer(gl_ctx, scene, size=64):
    sgl = SceneGL(gl_ctx, scene)
    gp = GBufferPass(gl_ctx, sgl)
    gp.resize(size, size)
    cam = scene.camera
    g = gp.render(cam.projection_matrix(1.0) @ cam.view_matrix(), cam.position)
    return {k: read_texture(getattr(g, k)) for k in ("albedo", "normal", "position")}


def _fence_columns(g, size=64):
    """Rows through the middle: the fence spans columns where |x| < 1 at z = 0."""
    pos = g["position"][size // 2 - 4: size // 2 + 4]
    x = pos[..., 0]
    return pos, x


def test_gbuffer_discards_the_cutout(gl_ctx, loaded):
    g = _gbuffer(gl_ctx, _scene(loaded, {"wall", "fence"}, 3.0))
    pos, x = _fence_columns(g)
    left = (x < -0.1) & (x > -0.9) & (pos[..., 3] > 0)
    right = (x > 0.1) & (x < 0.9) & (pos[..., 3] > 0)
    assert left.sum() > 20 and right.sum() > 20
    assert np.allclose(pos[..., 2][left], -1.0, atol=1e-3)  # through the hole: the wall
    assert np.allclose(pos[..., 2][right], 0.0, atol=1e-3)  # the fence's solid half


def _sun_from_front(scene):
    eye = np.array([0.0, 0.0, 10.0])
    view = look_at(eye, np.zeros(3), np.array([0.0, 1.0, 0.0]))
    return ortho(-3, 3, -3, 3, 1.0, 20.0) @ view


def test_shadow_map_has_the_cutout_hole(gl_ctx, loaded):
    scene = _scene(loaded, {"wall", "fence"}, 3.0)
    sgl = SceneGL(gl_ctx, scene)
    assert sgl.masked_caster_ranges and sgl.opaque_caster_index_count == 6  # the wall's two triangles
    sp = ShadowPass(gl_ctx, sgl, size=128, cascades=1)
    vp = _sun_from_front(scene)
    maps = sp.render([Cascade(vp, 100.0, 6.0 / 128, 19.0)])
    depth = np.frombuffer(maps.depth.read(), np.float32).reshape(128, 128)  # row 0 = bottom

    def depth_at(p):
        c = vp @ np.append(p, 1.0)
        ij = ((c[:2] / c[3]) * 0.5 + 0.5) * 128
        return depth[int(ij[1]), int(ij[0])]

    wall = depth_at([-0.5, 0.3, -1.0])
    fence = depth_at([0.5, 0.3, 0.0])
    assert depth_at([-0.5, 0.3, 0.0]) == pytest.approx(wall, abs=1e-6)  # the hole: the wall's depth
    assert fence < wall - 0.02  # the solid half: nearer the sun
    # the same scene without the alpha test would have the fence everywhere in front of the wall
    assert depth_at([-1.5, 0.3, -1.0]) == pytest.approx(wall, abs=1e-6)


def test_rsm_sees_the_wall_through_the_cutout(gl_ctx, loaded):
    scene = _scene(loaded, {"wall", "fence"}, 3.0)
    rsm = RSMPass(gl_ctx, SceneGL(gl_ctx, scene), size=64)
    rsm.render(np.array([0.0, 0.0, 1.0]), np.array([100.0, 100.0, 100.0]), scene.bounds)
    v = rsm.read()
    p = v.positions
    mid = (np.abs(p[:, 1]) < 0.8)
    left = mid & (p[:, 0] < -0.2) & (p[:, 0] > -0.8)
    right = mid & (p[:, 0] > 0.2) & (p[:, 0] < 0.8)
    assert left.any() and right.any()
    assert np.allclose(p[left, 2], -1.0, atol=1e-3) and np.allclose(p[right, 2], 0.0, atol=1e-3)


def test_gbuffer_normal_map_tilts_the_normal(gl_ctx, loaded):
    g = _gbuffer(gl_ctx, _scene(loaded, {"bumpy"}, 5.0))
    cov = g["position"][..., 3] > 0
    n = g["normal"][..., :3][cov]
    s, c = math.sin(math.radians(30)), math.cos(math.radians(30))
    assert cov.sum() > 50
    assert np.allclose(n, [s, 0.0, c], atol=0.02)


def test_gbuffer_texture_transform_moves_the_checker(gl_ctx, loaded):
    g = _gbuffer(gl_ctx, _scene(loaded, {"checker"}, 6.0))
    pos, alb = g["position"], g["albedo"]
    cov = pos[..., 3] > 0
    x, y = pos[..., 0], pos[..., 1]
    # near the quarters' centres (the texels' centres: bilinear filtering blends the rest)
    tl = cov & (np.abs(x + 0.5) < 0.1) & (np.abs(y - 0.5) < 0.1)
    tr = cov & (np.abs(x - 0.5) < 0.1) & (np.abs(y - 0.5) < 0.1)
    assert tl.sum() >= 1 and tr.sum() >= 1
    # offset u by 0.5: the top-left quarter reads the image's top-right texel (black), and so on
    assert np.all(alb[..., 0][tl] < 0.3) and np.all(alb[..., 0][tr] > 0.7)  # ±0.1 texel off centre


def test_double_sided_plane_seen_from_behind_faces_the_camera(gl_ctx, loaded):
    scene = _scene(loaded, {"glossy"}, 6.0)
    scene.camera = Camera(position=(0.0, 0.0, 1.0), target=(0.0, 0.0, 4.0), fov_y_deg=40.0, near=0.1, far=20.0)
    g = _gbuffer(gl_ctx, scene)
    cov = g["position"][..., 3] > 0
    assert cov.sum() > 50
    assert np.allclose(g["normal"][..., :3][cov], [0.0, 0.0, -1.0], atol=1e-3)

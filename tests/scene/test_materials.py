"""Cut-outs, normal maps, texture transforms, double-sided flags and KHR_materials_specular: the
loader's mapping and the CPU ray tracer's closest and any hits, on the small glTF of
``tests/data/materials_gltf.py``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from serenity.errors import SceneError, SerenityError
from serenity.scene.mesh_io import gltf_uv_transform, load_mesh_file, scene_from_meshes
from serenity.scene.model import Material, apply_uv_transform, vertex_tangents
from tests.data.materials_gltf import write_materials_gltf


@pytest.fixture(scope="module")
def gltf(tmp_path_factory):
    return write_materials_gltf(tmp_path_factory.mktemp("materials"))


@pytest.fixture(scope="module")
def loaded(gltf):
    return load_mesh_file(gltf)


def _subset(loaded, names, name="materials"):
    meshes, mats = loaded
    return scene_from_meshes(name, [m for m in meshes if m.name in names], mats)


def _mat(loaded, name) -> Material:
    return next(m for m in loaded[1] if m.name == name)


def test_loader_maps_the_material_extensions(loaded):
    cut = _mat(loaded, "cutout")
    assert cut.alpha_cutoff == 0.5 and cut.alpha == 1.0 and cut.alpha_tested and cut.double_sided
    assert cut.albedo_texture.channels == 4
    wall = _mat(loaded, "wall")
    assert wall.alpha_cutoff is None and not wall.alpha_tested and not wall.double_sided
    bumpy = _mat(loaded, "bumpy")
    assert bumpy.normal_texture is not None and bumpy.normal_scale == 1.0
    # the normal map is linear data: its texel decodes back to the 30° tilt
    n = bumpy.normal_texture.mips[0][0, 0] * 2 - 1
    assert abs(n[0] - math.sin(math.radians(30))) < 0.01 and abs(n[2] - math.cos(math.radians(30))) < 0.01
    checker = _mat(loaded, "checker")
    assert np.allclose(checker.albedo_uv_transform, [[1, 0, 0.5], [0, 1, 0]])
    # KHR_materials_specular: F0 = 0.04 x specularFactor 0.5 for a dielectric, times (1 - roughness 0.5)
    assert _mat(loaded, "glossy").specular == pytest.approx(0.04 * 0.5 * 0.5)
    assert _mat(loaded, "wall").specular == 0.0  # roughness 1


def test_missing_texture_file_is_a_one_line_error_naming_it(tmp_path):
    path = write_materials_gltf(tmp_path, images=False)
    with pytest.raises(SceneError) as e:
        load_mesh_file(path)
    msg = str(e.value)
    assert "cutout.png" in msg and "not found" in msg and "\n" not in msg


def test_texture_transform_matches_the_khronos_example():
    # the extension's example: offset (0, 1), rotation 90°, scale 0.5 reads the lower-left quadrant
    # of the image (glTF uvs, v down), rotated: in v-up uvs the lower-left quadrant is [0, .5]²
    m = gltf_uv_transform((0.0, 1.0), math.pi / 2, (0.5, 0.5))
    corners = apply_uv_transform(m, [[0, 0], [1, 0], [1, 1], [0, 1]])
    assert np.all(corners >= -1e-9) and np.all(corners <= 0.5 + 1e-9)
    # glTF uv (1, 0) (right, top) → scaled (0.5, 0) → rotated to (0, -0.5) → offset (0, 0.5): v-up (0, 0.5)
    assert np.allclose(apply_uv_transform(m, [[1.0, 1.0]]), [[0.0, 0.5]])
    # a plain offset moves a checker texel where expected: v-up offset keeps its sign along u
    assert np.allclose(apply_uv_transform(gltf_uv_transform((0.25, 0.0), 0.0, (1, 1)), [[0.1, 0.2]]), [[0.35, 0.2]])
    assert np.allclose(apply_uv_transform(gltf_uv_transform((0.0, 0.25), 0.0, (1, 1)), [[0.1, 0.2]]), [[0.1, -0.05]])


def test_generated_tangents_follow_the_uvs():
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 0, -1], [0, 0, -1]], np.float32)  # in y = 0, normal +y
    nrm = np.tile([0.0, 1.0, 0.0], (4, 1)).astype(np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)  # u along +x, v along -z
    t = vertex_tangents(pos, nrm, uv, faces)
    assert np.allclose(t[:, :3], [1, 0, 0], atol=1e-6)
    assert np.all(t[:, 3] == 1.0)  # n × t = (0,1,0) × (1,0,0) = (0,0,-1) = dP/dv
    t2 = vertex_tangents(pos, nrm, uv[:, ::-1].copy(), faces)  # u and v swapped: mirrored
    assert np.allclose(t2[:, :3], [0, 0, -1], atol=1e-6) and np.all(t2[:, 3] == -1.0)


# ------------------------------------------------------------------------------ the CPU ray tracer


@pytest.fixture(scope="module")
def fence_tracer(loaded):
    from serenity.kernels.raytrace import RayTracer

    return RayTracer(_subset(loaded, {"wall", "fence"}, "fence"), "cpu", cache=False)


def _rays_at(xs, z0=0.5):
    o = np.array([[x, 0.3, z0] for x in xs], np.float32)
    d = np.tile(np.array([0.0, 0.0, -1.0], np.float32), (len(xs), 1))
    return o, d


def test_ray_through_the_cutout_hole_hits_what_is_behind(fence_tracer):
    xs = [-0.7, -0.3, 0.3, 0.7]  # x < 0: the fence's transparent half
    o, d = _rays_at(xs)
    g = fence_tracer.trace(o, d)
    assert np.allclose(g["position"][:, 2], [-1, -1, 0, 0], atol=1e-5)
    # the tree's own closest-hit query runs the same test
    h = fence_tracer.tree.intersect(o, d, tmin=1e-4)
    assert np.allclose(h.t, [1.5, 1.5, 0.5, 0.5], atol=1e-5)
    # any hit: without the wall behind, a ray through the hole is unoccluded
    assert fence_tracer.tree.occluded(o, d, tmin=1e-4, tmax=1.2).tolist() == [False, False, True, True]
    assert fence_tracer.tree.occluded(o, d, tmin=1e-4).tolist() == [True] * 4
    # a big batch (reordered, packets) gives the same answers as the small one
    rng = np.random.default_rng(3)
    big_x = rng.uniform(-0.95, 0.95, 40000).astype(np.float32)
    ob = np.stack([big_x, rng.uniform(-0.9, 0.9, 40000), np.full(40000, 0.5)], axis=1).astype(np.float32)
    db = np.tile(np.array([0.0, 0.0, -1.0], np.float32), (40000, 1))
    hb = fence_tracer.tree.intersect(ob, db, tmin=1e-4)
    expect = np.where(big_x < 0, 1.5, 0.5)
    away = np.abs(big_x) > 1e-2  # the bilinear alpha edge is half a texel wide around x = 0
    assert np.allclose(hb.t[away], expect[away], atol=1e-5)
    ocb = fence_tracer.tree.occluded(ob, db, tmin=1e-4, tmax=1.2)
    assert np.array_equal(ocb[away], (big_x >= 0)[away])


def test_sun_rays_pass_the_cutout_hole(fence_tracer):
    # points on the wall, the sun straight ahead (+z): behind the hole lit, behind the solid half not
    o = np.array([[x, 0.3, 2.0] for x in (-0.5, 0.5)], np.float32)
    d = np.tile(np.array([0.0, 0.0, -1.0], np.float32), (2, 1))
    g = fence_tracer.trace(o, d, sun_direction=(0.0, 0.0, 1.0))
    assert np.allclose(g["position"][:, 2], [-1.0, 0.0], atol=1e-5)
    assert g["eye"][0, 3] == 1.0  # the wall behind the hole sees the sun through it
    o2 = np.array([[0.5, 0.3, -0.5]], np.float32)  # a ray from between the fence and the wall
    g2 = fence_tracer.trace(o2, np.array([[0.0, 0.0, -1.0]], np.float32), sun_direction=(0.0, 0.0, 1.0))
    assert g2["position"][0, 2] == pytest.approx(-1.0) and g2["eye"][0, 3] == 0.0


def test_opaque_alpha_test_is_bit_identical_to_no_test(loaded):
    """A cut-out whose texture is opaque everywhere traces exactly as the opaque material."""
    from serenity.kernels.raytrace import RayTracer

    meshes, mats = loaded
    cut = _mat(loaded, "cutout")
    tex = cut.albedo_texture
    solid = type(tex)(tex.name, [np.concatenate([m[..., :3], np.ones(m.shape[:2] + (1,), m.dtype)], axis=2)
                                 for m in tex.mips])
    sel = [m for m in meshes if m.name in ("wall", "fence")]
    as_cut = [Material(m.name, **{k: getattr(m, k) for k in ("albedo", "specular", "shininess", "alpha")},
                       albedo_texture=solid if m.name == "cutout" else m.albedo_texture,
                       alpha_cutoff=0.5 if m.name == "cutout" else None) for m in mats]
    opaque = [Material(m.name, albedo=m.albedo, specular=m.specular, shininess=m.shininess,
                       albedo_texture=solid if m.name == "cutout" else m.albedo_texture) for m in mats]
    rng = np.random.default_rng(5)
    o = rng.uniform(-1.5, 1.5, (5000, 3)).astype(np.float32)
    o[:, 2] = rng.uniform(0.2, 2.0, 5000)
    d = rng.normal(size=(5000, 3)).astype(np.float32)
    d[:, 2] = -np.abs(d[:, 2])
    a = RayTracer(scene_from_meshes("a", sel, as_cut), "cpu", cache=False)
    b = RayTracer(scene_from_meshes("b", sel, opaque), "cpu", cache=False)
    assert a.data.cutouts == 1 and b.data.cutouts == 0
    ga = a.trace(o, d, sun_direction=(0.3, 0.5, 0.8))
    gb = b.trace(o, d, sun_direction=(0.3, 0.5, 0.8))
    for k in ga:
        assert np.array_equal(ga[k], gb[k]), k
    assert np.array_equal(a.tree.occluded(o, d), b.tree.occluded(o, d))


def test_tilted_normal_map_shades_like_a_tilted_plane(loaded):
    from serenity.kernels.raytrace import RayTracer

    rt = RayTracer(_subset(loaded, {"bumpy"}, "bumpy"), "cpu", cache=False)
    g = rt.trace(np.array([[0.2, -0.3, 3.0]], np.float32), np.array([[0.0, 0.0, -1.0]], np.float32))
    s = math.sin(math.radians(30))
    # the quad's u runs along +x, v along +y: tangent +x, normal +z → the map's tilt towards +x
    assert np.allclose(g["normal"][0, :3], [s, 0.0, math.cos(math.radians(30))], atol=0.01)
    # seen from behind, the whole mapped normal turns to face the ray
    g2 = rt.trace(np.array([[0.2, -0.3, 1.0]], np.float32), np.array([[0.0, 0.0, 1.0]], np.float32))
    assert np.allclose(g2["normal"][0, :3], [-s, 0.0, -math.cos(math.radians(30))], atol=0.01)


def test_texture_transform_moves_the_checker_in_the_tracer(loaded):
    from serenity.kernels.raytrace import RayTracer

    rt = RayTracer(_subset(loaded, {"checker"}, "checker"), "cpu", cache=False)
    # the 2x2 checker is white top-left and bottom-right; offset u by 0.5 swaps them: the top-left
    # quarter of the quad (x < 0, y > 0) reads the top-right texel, black
    o = np.array([[-0.5, 0.5, 4.0], [0.5, 0.5, 4.0], [-0.5, -0.5, 4.0], [0.5, -0.5, 4.0]], np.float32)
    d = np.tile(np.array([0.0, 0.0, -1.0], np.float32), (4, 1))
    g = rt.trace(o, d, 0.0, 0.0)
    assert np.allclose(g["albedo"][:, 0], [0.0, 1.0, 1.0, 0.0], atol=1e-3)


def test_double_sided_plane_seen_from_behind_faces_the_ray(loaded):
    from serenity.kernels.raytrace import RayTracer

    rt = RayTracer(_subset(loaded, {"glossy"}, "glossy"), "cpu", cache=False)
    g = rt.trace(np.array([[0.0, 0.0, 3.0]], np.float32), np.array([[0.0, 0.0, 1.0]], np.float32),
                 sun_direction=(0.0, 0.0, -1.0))
    assert np.allclose(g["normal"][0, :3], [0, 0, -1])
    assert g["eye"][0, 3] == 1.0  # lit from behind: nothing between it and a sun behind it


def test_material_rejects_bad_cutout_values():
    with pytest.raises(SerenityError):
        Material("m", alpha_cutoff=1.5)
    with pytest.raises(SerenityError):
        Material("m", albedo_uv_transform=np.eye(3))


def test_mitsuba_export_masks_and_normal_maps(loaded):
    mi = pytest.importorskip("mitsuba")
    from serenity.eval.reference import material_bsdf, mitsuba

    mi = mitsuba()
    cut = material_bsdf(mi, _mat(loaded, "cutout"))
    assert cut["type"] == "mask"
    opacity = np.asarray(cut["opacity"]["bitmap"]).reshape(8, 8)
    assert np.all(opacity[:, :4] == 0) and np.all(opacity[:, 4:] == 1)  # the texture's transparent left half
    bumpy = material_bsdf(mi, _mat(loaded, "bumpy"))
    assert bumpy["type"] == "twosided" and bumpy["bsdf"]["type"] == "normalmap"
    n = np.asarray(bumpy["bsdf"]["normalmap"]["bitmap"])[0, 0] * 2 - 1
    assert np.allclose(n, [math.sin(math.radians(30)), 0, math.cos(math.radians(30))], atol=0.01)
    checker = material_bsdf(mi, _mat(loaded, "checker"))
    to_uv = np.array(checker["bsdf"]["reflectance"]["to_uv"].matrix)
    assert np.allclose(to_uv[:2], [[1, 0, 0.5], [0, 1, 0]])
    for m in loaded[1]:
        mi.load_dict(material_bsdf(mi, m))  # every exported BSDF is one Mitsuba accepts


def test_cutout_survives_glb_export_and_toml(loaded, tmp_path):
    from serenity.scene.mesh_io import export_glb
    from serenity.scene.toml_scene import load_toml, save_toml

    meshes, mats = loaded
    scene = scene_from_meshes("s", [m for m in meshes if m.name in ("wall", "fence")], mats[:2])  # wall, cutout
    export_glb(scene, tmp_path / "s.glb")
    save_toml(scene, tmp_path / "s.toml", "s.glb")
    back = load_toml(tmp_path / "s.toml")
    cut = back.materials[back.material_index("cutout")]
    assert cut.alpha_tested and cut.alpha_cutoff == 0.5
    uv = np.array([[0.2, 0.5], [0.8, 0.5]])
    assert cut.coverage(uv).tolist() == [False, True]

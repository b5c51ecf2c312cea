"""Loading scenes from files: round trips, the TOML format, and clear errors for bad input."""

import importlib.util
import json
import os
import warnings

import numpy as np
import pytest
import trimesh

from serenity.errors import SceneError
from serenity.scene import build_scene, export_glb, load, save_toml, scene_names

_EX = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "export_scenes.py")


def _example():
    spec = importlib.util.spec_from_file_location("export_scenes", _EX)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("name", ["courtyard", "cornell", "mirror-box", "courtyard-van"])
def test_glb_plus_toml_load_back_identically(name, tmp_path):
    ex = _example()
    toml = ex.export_scene(name, str(tmp_path))
    assert ex.scenes_equal(build_scene(name), load(toml)) == []


def test_builtin_scenes_are_deterministic_and_valid():
    for name in scene_names():
        a, b = build_scene(name), build_scene(name)
        assert a.triangle_count > 0
        assert np.array_equal(a.merged()[0], b.merged()[0])
    cy = build_scene("courtyard")
    assert any(m.transparency > 0 for m in cy.materials) and any(m.reflectivity > 0 for m in cy.materials)
    assert len(cy.occlusion_quads) > 0


@pytest.mark.parametrize("ext", [".obj", ".glb", ".ply"])
def test_mesh_file_geometry_round_trip(ext, tmp_path):
    box = trimesh.creation.box(extents=(2.0, 1.0, 3.0))
    path = tmp_path / f"box{ext}"
    box.export(path)
    scene = load(str(path))
    v = scene.merged()[0]
    assert scene.triangle_count == 12
    np.testing.assert_allclose(v.min(0), [-1.0, -0.5, -1.5], atol=1e-6)
    np.testing.assert_allclose(v.max(0), [1.0, 0.5, 1.5], atol=1e-6)
    # the framing camera sees the object
    assert np.linalg.norm(scene.camera.position) > 2.0


def test_obj_mtl_materials(tmp_path):
    (tmp_path / "m.mtl").write_text("newmtl shiny\nKd 0.2 0.4 0.6\nKs 0.5 0.5 0.5\nNs 64\nd 0.25\nNi 1.33\n")
    (tmp_path / "m.obj").write_text("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl shiny\nf 1 2 3\n")
    scene = load(str(tmp_path / "m.obj"))
    m = scene.materials[scene.meshes[0].face_material[0]]
    np.testing.assert_allclose(m.albedo, [0.2, 0.4, 0.6], atol=1e-6)
    assert m.shininess == pytest.approx(64) and m.specular == pytest.approx(0.5)
    assert m.transparency == pytest.approx(0.75) and m.ior == pytest.approx(1.33)


def test_degenerate_triangles_are_dropped_with_a_warning(tmp_path):
    path = tmp_path / "d.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\nf 1 1 3\n")
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        scene = load(str(path))
    assert scene.triangle_count == 1
    assert any("degenerate" in str(x.message) for x in w)


def test_toml_overrides_and_sun_by_time(tmp_path):
    scene = build_scene("cornell")
    export_glb(scene, tmp_path / "c.glb")
    (tmp_path / "c.toml").write_text(
        '[scene]\nmesh = "c.glb"\n[sun]\ntime = "2024-06-21 13:00 +01:00"\nlatitude = 38.72\nlongitude = -9.14\n'
        '[materials.red]\nreflectivity = 0.5\n')
    s = load(str(tmp_path / "c.toml"))
    assert s.materials[s.material_index("red")].reflectivity == 0.5
    assert 60 < s.sun.elevation_deg < 80


@pytest.mark.parametrize("body, words", [
    ('[scene]\nmesh = "c.glb"\n[camera]\nposition = [0, 0, 1]\ntarget = [0, 0, 0]\nzoom = 2\n', ["zoom"]),
    ('[scene]\nmesh = "nope.glb"\n', ["nope.glb"]),
    ('[scene]\nmesh = "c.glb"\n[materials.gold]\nior = 1.2\n', ["gold"]),
    ('[scene]\nmesh = "c.glb"\n[sun]\ntime = "2024-02-30 12:00"\nlatitude = 0\nlongitude = 0\n', ["30"]),
    ('[scene\nmesh = ', ["TOML"]),
])
def test_toml_errors_are_one_line_and_name_the_file(tmp_path, body, words):
    export_glb(build_scene("cornell"), tmp_path / "c.glb")
    path = tmp_path / "bad.toml"
    path.write_text(body)
    with pytest.raises(SceneError) as e:
        load(str(path))
    msg = str(e.value)
    assert "\n" not in msg and "bad.toml" in msg
    for w in words:
        assert w in msg


def test_bad_mesh_files(tmp_path):
    (tmp_path / "x.glb").write_bytes(b"garbage")
    with pytest.raises(SceneError, match="x.glb"):
        load(str(tmp_path / "x.glb"))
    (tmp_path / "y.stl2").write_text("solid")
    with pytest.raises(SceneError, match="unsupported"):
        load(str(tmp_path / "y.stl2"))
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n")
    with pytest.raises(SceneError, match="nan.obj"):
        load(str(tmp_path / "nan.obj"))
    with pytest.raises(SceneError, match="no-such"):
        load("no-such")


def test_save_toml_then_load_is_exact(tmp_path):
    scene = build_scene("courtyard")
    export_glb(scene, tmp_path / "a.glb")
    save_toml(scene, tmp_path / "a.toml", "a.glb")
    back = load(str(tmp_path / "a.toml"))
    np.testing.assert_array_equal(back.sun.direction, scene.sun.direction)
    np.testing.assert_array_equal(back.camera.position, scene.camera.position)


def _corners(v, n, uv, f):
    """Each triangle as a sorted tuple of its rounded (position, normal, uv) corners, order-free."""
    rows = np.concatenate([v[f], n[f], uv[f]], axis=2).astype(np.float64).round(3) + 0.0  # -0 -> 0
    return np.array(sorted(tuple(sorted(map(tuple, tri))) for tri in rows))


@pytest.mark.parametrize("ext", [".glb", ".obj"])
def test_trimesh_written_file_keeps_triangles_normals_uvs_and_material(ext, tmp_path):
    from PIL import Image

    mesh = trimesh.creation.box(extents=(2.0, 1.0, 3.0))
    mesh.unmerge_vertices()  # in place: flat normals, one uv per corner
    uv = np.random.default_rng(0).random((len(mesh.vertices), 2))
    tex = Image.fromarray(np.full((4, 4, 3), (200, 120, 40), np.uint8))
    mesh.visual = trimesh.visual.TextureVisuals(uv=uv, material=trimesh.visual.material.SimpleMaterial(
        image=tex, diffuse=(255, 255, 255, 255)))
    normals = np.asarray(mesh.vertex_normals)
    path = tmp_path / f"t{ext}"
    mesh.export(path)
    scene = load(str(path))
    v, n, u, f, fm = scene.merged()
    np.testing.assert_allclose(_corners(v, n, u, f), _corners(np.asarray(mesh.vertices), normals, uv,
                                                              np.asarray(mesh.faces)), atol=2e-3)
    mat = scene.materials[fm[0]]
    assert mat.albedo_texture is not None
    from serenity.colour import srgb_to_linear

    np.testing.assert_allclose(mat.albedo_texture.mips[0][0, 0, :3], srgb_to_linear(np.array([200, 120, 40]) / 255),
                               atol=2e-3)
    if ext == ".glb":  # trimesh writes no metallicFactor (glTF's default 1): a white metal, roughness 0.9
        np.testing.assert_allclose(mat.albedo + mat.specular, 1.0, atol=1e-6)


def test_big_gltf_is_read_back_from_the_disk_cache(tmp_path, monkeypatch):
    """A glTF over the cache's size is read once; the next load reads the disk cache (trimesh not
    called), gives the same meshes and materials and repeats the first load's warnings; a changed
    buffer, image or a corrupt cache file is read from the glTF again."""
    import pickle

    import serenity.scene.mesh_io as mio
    from tests.data.materials_gltf import write_materials_gltf

    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(mio, "MESH_CACHE_MIN_BYTES", 0)
    path = write_materials_gltf(tmp_path / "model")
    gltf = json.loads(path.read_text())
    for m in gltf["materials"]:  # a texture read through TEXCOORD_1: a warning each load must give
        m.get("pbrMetallicRoughness", {}).get("baseColorTexture", {})["texCoord"] = 1
    path.write_text(json.dumps(gltf))
    reads = []
    monkeypatch.setattr(mio, "_read_mesh_file", lambda *a, _r=mio._read_mesh_file: (reads.append(1), _r(*a))[1])
    with warnings.catch_warnings(record=True) as first_warnings:
        warnings.simplefilter("always")
        first = mio.load_mesh_file(path)
    with warnings.catch_warnings(record=True) as again_warnings:
        warnings.simplefilter("always")
        again = mio.load_mesh_file(path)
    assert len(reads) == 1 and len(list((tmp_path / "cache").glob("mesh-*.pickle"))) == 1
    assert pickle.dumps(first) == pickle.dumps(again)
    assert [str(w.message) for w in again_warnings] == [str(w.message) for w in first_warnings]
    assert any("TEXCOORD_1" in str(w.message) for w in first_warnings)
    buffer = next(path.parent.glob("*.bin"))
    data = bytearray(buffer.read_bytes())
    data[0] ^= 1  # another vertex coordinate
    buffer.write_bytes(bytes(data))
    changed = mio.load_mesh_file(path)
    assert len(reads) == 2 and not np.array_equal(changed[0][0].positions, first[0][0].positions)
    image = next(path.parent.glob("*.png"))
    image.write_bytes(image.read_bytes() + b"\0")  # a changed image file: another key
    mio.load_mesh_file(path)
    assert len(reads) == 3
    for f in (tmp_path / "cache").glob("mesh-*.pickle"):
        f.write_bytes(b"not a pickle")
    assert pickle.dumps(mio.load_mesh_file(path)[1]) == pickle.dumps(mio.load_mesh_file(path)[1])
    assert len(reads) == 4

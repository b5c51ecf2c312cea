"""The Blender Cycles peer: the export against the scene and the Mitsuba export's conventions (no bpy
needed), the one-line error without Cycles' interpreter, and, where that interpreter exists
(``make cycles``), renders against analytic answers and against Mitsuba."""

import math

import numpy as np
import pytest

from serenity.colour import luminance
from serenity.eval import cycles
from serenity.eval.reference import phong_alpha, with_effective_sun
from serenity.kernels.atmosphere_ref import equirect_directions
from serenity.scene import load
from serenity.scene.model import (
    Camera,
    Material,
    Scene,
    Sky,
    Sun,
    apply_uv_transform,
    direction_from_angles,
)
from serenity.scene.texture import texture_from_array
from tests.raster.scenes import plane_scene, quad

needs_cycles = pytest.mark.skipif(not cycles.available(), reason="no Cycles interpreter (make cycles)")
BLACK = None


def from_blender(v) -> np.ndarray:
    return np.asarray(v, np.float64) @ cycles.Y_UP_TO_Z_UP


# ------------------------------------------------------------------------------------------- export


@pytest.mark.parametrize("name", ["cornell", "courtyard"])
def test_meshes_carry_every_triangle_of_each_material(name):
    scene = load(name)
    desc, arrays = cycles.export_scene(scene, 32, 18, sky=BLACK)
    pos, nrm, uv, faces, fmat = scene.merged()
    assert sorted(m["name"] for m in desc["meshes"]) == sorted(f"m{k}" for k in np.unique(fmat))
    for mesh in desc["meshes"]:
        k = int(mesh["name"][1:])
        p = mesh["prefix"]
        got = from_blender(arrays[p + "positions"])[arrays[p + "faces"]]
        np.testing.assert_allclose(got, pos[faces[fmat == k]], atol=1e-5)
        np.testing.assert_allclose(from_blender(arrays[p + "normals"])[arrays[p + "faces"]], nrm[faces[fmat == k]],
                                   atol=1e-5)
        np.testing.assert_array_equal(arrays[p + "uv"][arrays[p + "faces"]], uv[faces[fmat == k]])
        assert desc["materials"][mesh["material"]]["name"] == f"m{k}_{scene.materials[k].name}"


def test_y_up_to_z_up_is_a_rotation_that_keeps_the_compass():
    r = cycles.Y_UP_TO_Z_UP
    np.testing.assert_allclose(r @ r.T, np.eye(3))
    assert np.linalg.det(r) == pytest.approx(1.0)
    np.testing.assert_allclose(cycles.to_blender([0, 1, 0]), [0, 0, 1])  # up
    np.testing.assert_allclose(cycles.to_blender([0, 0, -1]), [0, 1, 0])  # north: Blender's +y
    np.testing.assert_allclose(cycles.to_blender([1, 0, 0]), [1, 0, 0])  # east


def test_camera_matrix_reproduces_the_primary_rays():
    """Blender's camera (down its -z, vertical sensor fit) sees pixel (i, j) along Camera.primary_rays."""
    cam = Camera(position=(1.0, 2.0, 3.0), target=(4.0, 1.0, -2.0), fov_y_deg=55.0)
    w, h = 40, 24
    m = cycles.camera_matrix(cam)
    np.testing.assert_allclose(from_blender(m[:3, 3]), cam.position)
    np.testing.assert_allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-12)
    _, d = cam.primary_rays(w, h)
    local = cycles.to_blender(d) @ m[:3, :3]  # camera-space directions
    t = math.tan(math.radians(cam.fov_y_deg) / 2)
    x = ((np.arange(w) + 0.5) / w * 2 - 1) * t * w / h
    y = (1 - (np.arange(h) + 0.5) / h * 2) * t
    assert np.all(local[:, 2] < 0)
    np.testing.assert_allclose((local[:, 0] / -local[:, 2]).reshape(h, w), np.broadcast_to(x, (h, w)), atol=1e-5)
    np.testing.assert_allclose((local[:, 1] / -local[:, 2]).reshape(h, w), np.broadcast_to(y[:, None], (h, w)),
                               atol=1e-5)


def test_sky_map_is_turned_to_blenders_longitude():
    """Blender's equirect lookup of a direction reads the texel that Mitsuba's envmap reads for it."""
    width, height = 64, 16
    sky = np.random.default_rng(3).random((height, width, 3)).astype(np.float32)
    out = cycles.blender_sky(sky)
    assert out.shape == (height, width, 4) and out.dtype == np.float32
    np.testing.assert_array_equal(out[..., 3], 1.0)
    uv = cycles.blender_equirect_uv(cycles.to_blender(equirect_directions(width, height)))  # Mitsuba's texel centres
    col, row = uv[..., 0] * width - 0.5, uv[..., 1] * height - 0.5  # Blender's texel centres are at (i + 0.5)/n
    np.testing.assert_allclose(row, np.arange(height)[::-1, None] + np.zeros(width), atol=1e-6)
    np.testing.assert_allclose(col, np.rint(col), atol=1e-6)  # a quarter turn: a whole number of texels
    np.testing.assert_array_equal(out[np.rint(row).astype(int), np.rint(col).astype(int) % width, :3], sky)


def test_sky_map_of_a_width_not_a_multiple_of_four_is_interpolated():
    width, height = 30, 16
    d = equirect_directions(width, height)
    sky = (d + 2.0).astype(np.float32)  # smooth: texels hold their own direction
    out = cycles.blender_sky(sky)
    uv = cycles.blender_equirect_uv(cycles.to_blender(d))
    col, row = uv[..., 0] * width - 0.5, np.rint(uv[..., 1] * height - 0.5).astype(int)
    lo, f = np.floor(col).astype(int), (col - np.floor(col))[..., None]
    got = (1 - f) * out[row, lo % width, :3] + f * out[row, (lo + 1) % width, :3]  # a linear lookup
    np.testing.assert_allclose(got, sky, atol=0.02)  # two linear interpolations of 12-degree texels


def test_blender_equirect_uv_follows_blenders_convention():
    # +x is the middle of the map, +y a quarter to the left of it, the zenith the top row
    np.testing.assert_allclose(cycles.blender_equirect_uv([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [0, 0, -1.0]])[:, 1],
                               [0.5, 0.5, 1.0, 0.0])
    np.testing.assert_allclose(cycles.blender_equirect_uv([[1.0, 0, 0], [0, 1.0, 0], [-1.0, 0, 1e-9]])[:, 0],
                               [0.5, 0.25, 0.0], atol=1e-6)


def test_sun_lamp_carries_the_renderers_irradiance_and_disc():
    scene = load("courtyard")
    desc, _ = cycles.export_scene(scene, 32, 18, sky=BLACK)
    sun = desc["sun"]
    irr = with_effective_sun(scene).sun.irradiance
    np.testing.assert_allclose(np.asarray(sun["color"]) * sun["strength"], irr, rtol=1e-12)
    assert max(sun["color"]) == 1.0 and sun["angle_deg"] == scene.sun.angular_diameter_deg
    m = np.asarray(sun["matrix"])
    np.testing.assert_allclose(from_blender(m[:3, 2]), scene.sun.direction, atol=1e-12)  # local +z: towards the sun
    np.testing.assert_allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.det(m[:3, :3]) == pytest.approx(1.0)
    night = plane_scene()
    night.sun = Sun(direction_from_angles(-5.0, 90.0))
    assert cycles.export_scene(night, 32, 18, sky=BLACK)[0]["sun"] is None


def test_materials_follow_the_mitsuba_mapping():
    scene = load("courtyard")
    desc, arrays = cycles.export_scene(scene, 32, 18, sky=BLACK)
    by_name = {m["name"].split("_", 1)[1]: m for m in desc["materials"]}
    for mat in scene.materials:
        spec = by_name[mat.name]
        ks = mat.specular
        assert spec["ks"] == ks and spec["roughness"] ** 2 == pytest.approx(phong_alpha(mat.shininess))
        assert (spec["mirror"], spec["glass"], spec["ior"]) == (mat.reflectivity, mat.transparency, mat.ior)
        scale = 1.0 if ks <= 0 else 1.0 / (1.0 - ks)
        if mat.albedo_texture is None:
            np.testing.assert_allclose(spec["diffuse"]["rgb"], mat.albedo * scale)
        else:
            img = arrays[spec["diffuse"]["texture"]]
            want = (mat.albedo_texture.mips[0][..., :3] * mat.albedo.astype(np.float32) * np.float32(scale))[::-1]
            np.testing.assert_allclose(img[..., :3], want, rtol=1e-6)
    # the built-in glass reflects more than it receives in the reference too: exported unclamped
    assert max(by_name["glass"]["diffuse"]["rgb"]) > 1.0


def test_cutouts_normal_maps_and_uv_transforms():
    rgba = np.zeros((8, 8, 4), np.float32)
    rgba[..., :3] = 0.5
    rgba[:, :4, 3] = 1.0  # left half there
    nmap = np.zeros((8, 8, 3), np.float32)
    nmap[...] = (0.6, 0.5, 0.9)
    uvt = np.array([[2.0, 0.0, 0.25], [0.0, -1.0, 1.0]])
    mat = Material("leaf", albedo=(0.9, 0.8, 0.7), albedo_texture=texture_from_array(rgba), alpha_cutoff=0.5,
                   normal_texture=texture_from_array(nmap), albedo_uv_transform=uvt)
    scene = plane_scene()
    scene.materials[0] = mat
    desc, arrays = cycles.export_scene(scene, 32, 18, sky=BLACK)
    (spec,) = desc["materials"]
    assert spec["albedo_uv"] == "albedo_uv" and spec["normal_uv"] == "uv"
    np.testing.assert_array_equal(arrays[spec["opacity"]][..., 0], (rgba[..., 3] >= 0.5)[::-1])
    (mesh,) = desc["meshes"]
    assert mesh["uv_layers"] == ["uv", "albedo_uv"]
    np.testing.assert_allclose(arrays[mesh["prefix"] + "albedo_uv"],
                               apply_uv_transform(uvt, arrays[mesh["prefix"] + "uv"]), rtol=1e-6)
    n = arrays[spec["normal_map"]][..., :3] * 2 - 1
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, rtol=1e-5)
    assert set(desc["images"]) == {spec["diffuse"]["texture"], spec["opacity"], spec["normal_map"]}


def test_glass_faces_are_wound_as_their_normals_point():
    """Cycles tells a glass face's back (where the reference's opaque part is black) by its winding."""
    scene = plane_scene()
    scene.materials[0] = Material("glass", albedo=(0.9, 0.9, 0.9), transparency=0.9)
    mesh = scene.meshes[0]
    mesh.faces = mesh.faces[:, [0, 2, 1]].copy()  # wound against its normals (+y)
    desc, arrays = cycles.export_scene(scene, 32, 18, sky=BLACK)
    (m,) = desc["meshes"]
    p = from_blender(arrays[m["prefix"] + "positions"])[arrays[m["prefix"] + "faces"]]
    ng = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert np.all(ng[:, 1] > 0)
    np.testing.assert_allclose(np.sort(p.reshape(-1, 3), axis=0), np.sort(mesh.positions[mesh.faces].reshape(-1, 3),
                                                                           axis=0), atol=1e-6)


def test_missing_interpreter_is_a_one_line_error(tmp_path, monkeypatch):
    monkeypatch.setenv(cycles.ENV_VAR, str(tmp_path / "no-python"))
    assert not cycles.available()
    assert "make cycles" in cycles.unavailable_reason()
    with pytest.raises(cycles.CyclesUnavailableError) as exc:
        cycles.CyclesPeer(plane_scene(), 32, 18)
    msg = str(exc.value)
    assert "\n" not in msg and "make cycles" in msg and cycles.ENV_VAR in msg and "no-python" in msg


def test_an_interpreter_without_bpy_is_named(monkeypatch):
    import sys

    monkeypatch.setenv(cycles.ENV_VAR, sys.executable)  # the project's Python: numpy 2, no bpy
    if cycles.available():
        pytest.skip("this Python has bpy")
    assert "cannot import bpy" in cycles.unavailable_reason()


# ------------------------------------------------------------------------------------------ renders


@needs_cycles
def test_render_sees_the_sky_where_the_camera_looks():
    """Every pixel of a wide view of a sky whose texels hold their own direction decodes to that
    pixel's primary ray: the map's orientation and the camera agree with the reference's."""
    w, h = 48, 27
    cam = Camera(position=(0.0, 0.0, 0.0), target=(1.0, 0.25, -1.0), fov_y_deg=90.0)
    below = quad("below", 0.1, 0, y=-50.0)  # a scene needs a triangle: out of view
    scene = Scene("sky", [below], [Material("m")], cam, Sun(direction_from_angles(-10.0, 0.0)),
                  Sky(radiance=(0.0, 0.0, 0.0), model="constant"))
    sky = (equirect_directions(256, 128) + 2.0).astype(np.float32)
    img, _ = cycles.CyclesPeer(scene, w, h, sky=sky).render(16)
    got = img.reshape(-1, 3).astype(np.float64) - 2.0
    got /= np.linalg.norm(got, axis=1, keepdims=True)
    _, d = cam.primary_rays(w, h)
    err = np.degrees(np.arccos(np.clip((got * d).sum(axis=1), -1.0, 1.0)))
    assert err.max() < 0.7, f"sky direction off by up to {err.max():.2f} deg (a texel is 1.4 deg)"


@needs_cycles
def test_sun_lamp_strength_is_the_irradiance():
    """A diffuse plane of albedo ρ under the sun at elevation e: ρ/π · E · sin e (no sky)."""
    for elevation, azimuth, albedo in ((60.0, 180.0, 0.5), (20.0, 70.0, 0.8)):
        img, _ = cycles.CyclesPeer(plane_scene(albedo, 90.0 - elevation, azimuth), 48, 27).render(4)
        expect = albedo / math.pi * 1000.0 * math.sin(math.radians(elevation))
        lit = img[8:20, 12:36]  # the plane alone: each pixel's samples spread over the disc's 0.53 deg
        assert float(lit.mean()) == pytest.approx(expect, rel=1e-3)
        np.testing.assert_allclose(lit, expect, rtol=1e-2)


@needs_cycles
def test_textured_plane_and_box_match_mitsuba(tmp_path, monkeypatch):
    """Direct light on a plane with a texture that tells u from v and top from bottom, and a box's
    shadow: Cycles without bounces against Mitsuba's direct component."""
    pytest.importorskip("mitsuba")
    from serenity.eval.metrics import flip
    from serenity.eval.reference import render_reference
    from tests.eval.test_reference import asymmetric_texture, plane

    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path / "cache"))
    scene = plane(elevation=35.0, with_box=True, texture=asymmetric_texture())
    ref = render_reference(scene, 48, 27, spp=32, component="direct", progress=False)
    img, _ = cycles.CyclesPeer(scene, 48, 27, max_bounces=0).render(32)
    assert float(luminance(img).mean()) == pytest.approx(float(luminance(ref).mean()), rel=0.01)
    assert flip(img, ref) < 0.03


@needs_cycles
def test_cornell_matches_mitsuba_and_oidn_lowers_the_error(tmp_path, monkeypatch):
    """The Cornell box (all its light indirect but the sunlit patch) at 32x18: the mean luminance of
    Cycles within 3 % of Mitsuba's, both at 1024 spp (a mean over 0.6 M paths: about 1 % of noise);
    the 4-spp image (the first render after the warm-up, which persistent data would hand back
    unrendered were the scene not tagged) closer to the 1024-spp one than a 1-spp image, and the
    denoised 4-spp images closer than the raw one."""
    pytest.importorskip("mitsuba")
    from serenity.eval.metrics import flip
    from serenity.eval.reference import render_reference

    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path / "cache"))
    scene = load("cornell")
    ref = render_reference(scene, 32, 18, spp=1024, progress=False)
    peer = cycles.CyclesPeer(scene, 32, 18)
    curves = peer.curves([4, 1024], repeat_below_s=0.0)
    assert set(curves) == set(cycles.CURVES)
    (_, raw4, t4), (_, good, _) = curves["cycles"]
    assert good.shape == (18, 32, 3) and good.dtype == np.float32 and t4 > 0
    assert float(luminance(good).mean()) == pytest.approx(float(luminance(ref).mean()), rel=0.03)
    raw_err = flip(raw4, good)
    assert raw_err < flip(peer.render(1)[0], good)
    for curve in ("cycles+oidn-fast", "cycles+oidn-accurate"):
        (spp, den4, _), _ = curves[curve]
        assert spp == 4 and flip(den4, good) < raw_err


def _bench_frontier():
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_frontier.py"
    spec = importlib.util.spec_from_file_location("bench_frontier", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_bench_frontier_peers_are_checked_before_any_work(tmp_path, monkeypatch, capsys):
    bench = _bench_frontier()
    assert bench.main(["--quick", "--peers", "mitsuba,luxcore"]) == 2
    assert "--peers" in capsys.readouterr().err
    monkeypatch.setenv(cycles.ENV_VAR, str(tmp_path / "no-python"))
    assert bench.main(["--quick", "--peers", "cycles"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "make cycles" in err
